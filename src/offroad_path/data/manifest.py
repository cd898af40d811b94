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
    disparity: str  # KITTI format: uint16 of 256 x disparity, 0 unknown; empty for a recording of one camera
    semantic: str  # class ids 0..7; empty for real recordings
    fx: float
    baseline_m: float  # 0 for one camera


COLUMNS = [f.name for f in fields(Sample)]


def write_manifest(path: Path, samples: list[Sample]) -> None:
    with open(path, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=COLUMNS)
        writer.writeheader()
        writer.writerows(asdict(s) for s in samples)


BOOLEANS = {"true": True, "false": False, "1": True, "0": False}  # any case: spreadsheets write TRUE


def parse_boolean(value: str) -> bool:
    if value.strip().lower() not in BOOLEANS:
        raise ValueError(f"{value!r} is not true, false, 1 or 0")
    return BOOLEANS[value.strip().lower()]


def _sample(path: Path, number: int, r: dict) -> Sample:
    """Row `number` of the manifest at `path` as a Sample; ValueError naming row and column."""
    column = "sequence"
    try:
        values = {}
        for column, parse in (("f0", int), ("mirrored", parse_boolean), ("fx", float), ("baseline_m", float)):
            values[column] = parse(r[column])
        return Sample(
            r["sequence"],
            values["f0"],
            values["mirrored"],
            r["image"],
            r["label"],
            r["disparity"],
            r["semantic"],
            values["fx"],
            values["baseline_m"],
        )
    except (KeyError, ValueError, TypeError, AttributeError) as e:
        raise ValueError(f"{path}: row {number}, column {column}: {e}") from e


def _rows(path: str | Path, columns: list[str], made_by: str) -> list[dict]:
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: manifest is missing (run the {made_by} stage first)")
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        if reader.fieldnames != columns:
            raise ValueError(f"{path}: columns {reader.fieldnames} differ from the expected {columns}")
        return list(reader)


def manifest_folders(path: str | Path) -> list[Path]:
    """The recordings and label runs a manifest's rows point into, for the output rule
    (utils.outputs). Empty when the manifest cannot be read: the stage reports that."""
    folders: set[Path] = set()
    try:
        with open(path, newline="") as f:
            for row in csv.DictReader(f):
                for column in ("image", "semantic", "label", "disparity"):
                    if row.get(column):
                        folders.add(_container(Path(row[column])))
    except (OSError, csv.Error, UnicodeDecodeError):
        return []
    return sorted(folders)


def _container(file: Path) -> Path:
    """The recording or label run a listed file belongs to, by the layouts the project writes; the
    file's own folder for any other layout."""
    folder = file.parent
    if folder.name in ("label", "disparity"):  # <run>/<sequence>/label/NNNNNN.png
        return folder.parent.parent
    return folder.parent if folder.name in ("image_l", "image_2", "image_0", "semantic") else folder


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
    return [_sample(path, number, r) for number, r in enumerate(rows, start=2)]


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
    return [(_sample(path, number, r), r["prediction"]) for number, r in enumerate(rows, start=2)]
