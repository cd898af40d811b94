"""The evaluate stage's report: the test set and every run's maps, read once (TestSet), then a list
of sections (offroad_path.evaluate.sections), each of which scores what it needs and writes its
part of results.md and metrics.json. Here: reading the test set, and writing the report."""

from __future__ import annotations

import functools
import json
import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import numpy as np
from omegaconf import DictConfig

from offroad_path.data.loading import load_labels, load_maps
from offroad_path.data.manifest import Sample, read_manifest, read_predictions_manifest
from offroad_path.errors import InputError
from offroad_path.evaluate.design import design_record
from offroad_path.evaluate.figures import save_png
from offroad_path.evaluate.pixel_scores import counts, mean_path, precision_recall_curve
from offroad_path.report.tables import csv_text
from offroad_path.sequence import meta as meta_keys
from offroad_path.utils.atomic import atomic_directory, write_text_atomic

log = logging.getLogger(__name__)
POSTPROCESSING = ("no", "yes")


@dataclass
class TestSet:
    """The test frames, their labels and every run's confidence maps, read in one pass over the runs
    (a run's maps are loaded once, raw and post-processed): what the sections score."""

    runs: list[str]
    seeds: list[int]  # each run's training seeds; the first one's network runs where a section needs one
    samples: list[Sample]
    labels: np.ndarray  # (N, H, W) bool
    paths: dict[tuple[str, str], list[str]]  # (run, post-processing "no"/"yes") -> its map files, one per sample
    counts: dict[tuple[str, str], np.ndarray]  # (run, post-processing) -> (N, 4) per-image [tp, fp, tn, fn], summed over seeds
    seed_counts: dict[tuple[str, str], list[np.ndarray]]  # the same per seed
    predicted: dict[str, np.ndarray]  # run -> (N, H, W) bool: its first seed's raw map above the threshold
    seed_predicted: dict[str, list[np.ndarray]]  # run -> the same for every seed, the first one first
    curves: dict[str, dict[str, np.ndarray]]  # run -> precision-recall curve of its first seed's raw maps
    prior: np.ndarray  # (H, W) bool: the mean training label above the threshold
    threshold: float  # path where confidence > threshold (evaluate.threshold)
    colour: np.ndarray | None = None  # (N, H, W) float32: the colour baseline's path probability (evaluate.colour); None: off
    sets: np.ndarray | None = None  # (N,) each sample's test set (sample_test_sets): main or a stress set's name

    @property
    def main(self) -> np.ndarray:
        """(N,) bool: the samples of the main test set (a recording that names no test set is in it)."""
        sets = np.full(len(self.samples), meta_keys.MAIN, dtype=object) if self.sets is None else self.sets
        return sets == meta_keys.MAIN

    @classmethod
    def read(cls, e: DictConfig) -> TestSet:
        """Every run of evaluate.runs at every seed of evaluate.seeds, raw (train) and post-processed;
        all must list the same samples."""
        samples: list[Sample] = []
        labels, sets, main = np.zeros(0), np.zeros(0, dtype=object), np.zeros(0, bool)
        paths, per_seed, predicted, curves = {}, {}, {}, {}
        seed_predicted: dict[str, list[np.ndarray]] = {}
        for run in e.runs:
            for seed in e.seeds:
                folder = f"{run}/seed{seed}"
                for pp, manifest, made_by in (
                    ("no", Path(e.runs_dir) / folder / "predictions" / "manifest.csv", "train"),
                    ("yes", Path(e.postprocessed_dir) / folder / "manifest.csv", "postprocess"),
                ):
                    if not manifest.is_file():
                        raise InputError(
                            manifest,
                            f"missing: evaluate.seeds lists seed {seed}; run {made_by} seed={seed} for {run}, or list only seeds trained",
                        )
                    rows = read_predictions_manifest(manifest, made_by)
                    if samples and [s for s, _ in rows] != samples:
                        raise ValueError(f"{manifest}: lists other test samples than the runs before it (retrain on the same split)")
                    samples = [s for s, _ in rows]
                    if not len(labels):
                        labels = load_labels(samples)
                        sets = sample_test_sets(samples)
                        main = sets == meta_keys.MAIN
                    maps = load_maps([p for _, p in rows])
                    per_seed.setdefault((run, pp), []).append(counts(maps, labels, e.threshold))
                    if pp == "no":
                        seed_predicted.setdefault(run, []).append(maps > e.threshold)
                    if seed == e.seeds[0]:
                        paths[run, pp] = [p for _, p in rows]
                        if pp == "no":
                            predicted[run] = seed_predicted[run][0]
                            curves[run] = precision_recall_curve(maps[main], labels[main], e.pr_thresholds)  # the main test set's
        train = read_manifest(e.train_manifest)
        prior = mean_path(load_labels(train)) > e.threshold
        colour = _colour_maps(e, train, samples, labels.shape[1:])
        summed = {key: np.sum(seeds, axis=0) for key, seeds in per_seed.items()}
        return cls(
            list(e.runs),
            list(e.seeds),
            samples,
            labels,
            paths,
            summed,
            per_seed,
            predicted,
            seed_predicted,
            curves,
            prior,
            e.threshold,
            colour,
            sets,
        )

    def subset(self, keep: np.ndarray) -> TestSet:
        """The same runs on the samples where `keep` (N,) holds: a test set of its own (the prior stays the training set's)."""
        index = np.flatnonzero(keep)
        paths = {key: [files[i] for i in index] for key, files in self.paths.items()}
        part = TestSet(
            self.runs,
            self.seeds,
            [self.samples[i] for i in index],
            self.labels[index],
            paths,
            {key: c[index] for key, c in self.counts.items()},
            {key: [c[index] for c in seeds] for key, seeds in self.seed_counts.items()},
            {run: p[index] for run, p in self.predicted.items()},
            {run: [p[index] for p in seeds] for run, seeds in self.seed_predicted.items()},
            self.curves,
            self.prior,
            self.threshold,
            None if self.colour is None else self.colour[index],
            None if self.sets is None else self.sets[index],
        )
        for cached in ("prior_counts", "colour_counts"):  # computed once, on the whole test set
            if cached in self.__dict__:
                part.__dict__[cached] = None if self.__dict__[cached] is None else self.__dict__[cached][index]
        return part

    def checkpoint(self, runs_dir: str | Path, run: str) -> Path:
        """The network of `run` that sections run on frames of their own (its first seed's)."""
        return Path(runs_dir) / run / f"seed{self.seeds[0]}" / "checkpoints" / "best.ckpt"

    @functools.cached_property
    def prior_counts(self) -> np.ndarray:
        """(N, 4) per-image counts of the mean path prior painted on every test frame (baselines, conditions)."""
        return counts(np.broadcast_to(self.prior, self.labels.shape).astype(np.float32), self.labels, self.threshold)

    @functools.cached_property
    def colour_counts(self) -> np.ndarray | None:
        """(N, 4) per-image counts of the colour baseline (None when evaluate.colour_baseline_pixels is 0)."""
        return None if self.colour is None else counts(self.colour, self.labels, self.threshold)


def sample_test_sets(samples: list[Sample]) -> np.ndarray:
    """(N,) each sample's test set: its recording's meta.json "test_set" (main when it has none or no meta.json)."""
    found: dict[Path, str] = {}
    for sample in samples:
        root = Path(sample.image).parents[1]
        if root not in found:
            path = root / "meta.json"
            found[root] = meta_keys.test_set(json.loads(path.read_text())) if path.is_file() else meta_keys.MAIN
    return np.array([found[Path(s.image).parents[1]] for s in samples], dtype=object)


def _colour_maps(e: DictConfig, train: list[Sample], test: list[Sample], shape: tuple[int, int]) -> np.ndarray | None:
    """The colour baseline's path probabilities on the test frames, fitted on the training frames (None when off)."""
    if not e.colour_baseline_pixels:
        return None
    from offroad_path.evaluate.colour import ColourBaseline  # scikit-learn: only when asked for

    return ColourBaseline(e.colour_baseline_pixels, e.bootstrap.seed).fit(train).predict(test, shape)


class Section(Protocol):
    """One part of the report: `score` once, then its Markdown (for results.md) and its metrics
    (keys of metrics.json and of the MLflow run; numbers only, None where undefined)."""

    def score(self, test: TestSet) -> None: ...

    def markdown(self) -> str: ...

    def metrics(self) -> dict: ...


def report_metrics(sections: list[Section]) -> dict:
    return {key: value for section in sections for key, value in section.metrics().items()}


def write_report(e: DictConfig, test: TestSet, sections: list[Section], table: list, figures: dict[str, np.ndarray]) -> None:
    """evaluate.out_dir (results.md from the sections in order, results.csv of `table`, figures/),
    evaluate.plots_dir (each run's precision-recall curve), evaluate.metrics_path."""
    with atomic_directory(e.out_dir, "evaluate", key="evaluate.out_dir") as tmp:
        notice = f"> **{e.notice}**\n\n" if e.notice else ""
        (tmp / "results.md").write_text(notice + "".join(section.markdown() for section in sections))
        (tmp / "results.csv").write_text(csv_text(table))
        for name, image in figures.items():
            save_png(tmp / "figures" / name, image)
    with atomic_directory(e.plots_dir, "evaluate", key="evaluate.plots_dir") as tmp:
        for run, curve in test.curves.items():
            lines = ["threshold,precision,recall"] + [f"{t:.4f},{p:.6f},{r:.6f}" for t, p, r in zip(*curve.values(), strict=True)]
            (tmp / f"{run}.csv").write_text("\n".join(lines) + "\n")
        metrics = ({"notice": e.notice} if e.notice else {}) | {"design": design_record(e)} | report_metrics(sections)
        write_text_atomic(e.metrics_path, json.dumps(metrics, indent=2) + "\n", "evaluate")
