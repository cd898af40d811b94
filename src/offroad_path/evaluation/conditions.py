"""Test results by condition: the test frames grouped by what the world knows about their next
metres of driving (`conditions.csv` of each rendered sequence, offroad_path.world.conditions), with
each network's pooled IoU per group, so a reader sees where a network fails (the paper's failure
cases are shadows, water and forks). Recordings without conditions.csv get no such table."""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from offroad_path.data.manifest import Sample, parse_boolean
from offroad_path.evaluation.metrics import pooled
from offroad_path.evaluation.tables import fmt
from offroad_path.world.groups import GROUPS


def parse_row(row: dict[str, str]) -> dict:
    """A conditions.csv row with its columns typed as frame_conditions writes them."""
    return {"frame": int(row["frame"]), "shadow": float(row["shadow"]), "water": parse_boolean(row["water"]),
            "fork": parse_boolean(row["fork"]), "surface": row["surface"], "bend_radius_m": float(row["bend_radius_m"])}  # fmt: skip


def read_conditions(samples: list[Sample]) -> list[dict] | None:
    """Each sample's conditions row (mirrored copies share their frame's), from conditions.csv
    beside its sequence's image_l/; None when a sequence has none (real recordings)."""
    tables: dict[Path, list[dict] | None] = {}
    rows = []
    for sample in samples:
        root = Path(sample.image).parents[1]
        if root not in tables:
            path = root / "conditions.csv"
            tables[root] = _read_table(path) if path.is_file() else None
        table = tables[root]
        if table is None:
            return None
        if sample.f0 >= len(table) or table[sample.f0]["frame"] != sample.f0:
            raise ValueError(f"{root / 'conditions.csv'}: has no row for frame {sample.f0}")
        rows.append(table[sample.f0])
    return rows


def _read_table(path: Path) -> list[dict]:
    rows = []
    for number, row in enumerate(csv.DictReader(path.open()), start=2):
        try:
            rows.append(parse_row(row))
        except (KeyError, TypeError, ValueError) as e:
            raise ValueError(f"{path}: line {number}: {e}") from None
    return rows


@dataclass
class ConditionTable:
    """Pooled IoU per condition (rows) and per method (columns)."""

    keys: list[str]
    titles: list[str]
    frames: list[int]  # test images in each group
    iou: dict[str, list[float]]  # method -> IoU per condition (nan for an empty group)

    def markdown(self) -> str:
        methods = list(self.iou)
        lines = ["| condition | test images | " + " | ".join(methods) + " |", "|" + " --- |" * (2 + len(methods))]
        for i, title in enumerate(self.titles):
            lines.append(f"| {title} | {self.frames[i]} | " + " | ".join(fmt(self.iou[m][i]) for m in methods) + " |")
        return "\n".join(lines) + "\n"

    def metrics(self, method_keys: dict[str, str]) -> dict:
        """{condition key: {'frames': n, <method key>: IoU or None}} for metrics.json."""
        return {
            key: {"frames": self.frames[i]} | {method_keys[m]: (None if v[i] != v[i] else round(v[i], 6)) for m, v in self.iou.items()}
            for i, key in enumerate(self.keys)
        }


def by_condition(conditions: list[dict], per_image: dict[str, np.ndarray]) -> ConditionTable:
    """per_image: method -> its (N, 4) per-image counts [tp, fp, tn, fn] over the same samples."""
    masks = [np.array([test(row) for row in conditions], bool) for _, _, test in GROUPS]
    iou = {m: [pooled(counts[mask]).iou if mask.any() else float("nan") for mask in masks] for m, counts in per_image.items()}
    return ConditionTable([k for k, _, _ in GROUPS], [t for _, t, _ in GROUPS], [int(m.sum()) for m in masks], iou)
