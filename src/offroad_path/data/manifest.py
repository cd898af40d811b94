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


def _sample(r: dict) -> Sample:
    return Sample(r["sequence"], int(r["f0"]), r["mirrored"] == "True", r["image"], r["label"], r["disparity"], r["semantic"],
                  float(r["fx"]), float(r["baseline_m"]))  # fmt: skip


def _rows(path: str | Path, columns: list[str], made_by: str) -> list[dict]:
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: manifest is missing (run the {made_by} stage first)")
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        if reader.fieldnames != columns:
            raise ValueError(f"{path}: columns {reader.fieldnames} differ from the expected {columns}")
        return list(reader)


def read_manifest(path: str | Path) -> list[Sample]:
    return [_sample(r) for r in _rows(path, COLUMNS, "split")]


# Confidence maps (written by `train`, `postprocess`): a split's samples with one .npy map each.
PREDICTION_COLUMNS = [*COLUMNS, "prediction"]


def prediction_name(sample: Sample) -> str:
    """Where a sample's map lives inside a predictions folder: <sequence>/NNNNNN[_mirrored].npy."""
    return f"{sample.sequence}/{sample.f0:06d}{'_mirrored' if sample.mirrored else ''}.npy"


def write_predictions_manifest(path: Path, rows: list[tuple[Sample, str]]) -> None:
    with open(path, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=PREDICTION_COLUMNS)
        writer.writeheader()
        writer.writerows({**asdict(sample), "prediction": prediction} for sample, prediction in rows)


def read_predictions_manifest(path: str | Path, made_by: str = "train") -> list[tuple[Sample, str]]:
    return [(_sample(r), r["prediction"]) for r in _rows(path, PREDICTION_COLUMNS, made_by)]
