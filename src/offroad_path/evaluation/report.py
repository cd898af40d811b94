"""Every run scored with and without post-processing, and what the evaluate stage writes of it:
the results table, the baselines, precision-recall curves, `metrics.json` and the figures."""

from __future__ import annotations

import json
import logging
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
from omegaconf import DictConfig

from offroad_path.data.loading import load_labels, load_maps
from offroad_path.data.manifest import Sample, read_manifest, read_predictions_manifest
from offroad_path.evaluation.conditions import ConditionTable, by_condition, read_conditions
from offroad_path.evaluation.figures import before_and_after, good_and_bad_cases, save_png
from offroad_path.evaluation.metrics import Scores, counts, mean_path, non_corresponding, per_image_iou, pooled, precision_recall_curve
from offroad_path.evaluation.real import RealFrames, RealRow, score_real
from offroad_path.evaluation.steering import SteeringComparison
from offroad_path.evaluation.tables import BaselineRow, ResultRow, baseline_name, csv_text, markdown_table, network_name, split_run_name
from offroad_path.evaluation.temporal import TemporalRow
from offroad_path.utils.atomic import atomic_directory, check_output_dir, write_text_atomic

log = logging.getLogger(__name__)
POSTPROCESSING = ("no", "yes")


@dataclass
class Report:
    runs: list[str]
    samples: list[Sample] = field(default_factory=list)
    rows: dict[tuple[str, str], ResultRow] = field(default_factory=dict)  # (run, post-processing) -> table row
    per_image_iou: dict[tuple[str, str], np.ndarray] = field(default_factory=dict)
    paths: dict[tuple[str, str], list[str]] = field(default_factory=dict)  # the maps behind each row
    curves: dict[str, dict[str, np.ndarray]] = field(default_factory=dict)  # run -> precision-recall curve
    baselines: dict[str, Scores] = field(default_factory=dict)  # "non_corresponding.<run>", "mean_path_prior"
    steering: SteeringComparison | None = None  # steering from the paths against PilotNet
    counts: dict[str, np.ndarray] = field(default_factory=dict)  # method title -> raw per-image counts, for the conditions
    method_keys: dict[str, str] = field(default_factory=dict)  # method title -> its metrics key
    conditions: ConditionTable | None = None  # IoU by condition (rendered worlds only)
    real: dict[str, RealRow] | None = None  # every run on a labelled real recording (evaluate.real_labels_dir)
    real_name: str = ""
    temporal: dict[str, TemporalRow] | None = None  # every test-block frame, with and without the temporal filter

    def table(self) -> list[ResultRow]:
        return [self.rows[run, pp] for run in self.runs for pp in POSTPROCESSING]

    def best_run(self, runs: list[str] | None = None) -> str:
        return max(runs or self.runs, key=lambda run: self.rows[run, "no"].iou)

    def baseline_rows(self) -> list[BaselineRow]:
        return [BaselineRow(baseline_name(key), s.accuracy, s.recall, s.precision, s.iou) for key, s in self.baselines.items()]

    def metrics(self) -> dict:
        """For metrics.json and MLflow: numbers only (rounded), None for undefined (JSON has no nan)."""
        out: dict = {run: {"raw": _numbers(self.rows[run, "no"]), "postprocessed": _numbers(self.rows[run, "yes"])} for run in self.runs}
        out["baselines"] = {name: _numbers(s) for name, s in self.baselines.items()}
        if self.steering is not None and self.steering.rows:
            out["steering_from_paths"] = {key: _numbers(row) for key, row in self.steering.rows.items()}
        if self.conditions is not None:
            out["by_condition"] = self.conditions.metrics(self.method_keys)
        if self.temporal is not None:
            out["temporal"] = {key: _numbers(row) for key, row in self.temporal.items()}
        if self.real is not None:
            out["real_footage"] = {key: _numbers(row) for key, row in self.real.items()}
        return out


def _numbers(row) -> dict:
    return {k: (None if v != v else round(v, 6)) for k, v in asdict(row).items() if isinstance(v, float)}


def baseline(predicted: np.ndarray, labels: np.ndarray, samples: list[Sample]) -> Scores:
    """The non-corresponding baseline; undefined (nan) when the test set holds a single frame."""
    groups = [(s.sequence, s.f0) for s in samples]
    if len(set(groups)) < 2:
        log.warning("the test set holds one frame: no non-corresponding baseline")
        return Scores(*[float("nan")] * 4)
    return non_corresponding(predicted, labels, groups)


def score_runs(e: DictConfig) -> Report:
    """Score each run's raw (train) and post-processed maps against the test labels, with the baselines."""
    report = Report(list(e.runs), steering=SteeringComparison(e))
    labels = np.zeros(0)
    for run in report.runs:
        model, pretraining = split_run_name(run)
        for pp, manifest, made_by in (("no", Path(e.runs_dir) / run / "predictions" / "manifest.csv", "train"),
                                      ("yes", Path(e.postprocessed_dir) / run / "manifest.csv", "postprocess")):  # fmt: skip
            rows = read_predictions_manifest(manifest, made_by)
            if report.samples and [s for s, _ in rows] != report.samples:
                raise ValueError(f"{manifest}: lists other test samples than the runs before it (retrain on the same split)")
            report.samples, report.paths[run, pp] = [s for s, _ in rows], [p for _, p in rows]
            if not len(labels):
                labels = load_labels(report.samples)
                report.steering.start(report.samples, labels)
            maps = load_maps(report.paths[run, pp])
            per_image = counts(maps, labels, e.threshold)
            ious, s = per_image_iou(per_image), pooled(per_image)
            report.rows[run, pp] = ResultRow(
                network_name(model), pretraining, pp, s.accuracy, s.recall, s.precision, s.iou, float(ious.mean())
            )
            report.per_image_iou[run, pp] = ious
            if pp == "no":
                title = f"{network_name(model)} ({pretraining})"
                report.counts[title], report.method_keys[title] = per_image, run
                report.curves[run] = precision_recall_curve(maps, labels, e.pr_thresholds)
                report.baselines[f"non_corresponding.{run}"] = baseline(maps > e.threshold, labels, report.samples)
                report.steering.add(run, f"{title} + pure pursuit", maps > e.threshold)
        log.info("%s: IoU %.3f, post-processed %.3f", run, report.rows[run, "no"].iou, report.rows[run, "yes"].iou)
    prior = mean_path(load_labels(read_manifest(e.train_manifest))) > e.threshold
    everywhere = np.broadcast_to(prior, labels.shape).astype(np.float32)
    prior_counts = counts(everywhere, labels, e.threshold)
    report.baselines["mean_path_prior"] = pooled(prior_counts)
    if (conditions := read_conditions(report.samples)) is not None:
        report.counts["mean path prior"], report.method_keys["mean path prior"] = prior_counts, "mean_path_prior"
        report.conditions = by_condition(conditions, report.counts)
    if e.real_labels_dir:
        frames = RealFrames.read(Path(e.real_labels_dir))
        report.real, report.real_name = score_real(report.runs, Path(e.runs_dir), frames, prior, e.threshold), Path(e.real_labels_dir).name
    return report


def evaluate_inputs(e: DictConfig) -> list[str]:
    return [e.runs_dir, e.postprocessed_dir, str(Path(e.train_manifest).parent), *([e.real_labels_dir] if e.real_labels_dir else [])]


def check_outputs(e: DictConfig) -> None:
    """Before any scoring: the output folders may be written (see utils.atomic)."""
    for key in ("out_dir", "plots_dir"):
        check_output_dir(e[key], f"evaluate.{key}", evaluate_inputs(e))


def write_report(e: DictConfig, report: Report) -> None:
    """evaluate.out_dir (results.md, results.csv, figures/), evaluate.plots_dir, evaluate.metrics_path."""
    table = report.table()
    inputs = evaluate_inputs(e)
    with atomic_directory(e.out_dir, "evaluate", inputs, key="evaluate.out_dir") as tmp:
        (tmp / "results.md").write_text(
            "# Results (Table 5.1 layout)\n\nPooled over the test set: accuracy, recall, precision, IoU. "
            "The last column is the mean of per-image IoU, not the paper's measure.\n\n" + markdown_table(table) +
            "\n## Baselines\n\nNon-corresponding: each prediction against every other test frame's ground truth, "
            "averaged over those pairs (paper: accuracy 0.84, IoU 0.41).\n\n" + markdown_table(report.baseline_rows())
            + steering_section(e, report) + conditions_section(report) + temporal_section(e, report) + real_section(report)
        )  # fmt: skip
        (tmp / "results.csv").write_text(csv_text(table))
        save_png(tmp / "figures" / "good_and_bad_cases.png", cases_figure(report, e.figure_cases, e.figure_scale))
        save_png(tmp / "figures" / "postprocessing.png", postprocessing_figure(report, e.figure_cases, e.figure_scale))
    with atomic_directory(e.plots_dir, "evaluate", inputs, key="evaluate.plots_dir") as tmp:
        for run, curve in report.curves.items():
            lines = ["threshold,precision,recall"] + [f"{t:.4f},{p:.6f},{r:.6f}" for t, p, r in zip(*curve.values(), strict=True)]
            (tmp / f"{run}.csv").write_text("\n".join(lines) + "\n")
    write_text_atomic(e.metrics_path, json.dumps(report.metrics(), indent=2) + "\n")


def steering_section(e: DictConfig, report: Report) -> str:
    """The path-against-steering table for results.md (empty without steering ground truth)."""
    if report.steering is None or not report.steering.rows:
        return ""
    s = e.steering_from_paths
    return (
        "\n## Path prediction against end-to-end steering\n\nOn the same test frames: a steering angle from each "
        f"network's thresholded path (its centre line on the ground, pure pursuit at {s.lookahead_m:g} m look-ahead), "
        "from the ground-truth path label, and PilotNet's. Degrees at the road wheels are the normalised error times the "
        f"vehicle's steering lock; at the steering wheel, times the steering ratio {s.steering_ratio:g}.\n\n"
        + markdown_table(report.steering.table())
    )


def conditions_section(report: Report) -> str:
    """The IoU-by-condition table for results.md (empty without the world's conditions)."""
    if report.conditions is None:
        return ""
    return (
        "\n## Results by condition\n\nPooled IoU (raw maps) over the test frames of each group, from what the world knows "
        "about the next 20 m of driving (conditions.csv of each sequence); a frame can be in several groups. "
        "The mean path prior shows how hard a group is for a network that ignores the image.\n\n" + report.conditions.markdown()
    )


def temporal_section(e: DictConfig, report: Report) -> str:
    """The temporal-consistency table for results.md (empty when it was not run)."""
    if not report.temporal:
        return ""
    return (
        "\n## Temporal consistency\n\nEvery frame from the first to the last test frame of each block of driving, labelled "
        "exactly from the world's true poses and depth (so IoU here is not the table's, which scores VO labels). Filtered: the "
        "previous fused confidence carried into each frame by the VO pose and stereo depth, then averaged with the current "
        f"prediction (weight {e.temporal.alpha:g} on the current). Stability: the mean IoU of each thresholded path with the "
        "previous one carried into its frame by the true pose and depth.\n\n" + markdown_table(list(report.temporal.values()))
    )


def real_section(report: Report) -> str:
    """The real-footage rows for results.md (empty unless evaluate.real_labels_dir is set)."""
    if report.real is None:
        return ""
    return (
        f"\n## Real footage ({report.real_name})\n\nEach network, trained on the synthetic world, run on the labelled frames of "
        "a real recording (VO labels) and scored against each frame's own label and, averaged over pairs, against the other "
        "frames' labels. A network that perceives the path scores higher on its own frame; one that paints a fixed "
        "prior scores about the same on both, like the mean path of the synthetic training labels.\n\n"
        + markdown_table(list(report.real.values()))
    )


def cases_figure(report: Report, cases: int, scale: float) -> np.ndarray:
    """Fig. 8: each network's best run, its best and worst test images by IoU."""
    rows = []
    for model in dict.fromkeys(split_run_name(r)[0] for r in report.runs):
        best = report.best_run([r for r in report.runs if split_run_name(r)[0] == model])
        ious = report.per_image_iou[best, "no"]
        order = np.argsort(-ious, kind="stable")
        for kind, i in [("good", i) for i in order[:cases]] + [("bad", i) for i in order[::-1][:cases]]:
            rows.append((f"{best} {kind}", report.samples[i], load_maps([report.paths[best, "no"][i]])[0], float(ious[i])))
    return good_and_bad_cases(rows, scale)


def postprocessing_figure(report: Report, cases: int, scale: float) -> np.ndarray:
    """Fig. 5: the best run's images whose IoU post-processing raised most, and lowered most."""
    best = report.best_run()
    before, after = report.per_image_iou[best, "no"], report.per_image_iou[best, "yes"]
    order = np.argsort(-(after - before), kind="stable")
    picks = list(dict.fromkeys([*order[:cases], *order[::-1][:cases]]))
    rows = [(report.samples[i], *load_maps([report.paths[best, "no"][i], report.paths[best, "yes"][i]]), float(before[i]), float(after[i]))
            for i in picks]  # fmt: skip
    return before_and_after(rows, scale)
