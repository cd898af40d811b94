"""The training recipe of the path networks, chosen on the development set: each recipe (a list of
config overrides) trained by the train stage itself and scored on the development worlds, never
on the main test set.

    python benchmarks/recipe_search.py [--data data] [--recipes sgd adamw_cosine ...]
        [--models segnet fcn unet] [--seeds 0] [--work DIR] [--json out.json] [--figure PNG]

Run after `dvc repro synthesize label split` (it reads that run's labels and split, whose
development.csv lists the development worlds: synthesize.test_worlds.development_blocks). Each run
trains on the split's training frames with its validation frames (no pretraining; the default's
augmentation and mirrored copies), validating every `--val-every` of an epoch so that its
validation IoU can be read against SGD steps (convergence: the change over the last fifth of the
run). Scored: the development set's pooled IoU (seeds' counts pooled) minus the mean-path prior's,
with a 95 % paired interval from the hierarchical bootstrap of the development worlds, their 20 m
blocks and the seeds (evaluate.bootstrap's resampling), and each seed's IoU.

Runs are kept in --work (named by recipe, network and seed): a rerun rescores them.
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
import time
from pathlib import Path

import numpy as np
from common import development_problem, repeated

ROOT = Path(__file__).resolve().parents[1]
# Each recipe: overrides over the default config. The table the search recorded is
# benchmarks/README.md's "Training recipe"; the committed default is whichever conf/model says.
SGD = ["model.optimizer=sgd", "model.lr_schedule=step", "model.dice_weight=0"]
ADAMW = ["model.optimizer=adamw", "model.lr_schedule=cosine", "model.lr_warmup=0.05", "model.weight_decay=1e-4"]
RECIPES: dict[str, list[str]] = {
    "sgd": SGD,  # the recipe of the earlier committed runs (SGD 0.03, FCN 0.01, constant rate)
    "sgd_cosine": ["model.optimizer=sgd", "model.lr_schedule=cosine", "model.lr_warmup=0.05", "model.dice_weight=0"],
    "adamw_1e-3": [*ADAMW, "model.lr=1e-3", "model.dice_weight=0"],
    "adamw_3e-3": [*ADAMW, "model.lr=3e-3", "model.dice_weight=0"],
    "adamw_3e-3_dice": [*ADAMW, "model.lr=3e-3", "model.dice_weight=1"],
    "adamw_1e-3_dice": [*ADAMW, "model.lr=1e-3", "model.dice_weight=1"],
    # FCN-8s alone (the others have batch norm already): batch norm after each VGG convolution
    "sgd_bn": [*SGD, "model.batch_norm=true"],
    "adamw_1e-3_dice_bn": [*ADAMW, "model.lr=1e-3", "model.dice_weight=1", "model.batch_norm=true"],
    "adamw_1e-3_dice_3_epochs": [*ADAMW, "model.lr=1e-3", "model.dice_weight=1", "trainer.max_epochs=3"],
    "adamw_3e-3_dice_ema": [
        *ADAMW,
        "model.lr=3e-3",
        "model.dice_weight=1",
        *("+callbacks.ema._target_=lightning.pytorch.callbacks.EMAWeightAveraging", "+callbacks.ema.decay=0.99"),
    ],
}


def read_manifests(split_dir: Path) -> dict[str, list]:
    from offroad_path.data.manifest import read_manifest

    return {name: read_manifest(split_dir / f"{name}.csv") for name in ("train", "val", "development")}


def development_split(split_dir: Path, folder: Path) -> Path:
    """A split folder whose test manifest is the development set: the train stage predicts it."""
    folder.mkdir(parents=True, exist_ok=True)
    for name in ("train", "val"):
        (folder / f"{name}.csv").write_bytes((split_dir / f"{name}.csv").read_bytes())
    (folder / "test.csv").write_bytes((split_dir / "development.csv").read_bytes())
    return folder


def train_once(split_dir: Path, out: Path, model: str, seed: int, *, overrides: list[str], val_every: float) -> dict:  # noqa: PLR0913
    """The train stage on `split_dir` into `out` (kept: a rerun rescores): its metrics, wall seconds
    and validation IoU against SGD steps."""
    from offroad_path.config import load_config
    from offroad_path.train import train
    from offroad_path.utils.threads import set_threads

    done = out / "recipe_search.json"
    if not done.is_file():
        cfg = load_config(
            f"model={model}", "pretraining=none", f"seed={seed}", f"data.split_dir={split_dir}", f"train.out_dir={out}",
            "train.sample_images=0", "resume=false", "mlflow.enabled=false", "logger=csv", f"paths.logs_dir={out}_logs",
            f"trainer.val_check_interval={val_every}", *overrides,
            # early stopping's patience in epochs as the default's, though validation comes every val_every of one
            f"callbacks.early_stopping.patience={round(load_config().callbacks.early_stopping.patience / val_every)}",
        )  # fmt: skip
        set_threads(cfg.threads)
        start = time.perf_counter()
        metrics = train(cfg)
        seconds = time.perf_counter() - start
        done.write_text(json.dumps({"seconds": seconds, "steps": int(metrics["global_step"]), "curve": validation_curve(cfg)}))
    return json.loads(done.read_text())


def validation_curve(cfg) -> list[tuple[int, float]]:
    """(step, val/iou) of each validation of the run, from the CSV logger's newest metrics.csv."""
    found = sorted(Path(cfg.paths.logs_dir, "csv").rglob("metrics.csv"), key=lambda p: p.stat().st_mtime)
    rows = list(csv.DictReader(found[-1].open()))
    return [(int(r["step"]), float(r["val/iou"])) for r in rows if r.get("val/iou")]


def plateau(curve: list[tuple[int, float]]) -> float:
    """How much the validation IoU still rose over the last fifth of the run: the best IoU there
    minus the best IoU before it (<= 0.01: flat)."""
    steps = np.array([s for s, _ in curve])
    ious = np.array([v for _, v in curve])
    last = steps >= 0.8 * steps.max()
    return float(ious[last].max() - ious[~last].max()) if (~last).any() else float("nan")


def development_counts(manifest: Path, development: list, labels: np.ndarray) -> np.ndarray:
    """(N, 4) per-image [tp, fp, tn, fn] of a run's maps of the development samples."""
    from offroad_path.data.loading import load_maps
    from offroad_path.data.manifest import read_predictions_manifest
    from offroad_path.evaluate.pixel_scores import counts

    maps = {(s.sequence, s.f0, s.mirrored): path for s, path in read_predictions_manifest(manifest, "train")}
    return counts(load_maps([maps[s.sequence, s.f0, s.mirrored] for s in development]), labels, 0.5)


def search(args: argparse.Namespace) -> dict:
    from offroad_path.config import load_config
    from offroad_path.data.loading import load_labels
    from offroad_path.evaluate.pixel_scores import counts, mean_path, pooled
    from offroad_path.evaluate.uncertainty import HierarchicalBootstrap, sample_blocks
    from offroad_path.models import BATCH_NORM_CHOICE
    from offroad_path.statistics.bootstrap import Resampling
    from offroad_path.statistics.scores import iou

    cfg = load_config()
    split = read_manifests(args.data / "split")
    labels = load_labels(split["development"])
    blocks = sample_blocks(split["development"], args.data / "labels", cfg.split.block_m)
    b = cfg.evaluate.bootstrap
    bootstrap = HierarchicalBootstrap(blocks, Resampling(args.resamples, b.seed, b.level))
    prior = counts(np.broadcast_to(mean_path(load_labels(split["train"])) > 0.5, labels.shape).astype(np.float32), labels, 0.5)
    folder = development_split(args.data / "split", args.work / "split")
    rows = []
    for recipe in args.recipes:
        for model in args.models:
            if "model.batch_norm=true" in RECIPES[recipe] and model not in BATCH_NORM_CHOICE:
                continue  # batch norm is a choice of FCN-8s alone (models.BATCH_NORM_CHOICE)
            runs_dirs = [args.work / f"{recipe}_{model}_{s}" for s in args.seeds]
            overrides = RECIPES[recipe] + args.override
            runs = [
                train_once(folder, run, model, s, overrides=overrides, val_every=args.val_every)
                for run, s in zip(runs_dirs, args.seeds, strict=True)
            ]
            manifests = [run / "predictions" / "manifest.csv" for run in runs_dirs]
            per_seed = np.stack([development_counts(m, split["development"], labels) for m in manifests])
            margin = bootstrap.paired(per_seed, prior, iou)
            rows.append(
                {
                    "recipe": recipe, "model": model, "seeds": list(args.seeds), "steps": [r["steps"] for r in runs],
                    "seconds": [round(r["seconds"]) for r in runs], "iou": round(pooled(per_seed.reshape(-1, 4)).iou, 4),
                    "seed_iou": [round(pooled(c).iou, 4) for c in per_seed], "prior_iou": round(pooled(prior).iou, 4),
                    "margin": round(margin.estimate, 4), "low": round(margin.low, 4), "high": round(margin.high, 4),
                    "last_fifth_gain": [round(plateau(r["curve"]), 4) for r in runs], "curves": [r["curve"] for r in runs],
                }
            )  # fmt: skip
            print(table(rows[-1:]), flush=True)
    worlds = len({s.sequence for s in split["development"]})
    return {"development_worlds": worlds, "development_images": len(split["development"]), "rows": rows}


def table(rows: list[dict]) -> str:
    lines = [
        "| recipe | network | SGD steps | seconds (per seed) | IoU per seed | IoU | mean-path prior | margin [95 % interval] "
        "| gain over the last fifth |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for r in rows:
        lines.append(
            f"| {r['recipe']} | {r['model']} | {', '.join(map(str, r['steps']))} | {', '.join(map(str, r['seconds']))} | "
            f"{', '.join(f'{v:.3f}' for v in r['seed_iou'])} | {r['iou']:.3f} | {r['prior_iou']:.3f} | "
            f"{r['margin']:+.3f} [{r['low']:+.3f}, {r['high']:+.3f}] | {', '.join(f'{g:+.3f}' for g in r['last_fifth_gain'])} |"
        )
    return "\n".join(lines)


def figure(result: dict, path: Path) -> None:
    """Validation IoU against SGD steps, one panel per network, one line per recipe and seed."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    models = list(dict.fromkeys(r["model"] for r in result["rows"]))
    recipes = list(dict.fromkeys(r["recipe"] for r in result["rows"]))
    colours = {recipe: f"C{i}" for i, recipe in enumerate(recipes)}  # one colour per recipe, one line style per seed
    fig, axes = plt.subplots(1, len(models), figsize=(4.4 * len(models), 3.6), dpi=120, sharey=True, squeeze=False)
    for ax, model in zip(axes[0], models, strict=True):
        for r in (r for r in result["rows"] if r["model"] == model):
            for seed, curve in zip(r["seeds"], r["curves"], strict=True):
                ax.plot(*zip(*curve, strict=True), marker=".", color=colours[r["recipe"]], ls="-" if seed == r["seeds"][0] else "--",
                        label=f"{r['recipe']}, seed {seed}")  # fmt: skip
        ax.set_title(model, fontsize=10)
        ax.set_xlabel("SGD steps")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="lower right")
    axes[0][0].set_ylabel("validation IoU")
    fig.tight_layout()
    fig.savefig(path)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=ROOT / "data", help="a pipeline run's data folder (labels/, split/)")
    parser.add_argument("--recipes", nargs="+", default=list(RECIPES))
    parser.add_argument("--models", nargs="+", default=["segnet", "fcn", "unet"])
    parser.add_argument("--seeds", nargs="+", type=int, default=[0])
    parser.add_argument("--override", nargs="*", default=[], help="config overrides for every run (e.g. trainer.max_epochs=3)")
    parser.add_argument("--val-every", type=float, default=0.25, help="validation every this fraction of an epoch")
    parser.add_argument("--resamples", type=int, default=2000, help="bootstrap resamples")
    parser.add_argument("--work", type=Path, default=Path("/tmp/recipe_search"), help="runs are kept here: a rerun rescores")
    parser.add_argument("--json", type=Path, default=None)
    parser.add_argument("--figure", type=Path, default=None, help="e.g. docs/images/convergence.png")
    args = parser.parse_args()
    from offroad_path.models import MODELS

    problems = [f"--recipes: unknown {r!r}; valid: {', '.join(RECIPES)}" for r in args.recipes if r not in RECIPES]
    problems += [f"--models: unknown {m!r}; valid: {', '.join(MODELS)}" for m in args.models if m not in MODELS]
    problems += [f"--seeds: {s} is negative" for s in args.seeds if s < 0]
    problems += [f"--seeds: {s} is listed twice (each seed trains once)" for s in repeated(args.seeds)]
    problems += [] if 0 < args.val_every <= 1 else [f"--val-every: {args.val_every} is not in (0, 1]"]
    problems += [] if args.resamples > 0 else [f"--resamples: {args.resamples} is not positive"]
    if not problems and (problem := development_problem(args.data)):
        problems.append(problem)
    if problems:
        parser.exit(2, f"error: {problems[0]}\n")
    result = search(args)
    print(table(result["rows"]))
    if args.json:
        args.json.write_text(json.dumps(result, indent=2) + "\n")
    if args.figure:
        figure(result, args.figure)


if __name__ == "__main__":
    sys.exit(main())
