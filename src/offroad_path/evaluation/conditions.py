"""Test results by condition: the test frames grouped by what the world knows about their next
metres of driving (`conditions.csv` of each rendered sequence, offroad_path.world.conditions), with
each network's pooled IoU per group, so a reader sees where a network fails (the paper's failure
cases are shadows, water and forks). Recordings without conditions.csv get no such table."""

from __future__ import annotations

import csv
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from offroad_path.data.manifest import Sample, parse_boolean
from offroad_path.evaluation.metrics import pooled
from offroad_path.evaluation.tables import fmt

SHADOW_FRACTION = 0.1  # of the corridor, for "shadow on the path"
# (key, title, test on a frame's conditions row): a frame may be in several groups.
CONDITIONS: list[tuple[str, str, Callable[[dict], bool]]] = [
    ("all", "all test frames", lambda r: True),
    ("shadow", f"shadow on the path (>= {SHADOW_FRACTION:.0%} of it)", lambda r: float(r["shadow"]) >= SHADOW_FRACTION),
    ("no_shadow", "no shadow on the path", lambda r: float(r["shadow"]) < SHADOW_FRACTION),
    ("water", "water on or near the path", lambda r: parse_boolean(r["water"])),
    ("fork", "a fork in view", lambda r: parse_boolean(r["fork"])),
    ("off_track", "off the track (mostly grass)", lambda r: r["surface"] == "grass"),
    ("paved", "paved road", lambda r: r["surface"] == "paved"),
    ("dirt", "dirt track", lambda r: r["surface"] == "dirt"),
    ("sharp_bend", "bend radius below 20 m", lambda r: float(r["bend_radius_m"]) < 20),
    ("bend", "bend radius 20 to 30 m", lambda r: 20 <= float(r["bend_radius_m"]) < 30),
    ("gentle", "bend radius 30 m or more", lambda r: float(r["bend_radius_m"]) >= 30),
]


def read_conditions(samples: list[Sample]) -> list[dict] | None:
    """Each sample's conditions row (mirrored copies share their frame's), from conditions.csv
    beside its sequence's image_l/; None when a sequence has none (real recordings)."""
    tables: dict[Path, list[dict] | None] = {}
    rows = []
    for sample in samples:
        root = Path(sample.image).parents[1]
        if root not in tables:
            path = root / "conditions.csv"
            tables[root] = list(csv.DictReader(path.open())) if path.is_file() else None
        table = tables[root]
        if table is None:
            return None
        if sample.f0 >= len(table) or int(table[sample.f0]["frame"]) != sample.f0:
            raise ValueError(f"{root / 'conditions.csv'}: has no row for frame {sample.f0}")
        rows.append(table[sample.f0])
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
    masks = [np.array([test(row) for row in conditions], bool) for _, _, test in CONDITIONS]
    iou = {m: [pooled(counts[mask]).iou if mask.any() else float("nan") for mask in masks] for m, counts in per_image.items()}
    return ConditionTable([k for k, _, _ in CONDITIONS], [t for _, t, _ in CONDITIONS], [int(m.sum()) for m in masks], iou)
