"""The report's uncertainty section: a 95 % interval on every run's pooled IoU and a paired
interval on every comparison the results table invites (network against network without
pretraining, segmentation pretraining against none, post-processing against none), by the
hierarchical bootstrap of statistics.bootstrap (test worlds, their blocks of driving, training
seeds). A difference whose interval holds 0 is stated as "no difference measured"; the comparisons
evaluate.conclusions declares primary are tested with Holm's correction (statistics.primaries)."""

from __future__ import annotations

from collections.abc import Hashable
from dataclasses import dataclass
from itertools import combinations
from pathlib import Path

import numpy as np
from omegaconf import DictConfig

from offroad_path.config.evaluate_schema import EVERY_SCRATCH_VS_PRIOR
from offroad_path.data.labels import read_label_run
from offroad_path.data.manifest import Sample
from offroad_path.data.splitting import block_of
from offroad_path.errors import InputError
from offroad_path.evaluate.pixel_scores import pooled
from offroad_path.evaluate.scored_set import TestSet
from offroad_path.report.rendering import bootstrap_method, comparisons_markdown, seed_check_text
from offroad_path.report.tables import PP_KEY, grid, method_title, split_run_name, title
from offroad_path.statistics.bootstrap import Draws, Interval, Resampling, block_sums, paired_draws, score_draws, worlds_of
from offroad_path.statistics.scores import SCORES, Score, iou
from offroad_path.statistics.seed_check import FAILED_BELOW_MEDIAN, failed_seeds


def sample_blocks(samples: list[Sample], labels_dir: Path, block_m: float) -> list[tuple[str, int]]:
    """Each sample's block of driving, as the split formed them: (sequence, metres along its
    label run's poses // block_m); a mirrored copy is in its frame's block."""
    travelled = {run.name: run.distance() for run in read_label_run(labels_dir)}
    if missing := sorted({s.sequence for s in samples} - set(travelled)):
        raise InputError(labels_dir, f"holds no sequence {missing[0]} of the test manifest: give the label run the split was made from")
    return [block_of(s.sequence, travelled[s.sequence][s.f0], block_m) for s in samples]


@dataclass
class HierarchicalBootstrap:
    """The test set's blocks of driving (one label per item: (sequence, block), a sequence being one
    test world) and how to resample them: draws of any per-item statistic, (N, k) or per training
    seed (S, N, k), over all items or a subset (a condition group: only its blocks and worlds)."""

    blocks: list[Hashable]
    resampling: Resampling

    def _sums(self, per_item: np.ndarray, mask: np.ndarray | None) -> tuple[np.ndarray, list[Hashable]] | None:
        keep = np.ones(len(self.blocks), bool) if mask is None else mask
        blocks = [b for b, k in zip(self.blocks, keep, strict=True) if k]
        if len(set(blocks)) < 2:
            return None
        return block_sums(np.asarray(per_item)[..., keep, :], blocks), worlds_of(blocks)

    def draws(self, per_item: np.ndarray, score: Score, mask: np.ndarray | None = None) -> Draws | None:
        """None with fewer than 2 blocks to resample."""
        if (found := self._sums(per_item, mask)) is None:
            return None
        sums, worlds = found
        return score_draws(sums, score, self.resampling, worlds)

    def paired_draws(self, a: np.ndarray, b: np.ndarray, score: Score, mask: np.ndarray | None = None) -> Draws | None:
        if (found_a := self._sums(a, mask)) is None or (found_b := self._sums(b, mask)) is None:
            return None
        return paired_draws(found_a[0], found_b[0], score, self.resampling, worlds=found_a[1])

    def interval(self, per_item: np.ndarray, score: Score, mask: np.ndarray | None = None) -> Interval | None:
        found = self.draws(per_item, score, mask)
        return None if found is None else found.interval()

    def paired(self, a: np.ndarray, b: np.ndarray, score: Score, mask: np.ndarray | None = None) -> Interval | None:
        found = self.paired_draws(a, b, score, mask)
        return None if found is None else found.interval()

    @property
    def worlds(self) -> int:
        return len(set(worlds_of(self.blocks)))


def test_bootstrap(e: DictConfig, samples: list[Sample], block_m: float) -> HierarchicalBootstrap:
    """The hierarchical bootstrap of the test samples (evaluate.bootstrap; block_m: the split's)."""
    bootstrap = e.bootstrap
    return HierarchicalBootstrap(
        sample_blocks(samples, Path(e.labels_dir), block_m), Resampling(bootstrap.resamples, bootstrap.seed, bootstrap.level)
    )


Side = tuple[str, str]  # a run and its post-processing ("no" / "yes")
PRIOR: Side = ("mean_path_prior", "no")


def comparisons(runs: list[str]) -> list[tuple[str, Side, Side]]:
    """(metrics key, a, b): the differences a - b the report states (titled by tables.comparison_title)."""
    scratch = [r for r in runs if split_run_name(r)[1] == "none"]
    pairs = [(f"{run}_vs_mean_path_prior", (run, "no"), PRIOR) for run in scratch]
    pairs += [(f"{a}_vs_{b}", (a, "no"), (b, "no")) for a, b in combinations(scratch, 2)]
    for run in runs:
        model, pretraining = split_run_name(run)
        if pretraining != "none" and f"{model}-none" in runs:
            pairs.append((f"{run}_vs_{model}-none", (run, "no"), (f"{model}-none", "no")))
    pairs += [(f"{run}_postprocessed_vs_raw", (run, "yes"), (run, "no")) for run in runs]
    return pairs


def weakest_of(draws: dict[str, Draws]) -> str:
    """The comparison an intersection-union test of "each is above 0" rests on: one whose estimate is not
    above 0 (the lowest), else the one with the largest p-value."""
    if below := [key for key, d in draws.items() if d.estimate <= 0]:
        return min(below, key=lambda key: draws[key].estimate)
    return max(draws, key=lambda key: (draws[key].p_value(), -draws[key].estimate))  # ties (the least p resamples show): the smaller


class Uncertainty:
    """95 % hierarchical-bootstrap intervals (evaluate.bootstrap) on every run's IoU and on the comparisons."""

    def __init__(self, bootstrap: HierarchicalBootstrap, block_m: float) -> None:
        self.bootstrap, self.block_m = bootstrap, block_m
        self.resampling = bootstrap.resampling
        self.blocks = len(set(bootstrap.blocks))
        self.seeds: list[int] = []
        self.weakest = ""  # the central claim's weakest comparison against the prior (<run>_vs_mean_path_prior)
        self.intervals: dict[tuple[str, str], Interval] = {}
        self.others: dict[tuple[str, str], dict[str, Interval]] = {}  # precision, recall, accuracy
        self.over_seeds: dict[tuple[str, str], tuple[float, float]] = {}  # (mean, sample sd) of the seeds' IoU, with several
        self.failed: dict[str, list[int]] = {}  # network (raw maps) -> its seeds far below its others (seed_check)
        self.differences: dict[str, Interval] = {}  # metrics key -> a - b
        self.draws: dict[str, Draws] = {}  # metrics key -> the difference's resamples (for the primaries)

    def score(self, test: TestSet) -> None:
        self.seeds = test.seeds
        if self.blocks < 2:  # nothing to resample: the section says so
            return
        if len(test.seeds) > 1:
            for key, per_seed in test.seed_counts.items():
                ious = [pooled(c).iou for c in per_seed]
                self.over_seeds[key] = (float(np.mean(ious)), float(np.std(ious, ddof=1)))
                if key[1] == "no" and (failed := failed_seeds(dict(zip(test.seeds, ious, strict=True)))):
                    self.failed[key[0]] = failed
        b = self.bootstrap
        per_seed = {key: np.stack(seeds) for key, seeds in test.seed_counts.items()}  # (S, N, 4)
        self.intervals = {key: b.interval(counts, iou) for key, counts in per_seed.items()}
        self.others = {
            key: {name: b.interval(counts, score) for name, score in SCORES.items() if name != "iou"} for key, counts in per_seed.items()
        }
        sides = per_seed | {PRIOR: test.prior_counts}
        for key, x, y in comparisons(test.runs):
            self.draws[key] = b.paired_draws(sides[x], sides[y], iou)
            self.differences[key] = self.draws[key].interval()
        against_prior = [key for key, _, y in comparisons(test.runs) if y == PRIOR]
        if against_prior:
            self.weakest = weakest_of({key: self.draws[key] for key in against_prior})
            self.draws[EVERY_SCRATCH_VS_PRIOR] = self.draws[self.weakest]
            self.differences[EVERY_SCRATCH_VS_PRIOR] = self.draws[EVERY_SCRATCH_VS_PRIOR].interval()

    def markdown(self) -> str:
        r = self.resampling
        if self.blocks < 2:
            return f"\n## Uncertainty\n\nThe test set is {self.blocks} block of {self.block_m:g} m of driving: no interval can be drawn.\n"
        lines = [
            "\n## Uncertainty\n",
            bootstrap_method(r, self.bootstrap.worlds, self.blocks, self.block_m, len(self.seeds))
            + " An interval that holds 0: no difference measured. These comparisons are exploratory except those "
            "evaluate.conclusions declares primary (the Primary questions section).\n",
        ]
        runs = list(dict.fromkeys(run for run, _ in self.intervals))
        others = [name for name in SCORES if name != "iou"]
        lines += [
            "Each IoU's interval, and with several training seeds the mean and standard deviation of the seeds' own IoU, are "
            "in the results table above; here the other scores' intervals (raw maps) and the comparisons.\n",
        ]
        if len(self.seeds) > 1:
            lines.append(seed_check_text(self.failed, FAILED_BELOW_MEDIAN) + "\n")
        header = ["method (raw)", *(f"{title(name)} [95 % interval]" for name in others)]
        rows = [[method_title(run), *(self.others[run, "no"][name].text() for name in others)] for run in runs]
        return "\n".join([*lines, grid(header, rows)]) + "\n\n" + comparisons_markdown(self.metrics()["uncertainty"])

    def metrics(self) -> dict:
        def entry(i: Interval, name: str) -> dict:
            return {name: round(i.estimate, 6), "low": round(i.low, 6), "high": round(i.high, 6)}

        intervals = {f"{run}.{PP_KEY[pp]}": entry(i, "iou") for (run, pp), i in self.intervals.items()}
        for (run, pp), others in self.others.items():
            intervals[f"{run}.{PP_KEY[pp]}"] |= {name: entry(i, "estimate") for name, i in others.items()}
        for (run, pp), (mean, sd) in self.over_seeds.items():
            intervals[f"{run}.{PP_KEY[pp]}"] |= {"seed_mean": round(mean, 6), "seed_sd": round(sd, 6)}
        differences = {key: entry(i, "iou_difference") for key, i in self.differences.items()}
        test_set = {"worlds": self.bootstrap.worlds, "blocks": self.blocks, "seeds": len(self.seeds)}
        checked = {"failed_seeds": self.failed} if len(self.seeds) > 1 else {}
        return {"uncertainty": {"test_set": test_set, **checked, **intervals, **differences}}
