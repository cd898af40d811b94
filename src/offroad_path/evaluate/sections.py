"""The sections of the evaluate stage's report, in the order of results.md and metrics.json: the
results table (the paper's Table 5.1), the baselines, steering from the paths against PilotNet,
IoU by condition, temporal consistency, real footage. Each scores a TestSet (see report.py)."""

from __future__ import annotations

import logging
from dataclasses import asdict
from pathlib import Path

import numpy as np
from omegaconf import DictConfig

from offroad_path.config.evaluate_schema import EVERY_SCRATCH_VS_PRIOR
from offroad_path.data.loading import load_maps
from offroad_path.evaluate.against_pilotnet import SteeringComparison
from offroad_path.evaluate.by_condition import ConditionTable, by_condition, read_conditions
from offroad_path.evaluate.figures import before_and_after, good_and_bad_cases
from offroad_path.evaluate.pixel_scores import Scores, non_corresponding, per_image_iou, pooled
from offroad_path.evaluate.real import RealFrames, RealRow, Separability, score_real, separability
from offroad_path.evaluate.scored_set import POSTPROCESSING, TestSet
from offroad_path.evaluate.temporal_scores import TemporalRow, score_temporal
from offroad_path.evaluate.uncertainty import HierarchicalBootstrap, Uncertainty
from offroad_path.report.rendering import (
    against_pilotnet_markdown,
    baselines_markdown,
    conditions_markdown,
    results_table_markdown,
    temporal_markdown,
)
from offroad_path.report.tables import (
    PP_KEY,
    grid,
    markdown_table,
    method_title,
    network_name,
    result_row,
    split_run_name,
)
from offroad_path.statistics.bootstrap import Draws, Interval, mean
from offroad_path.statistics.primaries import from_draws, owned
from offroad_path.statistics.scores import Record

log = logging.getLogger(__name__)


def networks(e: DictConfig, test: TestSet) -> dict[str, Path]:
    """Each run's network for the sections that run it on frames of their own."""
    return {run: test.checkpoint(e.runs_dir, run) for run in test.runs}


def numbers(row) -> dict:
    """A row's numbers (a Record's or a dataclass's) for metrics.json, rounded; None for undefined (JSON has no nan)."""
    items = row.items() if isinstance(row, dict) else asdict(row).items()
    return {k: (None if v != v else round(v, 6)) for k, v in items if isinstance(v, float)}


class ResultsTable:
    """Every run, raw and post-processed, pooled over the test set (the paper's Table 5.1), and the
    figures that pick from it (good and bad cases, before and after post-processing)."""

    def __init__(self, uncertainty: Uncertainty | None = None) -> None:
        self.uncertainty = uncertainty  # its intervals go in the table (None: the pooled figures alone)
        self.runs: list[str] = []
        self.rows: dict[tuple[str, str], Record] = {}
        self.per_image_iou: dict[tuple[str, str], np.ndarray] = {}
        self.without_depth, self.images = 0, 0  # test images of one camera (post-processed without the depth mask), of all

    def score(self, test: TestSet) -> None:
        self.runs = test.runs
        self.without_depth, self.images = sum(not s.disparity for s in test.samples), len(test.samples)
        for run in test.runs:
            model, pretraining = split_run_name(run)
            for pp in POSTPROCESSING:
                per_image = test.counts[run, pp]
                ious, s = per_image_iou(per_image), pooled(per_image)
                self.rows[run, pp] = result_row(network_name(model), pretraining, pp, s, float(ious.mean()))
                self.per_image_iou[run, pp] = ious
            log.info("%s: IoU %.3f, post-processed %.3f", run, self.rows[run, "no"].iou, self.rows[run, "yes"].iou)

    def table(self) -> list[Record]:
        return [self.rows[run, pp] for run in self.runs for pp in POSTPROCESSING]

    def markdown(self) -> str:
        one_camera = (
            f"{self.without_depth} of {self.images} test images come from a recording of one camera: post-processed without "
            "the depth mask (it needs stereo disparity).\n\n"
            if self.without_depth
            else ""
        )
        return results_table_markdown(
            self.metrics() | (self.uncertainty.metrics() if self.uncertainty else {}), heading="# Results\n\n" + one_camera
        )

    def metrics(self) -> dict:
        return {run: {PP_KEY[pp]: numbers(self.rows[run, pp]) for pp in POSTPROCESSING} for run in self.runs}

    def best_run(self, runs: list[str] | None = None) -> str:
        return max(runs or self.runs, key=lambda run: self.rows[run, "no"].iou)

    def figures(self, test: TestSet, cases: int, scale: float) -> dict[str, np.ndarray]:
        return {
            "good_and_bad_cases.png": self.cases_figure(test, cases, scale),
            "postprocessing.png": self.postprocessing_figure(test, cases, scale),
        }

    def cases_figure(self, test: TestSet, cases: int, scale: float) -> np.ndarray:
        """Fig. 8: each network's best run, its best and worst test images by IoU."""
        rows = []
        for model in dict.fromkeys(split_run_name(r)[0] for r in self.runs):
            best = self.best_run([r for r in self.runs if split_run_name(r)[0] == model])
            ious = self.per_image_iou[best, "no"]
            order = np.argsort(-ious, kind="stable")
            for kind, i in [("good", i) for i in order[:cases]] + [("bad", i) for i in order[::-1][:cases]]:
                rows.append((f"{best} {kind}", test.samples[i], load_maps([test.paths[best, "no"][i]])[0], float(ious[i])))
        return good_and_bad_cases(rows, scale)

    def postprocessing_figure(self, test: TestSet, cases: int, scale: float) -> np.ndarray:
        """Fig. 5: the best run's images whose IoU post-processing raised most, and lowered most."""
        best = self.best_run()
        before, after = self.per_image_iou[best, "no"], self.per_image_iou[best, "yes"]
        order = np.argsort(-(after - before), kind="stable")
        picks = list(dict.fromkeys([*order[:cases], *order[::-1][:cases]]))
        rows = [
            (test.samples[i], *load_maps([test.paths[best, "no"][i], test.paths[best, "yes"][i]]), float(before[i]), float(after[i]))
            for i in picks
        ]
        return before_and_after(rows, scale)


class Baselines:
    """What a model must beat: each run against non-corresponding ground truth, and the mean path prior
    (by_condition: the section whose main-set row holds each network minus the prior, paired)."""

    def __init__(self, by_condition: ByCondition) -> None:
        self.scores: dict[str, Scores] = {}
        self.by_condition = by_condition

    def score(self, test: TestSet) -> None:
        groups = [(s.sequence, s.f0) for s in test.samples]
        for run in test.runs:
            if len(set(groups)) < 2:
                log.warning("the test set holds one frame: no non-corresponding baseline")
                self.scores[f"non_corresponding.{run}"] = Scores.undefined()
            else:
                self.scores[f"non_corresponding.{run}"] = non_corresponding(test.predicted[run], test.labels, groups)
        self.scores["mean_path_prior"] = pooled(test.prior_counts)
        if test.colour_counts is not None:
            self.scores["colour_classifier"] = pooled(test.colour_counts)

    def markdown(self) -> str:
        return baselines_markdown(self.metrics() | self.by_condition.metrics())

    def metrics(self) -> dict:
        return {"baselines": {name: numbers(s) for name, s in self.scores.items()}}


class SteeringFromPaths:
    """A steering angle from each run's thresholded path (pure pursuit), against PilotNet's and the
    label's (empty without steering ground truth)."""

    def __init__(self, e: DictConfig, bootstrap: HierarchicalBootstrap) -> None:
        self.e, self.bootstrap = e, bootstrap
        self.comparison = SteeringComparison(e)
        self.against_pilotnet: dict[str, Interval] = {}  # run -> paired MAE difference, path + pursuit - PilotNet
        self.draws: dict[str, Draws] = {}  # f"{run}_vs_pilotnet" -> its resamples (for the primaries)

    def score(self, test: TestSet) -> None:
        self.comparison.start(test.samples, test.labels, test.seeds)
        for run in test.runs:
            self.comparison.add(run, f"{method_title(run)} + pure pursuit", test.seed_predicted[run])
        errors = self.comparison.errors  # (S, N) each
        if "pilotnet" in errors:
            for run in test.runs:
                a, b = (np.stack([errors[k], np.ones_like(errors[k])], axis=-1) for k in (run, "pilotnet"))
                if (draws := self.bootstrap.paired_draws(a, b, mean)) is not None:
                    self.draws[f"{run}_vs_pilotnet"] = draws
                    self.against_pilotnet[run] = draws.interval()

    def markdown(self) -> str:
        if not self.comparison.rows:
            return ""
        s = self.e.steering_from_paths
        return (
            "\n## Path prediction against end-to-end steering\n\nOn the same test frames: a steering angle from each "
            f"network's thresholded path (its centre line on the ground, pure pursuit at {s.lookahead_m:g} m look-ahead), "
            "from the ground-truth path label, and PilotNet's. Degrees at the road wheels are the normalised error times the "
            f"vehicle's steering lock; at the steering wheel, times the steering ratio {s.steering_ratio:g}.\n\n"
            + markdown_table(self.comparison.table())
            + self._against_pilotnet()
        )

    def _against_pilotnet(self) -> str:
        if not self.against_pilotnet:
            return ""
        return (
            "\nPaired hierarchical-bootstrap intervals (worlds, blocks, training seeds; seed k of a network paired with seed k "
            "of PilotNet) of each path network's error minus PilotNet's, on the same frames, both pooled over their seeds; below "
            "0: the path network steers closer to the true angle.\n\n" + against_pilotnet_markdown(self.metrics()["steering_from_paths"])
        )

    def metrics(self) -> dict:
        rows = self.comparison.rows
        if not rows:
            return {}
        out = {key: numbers(row) for key, row in rows.items()}
        for run, i in self.against_pilotnet.items():
            out[f"{run}_vs_pilotnet"] = {"mae_difference": round(i.estimate, 6), "low": round(i.low, 6), "high": round(i.high, 6)}
        return {"steering_from_paths": out}


class ByCondition:
    """Pooled IoU of the raw maps per condition of the next 20 m of driving (rendered worlds only)."""

    def __init__(self, bootstrap: HierarchicalBootstrap) -> None:
        self.bootstrap = bootstrap
        self.table: ConditionTable | None = None
        self.keys: dict[str, str] = {}  # method title -> its metrics key

    def score(self, test: TestSet) -> None:
        if (conditions := read_conditions(test.samples)) is None:
            return
        per_image = {method_title(run): np.stack(test.seed_counts[run, "no"]) for run in test.runs} | {"mean path prior": test.prior_counts}
        self.keys = {method_title(run): run for run in test.runs} | {"mean path prior": "mean_path_prior"}
        if test.colour_counts is not None:
            per_image["colour classifier"] = test.colour_counts
            self.keys["colour classifier"] = "colour_classifier"
        self.table = by_condition(conditions, per_image, self.bootstrap, [s.sequence for s in test.samples], "mean path prior")

    def markdown(self) -> str:
        return conditions_markdown(self.metrics()["by_condition"]) if self.table is not None else ""

    def metrics(self) -> dict:
        return {"by_condition": self.table.metrics(self.keys)} if self.table is not None else {}


class Temporal:
    """Every frame of the test blocks, with and without the temporal filter (evaluate.temporal)."""

    def __init__(self, e: DictConfig, label: DictConfig, block_m: float) -> None:
        self.e, self.label, self.block_m = e, label, block_m
        self.rows: dict[str, TemporalRow] | None = None

    def score(self, test: TestSet) -> None:
        self.rows = score_temporal(self.e, self.label, self.block_m, networks(self.e, test), test.samples)

    def markdown(self) -> str:
        return temporal_markdown(self.metrics()["temporal"], self.e.temporal.alpha) if self.rows else ""

    def metrics(self) -> dict:
        if self.rows is None:
            return {}
        return {"temporal": {key: {"frames": row.frames, **numbers(row)} for key, row in self.rows.items()}}


class RealFootage:
    """Every run on a labelled real recording (evaluate.real_labels_dir; none by default)."""

    def __init__(self, e: DictConfig, bootstrap: HierarchicalBootstrap, block_m: float, distance_m: float) -> None:
        self.e, self.resampling, self.block_m, self.distance_m = e, bootstrap.resampling, block_m, distance_m
        self.rows: dict[str, RealRow] | None = None
        self.frames: RealFrames | None = None
        self.separability: Separability | None = None

    def score(self, test: TestSet) -> None:
        if self.e.real_labels_dir:
            self.frames = RealFrames.read(Path(self.e.real_labels_dir), self.block_m, self.distance_m)
            self.rows = score_real(networks(self.e, test), self.frames, test.prior, self.e.threshold, self.resampling)
            self.separability = separability(self.frames, self.rows)

    def _poses(self) -> str:
        return self.frames.poses if self.frames is not None else "its poses"

    def markdown(self) -> str:
        if self.rows is None:
            return ""
        return (
            f"\n## Real footage ({Path(self.e.real_labels_dir).name})\n\nEach network (its first training seed), trained on the "
            f"synthetic world, run on the labelled frames of a real recording (labels made by the label stage from {self._poses()}) "
            "and scored against each frame's own label and, averaged over pairs, against the other frames' labels. The label-centred "
            "gain: for each labelled frame, the IoU of its own prediction against its label minus the mean IoU of the predictions "
            "of the frames that bend the other way against the same label, averaged over frames; a constant prediction (the mean "
            "path prior among them) scores exactly 0, a network that follows the path above 0. Intervals: 95 % block bootstrap over "
            f"the recording's {len(set(self.frames.blocks))} blocks of driving, one world: few blocks understate the uncertainty.\n\n"
            + self.separability.sentence()
            + "\n\n"
            + markdown_table(list(self.rows.values()))
        )

    def metrics(self) -> dict:
        if self.rows is None:
            return {}
        s = self.separability
        recording = {
            "label_diversity": round(s.diversity, 6),
            "largest_gain": round(s.largest_gain, 6),
            "widest_iou_interval": None if s.width != s.width else round(s.width, 6),
            "separable": s.separable,
        }
        return {"real_footage": {"recording": recording} | {key: numbers(row) for key, row in self.rows.items()}}


class PrimaryQuestions:
    """The primaries evaluate answers (evaluate.conclusions: uncertainty/<key> and
    steering_from_paths/<key>), each with its hierarchical-bootstrap p-value and its interval at every
    Holm level; the family's verdicts, with the drive's primaries, are the README's (statistics.primaries)."""

    SECTIONS = ("uncertainty", "steering_from_paths")

    def __init__(self, e: DictConfig, uncertainty: Uncertainty, steering: SteeringFromPaths) -> None:
        self.conclusions = e.conclusions
        self.mine = owned(self.conclusions.primaries, self.SECTIONS)
        self.sources = {"uncertainty": uncertainty.draws, "steering_from_paths": steering.draws}
        self.uncertainty = uncertainty
        self.found: dict[str, dict] = {}

    def score(self, test: TestSet) -> None:
        family = len(self.conclusions.primaries)
        for name, (section, key) in self.mine.items():
            if (draws := self.sources[section].get(key)) is not None:
                self.found[name] = from_draws(draws, self.conclusions.alpha, family)
                if key == EVERY_SCRATCH_VS_PRIOR:
                    # Intersection-union: named by its weakest member; a one-sided claim ("each above the
                    # prior") whose weakest estimate is at or below 0 cannot be supported, whatever its p.
                    self.found[name]["weakest"] = self.uncertainty.weakest.split("_vs_")[0]
                    if draws.estimate <= 0:
                        self.found[name]["p_value"] = 1.0

    def markdown(self) -> str:
        if not self.mine:
            return ""
        q = self.conclusions
        lines = [
            "\n## Primary questions\n",
            f"Declared in evaluate.conclusions before the run: {len(q.primaries)} primaries in one family (these and the drive's), "
            f"tested with Holm's correction at family-wise {q.alpha:g}; the README states each verdict. Here each of this stage's: "
            "the estimate with its 95 % hierarchical-bootstrap interval and the bootstrap's two-sided p-value (uncorrected).\n",
        ]
        rows = []
        for name, (section, key) in self.mine.items():
            entry = self.found.get(name)  # None: this run does not make the comparison (evaluate.runs)
            shown = Interval(entry["estimate"], *entry["intervals"][0]).difference_text() if entry else "not measured"
            rows.append([name, q.primaries[name].claim, f"{section}/{key}", shown, f"{entry['p_value']:.4f}" if entry else ""])
        header = ["primary", "claim", "comparison", "estimate [95 % interval]", "p (uncorrected)"]
        return "\n".join([*lines, grid(header, rows)]) + "\n"

    def metrics(self) -> dict:
        return {"primaries": self.found} if self.found else {}
