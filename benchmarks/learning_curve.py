"""How much driving a path network needs: its margin over the mean-path prior on the development set
against the number of training drives, for each setting of the training budget.

    python benchmarks/learning_curve.py [--data data] [--models unet fcn] [--drives 2 4 8 16]
        [--seeds 0 1 2] [--settings epochs steps wide] [--work DIR] [--json out.json]
        [--figure docs/images/learning_curve.png]

Run after `dvc repro` (it reads the committed run's labels and split). Nested subsets of the
training drives of that one rendering (the first k drives by name; each subset's validation and
frames are the run's own), the train stage itself on each (no pretraining, the default's
augmentation and mirrored copies), scored on the development set (split/development.csv: held-out
worlds drawn as the main test set is, from a stream of their own; settings are chosen there, never
on the main test set). Settings:

- epochs: the default's epochs (trainer.max_epochs, early stopping on), so SGD steps grow with the data;
- steps: a fixed number of SGD steps, the default's at all drives (--steps), so only the data grows;
- wide: width 0.5 (twice the channels) for the wall time the `epochs` run of the same drives and seed
  took here (trainer.max_time): what more capacity buys at a fixed budget on this machine; at the
  drives of --wide-at only (default: all of them).

At all drives `steps` is the `epochs` run (the same steps, early stopping never reached): it is not run twice.
At all drives `epochs` is the default itself: `--reuse data/runs` scores the pipeline's own runs
(<model>-none/seed<k>) there instead of training them again (the same data, config and seeds).

Margin: the network's pooled IoU (its seeds' counts pooled) minus the prior's, the prior being the
mean label of that subset's training frames, with a 95 % paired interval from the hierarchical
bootstrap of the test worlds, their 20 m blocks and the seeds (evaluate.bootstrap's resampling).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
from common import development_problem, repeated

ROOT = Path(__file__).resolve().parents[1]
SETTINGS = ("epochs", "steps", "wide")


def read_split(split_dir: Path) -> dict[str, list]:
    from offroad_path.data.manifest import read_manifest

    return {name: read_manifest(split_dir / f"{name}.csv") for name in ("train", "val", "development")}


def subset_split(split: dict[str, list], drives: list[str], folder: Path) -> Path:
    """A split folder: the training frames of `drives`, the run's validation frames of them, and the
    development set as its test manifest (what the train stage predicts)."""
    from offroad_path.data.manifest import write_manifest

    folder.mkdir(parents=True, exist_ok=True)
    write_manifest(folder / "train.csv", [s for s in split["train"] if s.sequence in drives])
    write_manifest(folder / "val.csv", [s for s in split["val"] if s.sequence in drives])
    write_manifest(folder / "test.csv", split["development"])
    return folder


def train_once(split_dir: Path, out: Path, model: str, seed: int, overrides: list[str]) -> tuple[Path, float, int]:
    """The train stage on `split_dir`: (its predictions manifest, wall seconds, SGD steps); an earlier
    run's in the same --work folder is kept (rescoring)."""
    from offroad_path.config import load_config
    from offroad_path.train import train
    from offroad_path.utils.threads import set_threads

    done = out / "learning_curve.json"
    if not done.is_file():
        cfg = load_config(
            f"model={model}", "pretraining=none", f"seed={seed}", f"data.split_dir={split_dir}", f"train.out_dir={out}",
            "train.sample_images=0", "resume=false", "mlflow.enabled=false", *overrides,
        )  # fmt: skip
        set_threads(cfg.threads)
        start = time.perf_counter()
        metrics = train(cfg)
        done.write_text(json.dumps({"seconds": time.perf_counter() - start, "steps": int(metrics.get("global_step", -1))}))
    found = json.loads(done.read_text())
    return out / "predictions" / "manifest.csv", float(found["seconds"]), int(found["steps"])


def test_counts(manifest: Path, test: list, labels: np.ndarray) -> np.ndarray:
    """(N, 4) per-image [tp, fp, tn, fn] of a run's maps of the `test` samples (found by sequence, frame and
    mirroring among the run's, which may hold more) at the default threshold."""
    from offroad_path.data.loading import load_maps
    from offroad_path.data.manifest import read_predictions_manifest
    from offroad_path.evaluate.pixel_scores import counts

    maps = {(s.sequence, s.f0, s.mirrored): path for s, path in read_predictions_manifest(manifest, "train")}
    return counts(load_maps([maps[s.sequence, s.f0, s.mirrored] for s in test]), labels, 0.5)


def curve(args: argparse.Namespace) -> dict:
    from offroad_path.config import load_config
    from offroad_path.data.loading import load_labels
    from offroad_path.evaluate.pixel_scores import counts, mean_path, pooled
    from offroad_path.evaluate.uncertainty import HierarchicalBootstrap, sample_blocks
    from offroad_path.statistics.bootstrap import Resampling
    from offroad_path.statistics.scores import iou

    cfg = load_config()
    split = read_split(args.data / "split")
    split["test"] = split["development"]
    labels = load_labels(split["test"])
    blocks = sample_blocks(split["test"], args.data / "labels", cfg.split.block_m)
    b = cfg.evaluate.bootstrap
    bootstrap = HierarchicalBootstrap(blocks, Resampling(args.resamples or b.resamples, b.seed, b.level))
    drives = sorted({s.sequence for s in split["train"]})
    steps = args.steps or cfg.trainer.max_epochs * (len(split["train"]) // cfg.data.batch_size)
    rows = []
    for k in sorted(set(args.drives)):
        chosen = drives[:k]
        folder = subset_split(split, chosen, args.work / f"split_{k}")
        train_labels = load_labels([s for s in split["train"] if s.sequence in chosen])
        prior = counts(np.broadcast_to(mean_path(train_labels) > 0.5, labels.shape).astype(np.float32), labels, 0.5)
        frames = sum(1 for s in split["train"] if s.sequence in chosen and not s.mirrored)
        for model in args.models:
            for setting in args.settings:
                if setting == "wide" and k not in (args.wide_at or [len(drives)]):
                    continue
                per_seed, seconds, trained_steps = [], [], []
                for seed in args.seeds:
                    same = setting == "steps" and k == len(drives)  # the default's steps at all drives: the epochs run
                    if setting == "epochs" or same:
                        overrides = []
                    elif setting == "steps":
                        overrides = [f"train.max_steps={steps}", "trainer.max_epochs=100000", "callbacks.early_stopping.patience=100000"]
                    else:
                        budget = json.loads((args.work / f"epochs_{model}_{k}_{seed}" / "learning_curve.json").read_text())["seconds"]
                        whole = round(budget)
                        overrides = ["model.width=0.5", f"trainer.max_time='00:00:{whole // 60:02d}:{whole % 60:02d}'"]
                    run = args.work / f"{'epochs' if same else setting}_{model}_{k}_{seed}"
                    if args.reuse and setting in ("epochs", "steps") and k == len(drives):
                        run = args.reuse / f"{model}-none" / f"seed{seed}"  # the pipeline's own run of the default
                        steps_run = int(json.loads((run / "metrics.json").read_text())["global_step"])
                        manifest, s, n = run / "predictions" / "manifest.csv", float("nan"), steps_run
                    else:
                        manifest, s, n = train_once(folder, run, model, seed, overrides)
                    per_seed.append(test_counts(manifest, split["test"], labels))
                    seconds.append(s)
                    trained_steps.append(n)
                network = np.stack(per_seed)
                margin = bootstrap.paired(network, prior, iou)
                rows.append(
                    {
                        "setting": setting, "model": model, "drives": k, "frames": frames, "seeds": list(args.seeds),
                        "steps": trained_steps, "seconds": [round(x, 1) for x in seconds],
                        "iou": round(pooled(network.reshape(-1, 4)).iou, 4), "prior_iou": round(pooled(prior).iou, 4),
                        "margin": round(margin.estimate, 4), "low": round(margin.low, 4), "high": round(margin.high, 4),
                    }
                )  # fmt: skip
                print(table(rows[-1:]), flush=True)
    worlds = len({s.sequence for s in split["test"]})
    return {"test_worlds": worlds, "test_images": len(split["test"]), "default_steps": steps, "rows": rows}


def table(rows: list[dict]) -> str:
    lines = [
        "| setting | network | drives | training frames | SGD steps (per seed) | seconds (per seed) | IoU | mean-path prior "
        "| margin [95 % interval] |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for r in rows:
        shown = f"{r['margin']:+.3f} [{r['low']:+.3f}, {r['high']:+.3f}]"
        lines.append(
            f"| {r['setting']} | {r['model']} | {r['drives']} | {r['frames']} | {', '.join(map(str, r['steps']))} | "
            f"{', '.join(f'{s:.0f}' for s in r['seconds'])} | {r['iou']:.3f} | {r['prior_iou']:.3f} | {shown} |"
        )
    return "\n".join(lines)


def figure(result: dict, path: Path) -> None:
    """Margin over the prior against training frames (log scale), one line per setting and network."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 3.8), dpi=120)
    lines: dict[tuple[str, str], list[dict]] = {}
    for r in result["rows"]:
        lines.setdefault((r["setting"], r["model"]), []).append(r)
    for (setting, model), rows in lines.items():
        rows.sort(key=lambda r: r["frames"])
        x = np.array([r["frames"] for r in rows], float)
        y = np.array([r["margin"] for r in rows])
        err = np.array([[r["margin"] - r["low"] for r in rows], [r["high"] - r["margin"] for r in rows]])
        ax.errorbar(x, y, yerr=err, fmt="o-" if setting == "epochs" else "s--" if setting == "steps" else "^:", capsize=3,
                    label=f"{model}, {setting}")  # fmt: skip
    ax.set_xscale("log")
    ax.axhline(0.0, color="grey", lw=0.8)
    ax.set_xlabel("training frames (before mirroring)")
    ax.set_ylabel("IoU minus mean-path prior")
    ax.set_title(f"development set: {result['test_worlds']} worlds, {result['test_images']} images; 95 % intervals", fontsize=10)
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=ROOT / "data", help="a pipeline run's data folder (labels/, split/)")
    parser.add_argument("--models", nargs="+", default=["unet", "fcn"])
    parser.add_argument("--drives", nargs="+", type=int, default=[2, 4, 8, 16])
    parser.add_argument("--seeds", nargs="+", type=int, default=[0])
    parser.add_argument("--settings", nargs="+", choices=SETTINGS, default=list(SETTINGS))
    parser.add_argument("--wide-at", nargs="+", type=int, default=None, help="drives of the wide setting (default: all drives)")
    parser.add_argument("--steps", type=int, default=None, help="the steps setting's SGD steps (default: the default's at all drives)")
    parser.add_argument("--reuse", type=Path, default=None, help="the pipeline's runs folder (data/runs): its runs at all drives")
    parser.add_argument("--resamples", type=int, default=None, help="bootstrap resamples (default: evaluate.bootstrap's)")
    parser.add_argument("--work", type=Path, default=Path("/tmp/learning_curve"), help="runs are kept here: a rerun rescores")
    parser.add_argument("--json", type=Path, default=None)
    parser.add_argument("--figure", type=Path, default=None, help="e.g. docs/images/learning_curve.png")
    args = parser.parse_args()
    from offroad_path.models import MODELS

    problems = [f"--models: unknown {m!r}; valid: {', '.join(MODELS)}" for m in args.models if m not in MODELS]
    problems += [f"--seeds: {s} is negative" for s in args.seeds if s < 0]
    problems += [f"--seeds: {s} is listed twice (each seed trains once)" for s in repeated(args.seeds)]
    problems += [f"--drives: {k} is listed twice" for k in repeated(args.drives)]
    problems += [f"--drives: {k} is not a number of drives (at least 1)" for k in args.drives if k < 1]
    problems += [f"--steps: {args.steps} is not positive"] if args.steps is not None and args.steps < 1 else []
    problems += [f"--resamples: {args.resamples} is not positive"] if args.resamples is not None and args.resamples < 1 else []
    if problems:
        parser.exit(2, f"error: {problems[0]}\n")
    if problem := development_problem(args.data):
        parser.exit(2, f"error: {problem}\n")
    from offroad_path.data.manifest import read_manifest

    drives = len({s.sequence for s in read_manifest(args.data / "split" / "train.csv")})
    if too_many := [k for k in args.drives if k > drives]:
        parser.exit(2, f"error: --drives: {too_many[0]} is more than the run's {drives} training drives\n")
    if "wide" in args.settings and "epochs" not in args.settings:
        parser.exit(2, "--settings: wide takes its wall time from the epochs runs; list epochs too\n")
    args.settings = sorted(args.settings, key=SETTINGS.index)  # epochs before wide
    result = curve(args)
    print(table(result["rows"]))
    if args.json:
        args.json.write_text(json.dumps(result, indent=2) + "\n")
    if args.figure:
        figure(result, args.figure)


if __name__ == "__main__":
    main()
