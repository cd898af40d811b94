"""The report's uncertainty section: a 95 % interval on every run's pooled IoU and a paired
interval on every comparison the results table invites (network against network without
pretraining, segmentation pretraining against none, post-processing against none), by resampling
the test set's blocks of driving (evaluation.bootstrap). A difference whose interval holds 0 is
stated as "no difference measured"."""

from __future__ import annotations

from itertools import combinations
from pathlib import Path

import numpy as np
from omegaconf import DictConfig

from offroad_path.data.labels import read_label_run
from offroad_path.data.manifest import Sample
from offroad_path.data.splitting import block_of
from offroad_path.evaluation.bootstrap import Interval, Resampling, block_sums, interval, iou, paired_interval
from offroad_path.evaluation.metrics import pooled
from offroad_path.evaluation.report import POSTPROCESSING, PP_KEY, TestSet
from offroad_path.evaluation.tables import method_title, split_run_name


def sample_blocks(samples: list[Sample], labels_dir: Path, block_m: float) -> list[tuple[str, int]]:
    """Each sample's block of driving, as the split formed them: (sequence, metres along its
    label run's poses // block_m); a mirrored copy is in its frame's block."""
    travelled = {run.name: run.distance() for run in read_label_run(labels_dir)}
    return [block_of(s.sequence, travelled[s.sequence][s.f0], block_m) for s in samples]


Side = tuple[str, str]  # a run and its post-processing ("no" / "yes")


def comparisons(runs: list[str]) -> list[tuple[str, str, Side, Side]]:
    """(metrics key, title, a, b): the differences a - b the report states."""
    pairs = []
    scratch = [r for r in runs if split_run_name(r)[1] == "none"]
    for a, b in combinations(scratch, 2):
        pairs.append((f"{a}_vs_{b}", f"{method_title(a)} - {method_title(b)}", (a, "no"), (b, "no")))
    for run in runs:
        model, pretraining = split_run_name(run)
        if pretraining != "none" and f"{model}-none" in runs:
            base = f"{model}-none"
            pairs.append((f"{run}_vs_{base}", f"{method_title(run)} - {method_title(base)}", (run, "no"), (base, "no")))
    for run in runs:
        pairs.append((f"{run}_postprocessed_vs_raw", f"{method_title(run)}: post-processed - raw", (run, "yes"), (run, "no")))
    return pairs


class Uncertainty:
    """95 % block-bootstrap intervals (evaluate.bootstrap) on every run's IoU and on the comparisons."""

    def __init__(self, e: DictConfig, block_m: float) -> None:
        self.e, self.block_m = e, block_m
        self.resampling = Resampling(e.bootstrap.resamples, e.bootstrap.seed, e.bootstrap.level)
        self.blocks = 0
        self.seeds: list[int] = []
        self.intervals: dict[tuple[str, str], Interval] = {}
        self.over_seeds: dict[tuple[str, str], tuple[float, float]] = {}  # (mean, sample sd) of the seeds' IoU, with several
        self.differences: list[tuple[str, str, Interval]] = []  # (metrics key, title, a - b)

    def score(self, test: TestSet) -> None:
        self.seeds = test.seeds
        blocks = sample_blocks(test.samples, Path(self.e.labels_dir), self.block_m)
        self.blocks = len(set(blocks))
        if self.blocks < 2:  # nothing to resample: the section says so
            return
        if len(test.seeds) > 1:
            for key, per_seed in test.seed_counts.items():
                ious = [pooled(c).iou for c in per_seed]
                self.over_seeds[key] = (float(np.mean(ious)), float(np.std(ious, ddof=1)))
        sums = {key: block_sums(counts, blocks) for key, counts in test.counts.items()}
        self.intervals = {key: interval(s, iou, self.resampling) for key, s in sums.items()}
        self.differences = [
            (key, title, paired_interval(sums[a], sums[b], iou, self.resampling)) for key, title, a, b in comparisons(test.runs)
        ]

    def markdown(self) -> str:
        r = self.resampling
        if self.blocks < 2:
            return f"\n## Uncertainty\n\nThe test set is {self.blocks} block of {self.block_m:g} m of driving: no interval can be drawn.\n"
        lines = [
            "\n## Uncertainty\n",
            f"{r.level:.0%} percentile intervals from {r.count} resamples (seed {r.seed}) of the test set's {self.blocks} blocks of "
            f"{self.block_m:g} m of driving, drawn with replacement; a comparison scores both methods on the same resamples "
            "(paired). An interval that holds 0: no difference measured.\n",
        ]
        runs = list(dict.fromkeys(run for run, _ in self.intervals))
        columns = ["IoU, raw [95 % interval]", "IoU, post-processed [95 % interval]"]
        if self.over_seeds:
            lines.append(f"Each method's counts are pooled over its {len(self.seeds)} training seeds ({', '.join(map(str, self.seeds))}), "
                         "and a comparison pairs them seed by seed on each resample; beside each interval, the mean and sample "
                         "standard deviation of the seeds' own IoU.\n")  # fmt: skip
            columns = [columns[0], "raw, over seeds", columns[1], "post-processed, over seeds"]
        lines += ["| method | " + " | ".join(columns) + " |", "|" + " --- |" * (1 + len(columns))]
        lines += [f"| {method_title(run)} | " + " | ".join(self._cells(run, pp) for pp in POSTPROCESSING) + " |" for run in runs]
        lines += ["", "| comparison (IoU, a - b) | difference [95 % interval] |", "| --- | --- |"]
        lines += [f"| {title} | {difference.difference_text()} |" for _, title, difference in self.differences]
        return "\n".join(lines) + "\n"

    def _cells(self, run: str, pp: str) -> str:
        text = self.intervals[run, pp].text()
        if (run, pp) not in self.over_seeds:
            return text
        mean, sd = self.over_seeds[run, pp]
        return f"{text} | {mean:.3f} ± {sd:.3f}"

    def metrics(self) -> dict:
        def entry(i: Interval, name: str) -> dict:
            return {name: round(i.estimate, 6), "low": round(i.low, 6), "high": round(i.high, 6)}

        intervals = {f"{run}.{PP_KEY[pp]}": entry(i, "iou") for (run, pp), i in self.intervals.items()}
        for (run, pp), (mean, sd) in self.over_seeds.items():
            intervals[f"{run}.{PP_KEY[pp]}"] |= {"seed_mean": round(mean, 6), "seed_sd": round(sd, 6)}
        differences = {key: entry(i, "iou_difference") for key, _, i in self.differences}
        test_set = {"blocks": self.blocks, "seeds": len(self.seeds)}
        return {"uncertainty": {"test_set": test_set, **intervals, **differences}}
