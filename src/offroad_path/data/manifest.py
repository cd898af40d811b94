"""Manifests: the CSV files that list a split's samples (written by `split`, read by training)."""

from __future__ import annotations

import csv
from dataclasses import asdict, dataclass, fields
from pathlib import Path


@dataclass(frozen=True)
class Sample:
    sequence: str
    f0: int
    mirrored: bool  # flip image, label, disparity and semantic map left-right when loading
    image: str
    label: str
    disparity: str  # KITTI format: uint16 of 256 x disparity, 0 unknown
    semantic: str  # class ids 0..7; empty for real recordings
    fx: float
    baseline_m: float


COLUMNS = [f.name for f in fields(Sample)]


def write_manifest(path: Path, samples: list[Sample]) -> None:
    with open(path, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=COLUMNS)
        writer.writeheader()
        writer.writerows(asdict(s) for s in samples)


def read_manifest(path: str | Path) -> list[Sample]:
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: manifest is missing (run the split stage first)")
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        if reader.fieldnames != COLUMNS:
            raise ValueError(f"{path}: columns {reader.fieldnames} differ from the expected {COLUMNS}")
        return [
            Sample(r["sequence"], int(r["f0"]), r["mirrored"] == "True", r["image"], r["label"], r["disparity"], r["semantic"],
                   float(r["fx"]), float(r["baseline_m"]))
            for r in reader
        ]  # fmt: skip
