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
from offroad_path.evaluate.by_condition import read_conditions
from offroad_path.evaluate.pixel_scores import pooled
from offroad_path.evaluate.scored_set import TestSet
from offroad_path.evaluate.uncertainty import HierarchicalBootstrap
from offroad_path.report.rendering import stress_markdown
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
        return stress_markdown(self.metrics().get("stress_sets", {}))

    def metrics(self) -> dict:
        def entry(row: StressRow) -> dict:
            found: dict = {"worlds": row.worlds, "frames": row.frames, "mean_path_prior": round(row.prior, 6)}
            for run, (value, margin) in row.runs.items():
                found[run] = {"iou": round(value, 6)}
                if margin is not None:
                    found[run] |= {"minus_prior": round(margin.estimate, 6), "low": round(margin.low, 6), "high": round(margin.high, 6)}
            return found

        return {"stress_sets": {name: entry(row) for name, row in self.rows.items()}} if self.rows else {}
