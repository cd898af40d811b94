"""Stage `evaluate`: every run with and without post-processing, scored the paper's way, beside
the baselines a model must beat (see offroad_path.evaluation and DESIGN.md).

    python -m offroad_path.evaluate [evaluate.runs='[unet-none,unet-segmentation]'] [evaluate.threshold=0.4]

Writes evaluate.out_dir (data/evaluation): results.md (Table 5.1 layout and the baselines),
results.csv, figures/good_and_bad_cases.png (Fig. 8), figures/postprocessing.png (Fig. 5);
evaluate.metrics_path (metrics/evaluation.json, for `dvc metrics show`); evaluate.plots_dir (one
precision-recall CSV per run, for `dvc plots show`); one MLflow run linking the training runs.
"""

from __future__ import annotations

import json
import logging
from dataclasses import asdict
from pathlib import Path

import numpy as np
from omegaconf import DictConfig

from offroad_path.data.manifest import Sample, read_manifest, read_predictions_manifest
from offroad_path.evaluation.figures import before_and_after, good_and_bad_cases, save_png
from offroad_path.evaluation.metrics import Scores, counts, mean_path, non_corresponding, pooled, precision_recall_curve
from offroad_path.evaluation.results import (
    ResultRow,
    baseline_table,
    csv_text,
    load_labels,
    load_maps,
    markdown_table,
    network_name,
    score,
    split_run_name,
)
from offroad_path.utils.atomic import atomic_directory, write_text_atomic
from offroad_path.utils.cli import hydra_stage
from offroad_path.utils.tracking import stage_run, tracking_uri

log = logging.getLogger("offroad_path.evaluate")


def predictions(manifest: Path, made_by: str, samples: list[Sample] | None) -> tuple[list[Sample], list[str]]:
    """A predictions manifest's samples and map paths, checked against the test set seen so far."""
    rows = read_predictions_manifest(manifest, made_by)
    found = [s for s, _ in rows]
    if samples is not None and found != samples:
        raise ValueError(f"{manifest}: lists other test samples than the runs before it (retrain on the same split)")
    return found, [p for _, p in rows]


def baseline(predicted: np.ndarray, labels: np.ndarray, samples: list[Sample]) -> Scores:
    """The non-corresponding baseline; undefined (nan) when the test set holds a single frame."""
    groups = [(s.sequence, s.f0) for s in samples]
    if len(set(groups)) < 2:
        log.warning("the test set holds one frame: no non-corresponding baseline")
        return Scores(*[float("nan")] * 4)
    return non_corresponding(predicted, labels, groups)


def evaluate(cfg: DictConfig) -> list[ResultRow]:
    e = cfg.evaluate
    samples: list[Sample] | None = None
    labels = np.zeros(0)
    rows: list[ResultRow] = []
    per_image: dict[tuple[str, str], np.ndarray] = {}  # (run, post-processing) -> IoU per image
    paths: dict[tuple[str, str], list[str]] = {}
    curves, baselines = {}, {}
    for run in e.runs:
        model, pretraining = split_run_name(run)
        for pp, manifest in (("no", Path(e.runs_dir) / run / "predictions" / "manifest.csv"),
                             ("yes", Path(e.postprocessed_dir) / run / "manifest.csv")):  # fmt: skip
            samples, paths[run, pp] = predictions(manifest, "train" if pp == "no" else "postprocess", samples)
            if not len(labels):
                labels = load_labels(samples)
            maps = load_maps(paths[run, pp])
            row, per_image[run, pp] = score(network_name(model), pretraining, pp, maps, labels, e.threshold)
            rows.append(row)
            if pp == "no":
                curves[run] = precision_recall_curve(maps, labels, e.pr_thresholds)
                baselines[f"{network_name(model)} ({pretraining}) against non-corresponding ground truth"] = baseline(
                    maps > e.threshold, labels, samples
                )
        log.info("%s: IoU %.3f, post-processed %.3f", run, rows[-2].iou, rows[-1].iou)
    prior = mean_path(load_labels(read_manifest(e.train_manifest))) > e.threshold
    baselines["mean path prior (average training label)"] = pooled(counts(np.broadcast_to(prior, labels.shape).astype(np.float32), labels))

    write_outputs(cfg, samples, rows, baselines, curves, per_image, paths)
    log_to_mlflow(cfg, rows, baselines)
    return rows


def write_outputs(cfg, samples, rows, baselines, curves, per_image, paths) -> None:
    e = cfg.evaluate
    out_dir = Path(e.out_dir)
    with atomic_directory(out_dir) as tmp:
        (tmp / "results.md").write_text(
            "# Results (Table 5.1 layout)\n\nPooled over the test set: accuracy, recall, precision, IoU. "
            "The last column is the mean of per-image IoU, not the paper's measure.\n\n" + markdown_table(rows) +
            "\n## Baselines\n\nNon-corresponding: each prediction against every other test frame's ground truth, "
            "averaged over those pairs (paper: accuracy 0.84, IoU 0.41).\n\n" + baseline_table(baselines)
        )  # fmt: skip
        (tmp / "results.csv").write_text(csv_text(rows))
        save_png(tmp / "figures" / "good_and_bad_cases.png", fig8(e, samples, rows, per_image, paths))
        save_png(tmp / "figures" / "postprocessing.png", fig5(e, samples, rows, per_image, paths))
    with atomic_directory(e.plots_dir) as tmp:
        for run, curve in curves.items():
            lines = ["threshold,precision,recall"] + [f"{t:.4f},{p:.6f},{r:.6f}" for t, p, r in zip(*curve.values(), strict=True)]
            (tmp / f"{run}.csv").write_text("\n".join(lines) + "\n")
    metrics: dict = {}
    for run, (raw, post) in zip(e.runs, zip(rows[::2], rows[1::2], strict=True), strict=True):
        metrics[run] = {"raw": _clean(asdict(raw)), "postprocessed": _clean(asdict(post))}
    metrics["baselines"] = {name: _clean(asdict(s)) for name, s in baselines.items()}
    write_text_atomic(e.metrics_path, json.dumps(metrics, indent=2) + "\n")


def _clean(d: dict) -> dict:
    """Numbers only (rounded), None for undefined: JSON and `dvc metrics show` take no nan."""
    return {k: (None if v != v else round(v, 6)) for k, v in d.items() if isinstance(v, float)}


def fig8(e, samples, rows, per_image, paths) -> np.ndarray:
    """Each network's best run: its best and worst test images by IoU (the paper's good and bad cases)."""
    cases = []
    for model in dict.fromkeys(split_run_name(r)[0] for r in e.runs):
        runs = [r for r in e.runs if split_run_name(r)[0] == model]
        best = max(runs, key=lambda r: rows[2 * e.runs.index(r)].iou)
        ious = per_image[best, "no"]
        order = np.argsort(-ious, kind="stable")
        picks = [("good", i) for i in order[: e.figure_cases]] + [("bad", i) for i in order[::-1][: e.figure_cases]]
        for kind, i in picks:
            cases.append((f"{best} {kind}", samples[i], load_maps([paths[best, "no"][i]])[0], float(ious[i])))
    return good_and_bad_cases(cases, e.figure_scale)


def fig5(e, samples, rows, per_image, paths) -> np.ndarray:
    """The best run's images whose IoU post-processing raised most, and lowered most."""
    best = max(e.runs, key=lambda r: rows[2 * e.runs.index(r)].iou)
    change = per_image[best, "yes"] - per_image[best, "no"]
    order = np.argsort(-change, kind="stable")
    picks = list(dict.fromkeys([*order[: e.figure_cases], *order[::-1][: e.figure_cases]]))
    cases = [(samples[i], *load_maps([paths[best, "no"][i], paths[best, "yes"][i]]), float(per_image[best, "no"][i]),
              float(per_image[best, "yes"][i])) for i in picks]  # fmt: skip
    return before_and_after(cases, e.figure_scale)


def training_runs(cfg: DictConfig) -> dict[str, str]:
    """The latest MLflow training run of each evaluated model-pretraining pair."""
    from mlflow.tracking import MlflowClient

    client = MlflowClient(tracking_uri(cfg.mlflow))
    experiment = client.get_experiment_by_name(cfg.mlflow.experiment)
    found = {}
    for run in cfg.evaluate.runs if experiment else []:
        model, pretraining = split_run_name(run)
        query = f"tags.stage = 'train' and tags.model = '{model}' and tags.pretraining = '{pretraining}'"
        hits = client.search_runs([experiment.experiment_id], query, max_results=1, order_by=["attributes.start_time DESC"])
        if hits:
            found[run] = hits[0].info.run_id
    return found


def log_to_mlflow(cfg: DictConfig, rows: list[ResultRow], baselines: dict[str, Scores]) -> None:
    with stage_run(cfg, "evaluate") as run:
        if run is None:
            return
        import mlflow

        for name, row in zip(cfg.evaluate.runs, zip(rows[::2], rows[1::2], strict=True), strict=True):
            for pp, r in zip(("raw", "postprocessed"), row, strict=True):
                mlflow.log_metrics({f"{name}.{pp}.{k}": v for k, v in _clean(asdict(r)).items() if v is not None})
        linked = training_runs(cfg)
        mlflow.set_tags({f"training_run.{name}": run_id for name, run_id in linked.items()})
        mlflow.log_table({k: [getattr(r, k) for r in rows] for k in asdict(rows[0])}, artifact_file="results.json")
        mlflow.log_artifacts(cfg.evaluate.out_dir)
        mlflow.log_artifacts(cfg.evaluate.plots_dir, "precision_recall")
        log.info("MLflow run %s, linked to %d training runs", run.info.run_id, len(linked))


main = hydra_stage(evaluate)


if __name__ == "__main__":
    main()
