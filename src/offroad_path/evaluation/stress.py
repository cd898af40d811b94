"""Stress sets: the hard cases, each a set of test worlds drawn to show it (offroad_path.world.held_out),
scored on its own against the mean-path prior and never pooled into the main figures.

A stress set's frames are its worlds' frames that show its condition (offroad_path.world.groups: shadow
and water together, dappled shade, off the track, a held-out look, a look outside the training
distribution). Each network's IoU (its training seeds pooled) minus the prior's, with a paired interval
from the hierarchical bootstrap of that set's own worlds, blocks and seeds.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from offroad_path.data.manifest import Sample
from offroad_path.evaluation.conditions import read_conditions
from offroad_path.evaluation.metrics import pooled
from offroad_path.evaluation.report import TestSet
from offroad_path.evaluation.tables import method_title, title
from offroad_path.evaluation.uncertainty import HierarchicalBootstrap
from offroad_path.statistics.bootstrap import Interval
from offroad_path.statistics.scores import iou as iou_score
from offroad_path.world.groups import GROUPS

TESTS = {key: test for key, _, test in GROUPS}


@dataclass
class StressRow:
    worlds: int
    frames: int  # test images (mirrored copies included)
    prior: float  # the mean-path prior's pooled IoU
    runs: dict[str, tuple[float, Interval | None]]  # run -> (pooled IoU, IoU minus the prior's [interval])


class StressSets:
    """The report section (evaluate): one row per stress set the test worlds hold."""

    def __init__(self, bootstrap_for: Callable[[list[Sample]], HierarchicalBootstrap]) -> None:
        self.bootstrap_for = bootstrap_for  # the hierarchical bootstrap of a set's own samples (uncertainty.test_bootstrap)
        self.rows: dict[str, StressRow] = {}

    def score(self, test: TestSet) -> None:
        if test.sets is None or test.main.all():
            return
        conditions = read_conditions(test.samples)
        for name in dict.fromkeys(s for s in test.sets if s in TESTS):
            shows = np.array([TESTS[name](row) for row in conditions], bool) if conditions else np.ones(len(test.samples), bool)
            part = test.subset((test.sets == name) & shows)
            if not part.samples:
                continue
            bootstrap = self.bootstrap_for(part.samples)
            runs = {}
            for run in part.runs:
                counts = np.stack(part.seed_counts[run, "no"])  # (S, N, 4)
                runs[run] = (pooled(counts.reshape(-1, 4)).iou, bootstrap.paired(counts, part.prior_counts, iou_score))
            worlds = len({s.sequence for s in part.samples})
            self.rows[name] = StressRow(worlds, len(part.samples), pooled(part.prior_counts).iou, runs)

    def markdown(self) -> str:
        return markdown(self.metrics().get("stress_sets", {}))

    def metrics(self) -> dict:
        def entry(row: StressRow) -> dict:
            found: dict = {"worlds": row.worlds, "frames": row.frames, "mean_path_prior": round(row.prior, 6)}
            for run, (value, margin) in row.runs.items():
                found[run] = {"iou": round(value, 6)}
                if margin is not None:
                    found[run] |= {"minus_prior": round(margin.estimate, 6), "low": round(margin.low, 6), "high": round(margin.high, 6)}
            return found

        return {"stress_sets": {name: entry(row) for name, row in self.rows.items()}} if self.rows else {}


MIN_WORLDS = 4  # a set scored on fewer worlds (those whose test frames show its case) is an example: no interval
INTRO = (
    "Each hard case is a set of test worlds drawn to show it, scored on its frames that show it and never pooled into "
    "the main test set's figures: the mean-path prior's IoU, then each network's IoU (raw maps, its seeds pooled) and its "
    "margin over the prior with a 95 % paired interval from the hierarchical bootstrap of the set's own worlds, blocks and "
    "seeds (few worlds: wide intervals). An interval that holds 0: no difference measured. A set whose case shows in fewer "
    f"than {MIN_WORLDS} of its worlds' test frames is an example: its IoUs alone, without a margin or interval."
)


def markdown(found: dict, heading: str = "\n## Stress sets\n\n") -> str:
    """The section from its metrics (metrics.json's "stress_sets"): the report and the README render the same table."""
    if not found:
        return ""
    runs = [key for key, value in next(iter(found.values())).items() if isinstance(value, dict)]
    lines = [
        heading + INTRO + "\n",
        "| stress set | worlds | test images | mean-path prior | " + " | ".join(method_title(r) for r in runs) + " |",
        "|" + " --- |" * (4 + len(runs)),
    ]
    for name, row in found.items():
        cells = [_cell(row[r]) if row["worlds"] >= MIN_WORLDS else f"{row[r]['iou']:.3f}" for r in runs]
        lines.append(f"| {title(name)} | {row['worlds']} | {row['frames']} | {row['mean_path_prior']:.3f} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def _cell(entry: dict) -> str:
    if "minus_prior" not in entry:
        return f"{entry['iou']:.3f}"
    return f"{entry['iou']:.3f}, {Interval(entry['minus_prior'], entry['low'], entry['high']).difference_text()}"
