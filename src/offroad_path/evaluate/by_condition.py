"""Test results by condition: the test frames grouped by what the world knows about their next
metres of driving (`conditions.csv` of each rendered sequence, offroad_path.world.conditions), with
each network's pooled IoU per group, so a reader sees where a network fails (the paper's failure
cases are shadows, water and forks). Recordings without conditions.csv get no such table."""

from __future__ import annotations

import csv
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from offroad_path.data.manifest import Sample, parse_boolean
from offroad_path.evaluate.pixel_scores import pooled
from offroad_path.statistics.bootstrap import Interval
from offroad_path.statistics.scores import iou as iou_score
from offroad_path.world.groups import GROUPS, SINGLE_LOOK

if TYPE_CHECKING:
    from offroad_path.evaluate.uncertainty import HierarchicalBootstrap


def parse_row(row: dict[str, str]) -> dict:
    """A conditions.csv row with its columns typed as frame_conditions writes them."""
    return {
        "frame": int(row["frame"]),
        "shadow": float(row["shadow"]),
        "water": parse_boolean(row["water"]),
        "fork": parse_boolean(row["fork"]),
        "surface": row["surface"],
        "bend_radius_m": float(row["bend_radius_m"]),
    } | {k: row.get(k) or v for k, v in SINGLE_LOOK.items()}  # rendered without world.appearance: its single look


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

    keys: list[str]  # the condition groups (world.groups.GROUPS)
    frames: list[int]  # test images in each group
    iou: dict[str, list[float]]  # method -> IoU per condition (nan for an empty group)
    sequences: list[int] = field(default_factory=list)  # test sequences each group's frames come from
    intervals: dict[str, list[Interval | None]] = field(default_factory=dict)  # method -> per condition; None: < 2 blocks
    minus_baseline: dict[str, list[Interval | None]] = field(default_factory=dict)  # method -> its IoU minus the baseline's, paired

    def metrics(self, method_keys: dict[str, str]) -> dict:
        """{condition key: {'frames': n, 'sequences': n, <method key>: IoU or None, <method key>.interval: [low, high]}}."""
        out = {}
        for i, key in enumerate(self.keys):
            row = {"frames": self.frames[i]} | ({"sequences": self.sequences[i]} if self.sequences else {})
            for m, v in self.iou.items():
                row[method_keys[m]] = None if v[i] != v[i] else round(v[i], 6)
                if (found := self.intervals.get(m, [None] * len(self.keys))[i]) is not None:
                    row[f"{method_keys[m]}.interval"] = [round(found.low, 6), round(found.high, 6)]
                if (gap := self.minus_baseline.get(m, [None] * len(self.keys))[i]) is not None:
                    row[f"{method_keys[m]}.minus_prior"] = [round(gap.estimate, 6), round(gap.low, 6), round(gap.high, 6)]
            out[key] = row
        return out


def by_condition(
    conditions: list[dict],
    per_image: dict[str, np.ndarray],
    bootstrap: HierarchicalBootstrap | None = None,
    sequences: list[str] | None = None,
    baseline: str | None = None,
) -> ConditionTable:
    """per_image: method -> its (N, 4) per-image counts [tp, fp, tn, fn] over the same samples, or per
    training seed (S, N, 4); bootstrap: intervals over each group's worlds, blocks and seeds;
    sequences: each sample's, to count them per group; baseline: the method (of per_image) every other
    is compared with in each group, paired on the same draws (the mean path prior)."""
    masks = [np.array([test(row) for row in conditions], bool) for _, _, test in GROUPS]
    iou = {
        m: [pooled(counts[..., mask, :].reshape(-1, 4)).iou if mask.any() else float("nan") for mask in masks]
        for m, counts in per_image.items()
    }
    table = ConditionTable([k for k, _, _ in GROUPS], [int(m.sum()) for m in masks], iou)
    if sequences is not None:
        table.sequences = [len({s for s, keep in zip(sequences, mask, strict=True) if keep}) for mask in masks]
    if bootstrap is not None:
        table.intervals = {m: [bootstrap.interval(counts, iou_score, mask) for mask in masks] for m, counts in per_image.items()}
        if baseline is not None:
            table.minus_baseline = {
                m: [bootstrap.paired(counts, per_image[baseline], iou_score, mask) for mask in masks]
                for m, counts in per_image.items()
                if m != baseline
            }
    return table
