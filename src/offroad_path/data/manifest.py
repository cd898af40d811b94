"""Manifests: the CSV files that list a split's samples (written by `split`, read by training)."""

from __future__ import annotations

import csv
import json
import os
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


def data_root(paths: list[str | Path]) -> str:
    """The deepest folder holding all `paths`: relative to the working directory when inside it, so
    that a split made in one checkout reads the same in another."""
    common = Path(os.path.commonpath([Path(p).resolve() for p in paths]))
    return str(common.relative_to(Path.cwd())) if common.is_relative_to(Path.cwd()) else str(common)


def _check_inside(path: Path, row: int, column: str, value: str, root: Path) -> None:
    if value and not Path(value).resolve().is_relative_to(root.resolve()):
        raise ValueError(f"{path}: row {row}, {column} {value!r} lies outside the data root {root}; refused")


def read_manifest(path: str | Path, check_files: bool = False) -> list[Sample]:
    """A split manifest's samples. Every path in it must lie inside the data root the split stage
    recorded beside it (summary.json), and with check_files, exist."""
    path = Path(path)
    rows = _rows(path, COLUMNS, "split")
    summary = path.parent / "summary.json"
    root = json.loads(summary.read_text()).get("data_root") if summary.is_file() else None
    for number, r in enumerate(rows, start=2):
        for column in ("image", "label", "disparity", "semantic"):
            if root is not None:
                _check_inside(path, number, column, r[column], Path(root))
            if check_files and r[column] and not Path(r[column]).is_file():
                raise FileNotFoundError(f"{path}: row {number}, {column} {r[column]} does not exist")
    try:
        return [_sample(r) for r in rows]
    except (KeyError, ValueError) as e:
        raise ValueError(f"{path}: a row is malformed ({e})") from e


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
    """Samples and their map files; every map must lie inside the manifest's own folder."""
    path = Path(path)
    rows = _rows(path, PREDICTION_COLUMNS, made_by)
    for number, r in enumerate(rows, start=2):
        _check_inside(path, number, "prediction", r["prediction"], path.parent)
    try:
        return [(_sample(r), r["prediction"]) for r in rows]
    except (KeyError, ValueError) as e:
        raise ValueError(f"{path}: a row is malformed ({e})") from e
