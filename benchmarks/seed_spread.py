"""How much a network's laptop test score moves with the training seed alone, and whether a preset
change is admissible under the rule for changes that alter results: each network trained from
scratch once per seed, scored the evaluate stage's way; PilotNet by its mean absolute error.

    python benchmarks/seed_spread.py [--seeds 0 1 2 3 4] [--models segnet fcn unet pilotnet] [--json OUT]
        [--pretraining none] [--labels-from CHECKOUT] [--test-set main] [--runs-dir data/runs]
        [--steering-dir data/steering] [-- overrides]
    python benchmarks/seed_spread.py --merge OUT IN [IN ...]
    python benchmarks/seed_spread.py --compare REFERENCE.json CANDIDATE.json [--margin 0.02] [--mae-margin 0.01]

Needs the split of a finished `dvc repro` (data/split, data/labels) in the working directory. Each
run is `python -m offroad_path.train pretraining=none seed=S` (MLflow off; `--pretraining
segmentation` needs the pretrain stage's data/pretrain) into a temporary folder, with any overrides
after `--`; its confidence maps are scored against the labels with the evaluate stage's pooled IoU
at 0.5. Scored on the **development set** (data/split/development.csv: the training reads a copy
of the split whose test.csv is it), since settings are chosen there and the main test set scores
the committed run alone; `--test-set main` scores the main test set instead (an audit only).
Prints one row per run (IoU, epochs trained, seconds)
and, per network, the mean, the sample standard deviation and the range over the seeds. `--json`
also writes each run's per-image counts and the mean-path prior's. `--labels-from CHECKOUT` scores
against another checkout's test labels instead (its data/split/test.csv; frames matched by
sequence, frame and mirroring, maps resized bilinearly to the labels' size): a preset that renders
the same test worlds at another size is then scored on the same yardstick as the reference.
`--runs-dir data/runs` (and `--steering-dir data/steering` for PilotNet) scores the pipeline's own
runs (the seeds of `dvc repro`) instead of training them again; only valid when the overrides are
none (the runs were made with the checkout's config). `pilotnet` is `python -m
offroad_path.train_steering seed=S`, scored by its test predictions (predictions.csv). `--merge`
joins files of the same preset that hold other seeds (the pipeline's own and more trained here).

`--compare` applies the rule for changes that alter results (benchmarks/README.md): per path
network, the candidate is admissible when the one-sided 95 % lower bound (Student's t over the
seeds) of the paired (by seed) difference in pooled test IoU, candidate - reference, is above
-margin, and no seed collapses (every seed's IoU above the mean-path prior's); for PilotNet, when
the upper bound of the paired difference in mean absolute error is below +mae-margin and every seed
is below always-straight-ahead's error. Both on the test frames both files scored.
"""

from __future__ import annotations

import argparse
import csv
import json
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
from common import PER_SEED, compare, iou, key, mae, merge, test_counts

from offroad_path.data.loading import load_labels
from offroad_path.data.manifest import read_manifest
from offroad_path.evaluate.pixel_scores import counts, mean_path
from offroad_path.report.tables import grid_head, grid_row

SPLIT = Path("data/split")


SCORED = {"development": "development.csv", "main": "test.csv"}  # --test-set: the manifest the runs are scored on


def scored_split(test_set: str, folder: Path) -> Path:
    """A split folder whose test.csv is the `test_set`'s manifest of data/split (train.csv and val.csv as they are)."""
    for name in ("train.csv", "val.csv"):
        (folder / name).write_bytes((SPLIT / name).read_bytes())
    (folder / "test.csv").write_bytes((SPLIT / SCORED[test_set]).read_bytes())
    return folder


def yardstick_labels(root: Path | None, test_set: str) -> dict[str, str] | None:
    """Label files of another checkout's split (root/data/split/<the scored manifest>) by frame key, or None: each run's own."""
    if root is None:
        return None
    return {key(s): str(root / s.label) for s in read_manifest(root / "data" / "split" / SCORED[test_set])}


def prior_counts(yardstick: dict[str, str] | None, test_set: str, threshold: float = 0.5) -> dict[str, list[int]]:
    """The mean-path prior (this checkout's average training label) painted on every scored frame, scored as the runs are."""
    prior = mean_path(load_labels(read_manifest(SPLIT / "train.csv"))) > threshold
    test = read_manifest(SPLIT / SCORED[test_set])
    if yardstick is not None:
        test = [s for s in test if key(s) in yardstick]
        test = [replace(s, label=yardstick[key(s)]) for s in test]
    labels = load_labels(test)
    prior = cv2.resize(prior.astype(np.uint8), labels.shape[:0:-1], interpolation=cv2.INTER_NEAREST).astype(np.float32)
    per_image = counts(np.broadcast_to(prior, labels.shape).astype(np.float32), labels, threshold)
    return {key(s): c.tolist() for s, c in zip(test, per_image, strict=True)}


def steering_errors(run_dir: Path) -> tuple[dict[str, float], dict[str, float]]:
    """Per test frame (by frame key) PilotNet's absolute error and always-straight-ahead's (|true|), from predictions.csv."""
    errors, straight = {}, {}
    with open(run_dir / "predictions.csv", newline="") as f:
        for row in csv.DictReader(f):
            frame = f"{row['sequence']}/{row['frame']}/{int(row['mirrored'] == 'True')}"
            errors[frame] = abs(float(row["predicted"]) - float(row["true"]))
            straight[frame] = abs(float(row["true"]))
    return errors, straight


def train_command(model: str, seed: int, out: Path, split: Path, args: argparse.Namespace) -> list[str]:
    """The stage that trains `model` with `seed` into `out` on `split` (MLflow off, never resumed)."""
    common = [f"seed={seed}", "resume=false", "mlflow.enabled=false", *args.overrides]
    if model == "pilotnet":
        return [sys.executable, "-m", "offroad_path.train_steering", f"steering.out_dir={out}", f"steering.split_dir={split}",
                f"steering.metrics_path={out}.json", f"steering.plots_path={out}.csv", *common]  # fmt: skip
    return [sys.executable, "-m", "offroad_path.train", f"model={model}", f"pretraining={args.pretraining}",
            f"train.out_dir={out}", f"data.split_dir={split}", *common]  # fmt: skip


def pipeline_run(args: argparse.Namespace, model: str, seed: int) -> Path | None:
    """The pipeline's own run of `model` and `seed` (--runs-dir, --steering-dir), when given and finished."""
    where = args.steering_dir if model == "pilotnet" else args.runs_dir and args.runs_dir / f"{model}-{args.pretraining}"
    done = where / f"seed{seed}" if where else None
    return done if done is not None and (done / "metrics.json").is_file() else None


def train_seeds(args: argparse.Namespace, yardstick: dict[str, str] | None) -> dict[str, dict]:
    """Each of args.models at each of args.seeds (with args.overrides), trained here unless the pipeline's run is given."""
    print(grid_head(["network", "seed", "test IoU (PilotNet: MAE)", "epochs", "seconds"]))
    results: dict[str, dict] = {}
    with tempfile.TemporaryDirectory() as tmp:
        (Path(tmp) / "split").mkdir()
        split = scored_split(args.test_set, Path(tmp) / "split")  # beside the runs' folders, never above them
        for model in args.models:
            for seed in args.seeds:
                out, seconds = Path(tmp) / f"{model}-{seed}", 0.0
                if done := pipeline_run(args, model, seed):  # made with the same config
                    out = done
                else:
                    command = train_command(model, seed, out, split, args)
                    start = time.perf_counter()
                    run = subprocess.run(command, capture_output=True, text=True)
                    seconds = time.perf_counter() - start
                    if run.returncode:
                        sys.exit(f"{' '.join(command)} failed:\n{run.stderr[-3000:]}")
                epochs = json.loads((out / "metrics.json").read_text())["epochs"]
                row = results.setdefault(model, {key: [] for key in PER_SEED})
                if model == "pilotnet":
                    errors, straight = steering_errors(out)
                    row["straight"] = straight
                    score, per_frame = mae(errors, list(errors)), errors
                else:
                    per_frame = test_counts(out, yardstick)
                    score = iou(per_frame, list(per_frame))
                values = (seed, score, epochs, round(seconds, 1), per_frame)
                for name, value in zip(PER_SEED, values, strict=True):
                    row[name].append(value)
                print(grid_row([model, seed, f"{score:.4f}", epochs, f"{seconds:.0f}"]), flush=True)
    return results


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--models", nargs="+", default=["segnet", "fcn", "unet"])
    parser.add_argument("--json", type=Path, help="write each run's per-image counts and the prior's here")
    parser.add_argument("--labels-from", type=Path, metavar="CHECKOUT", help="score against this checkout's labels")
    parser.add_argument("--test-set", choices=list(SCORED), default="development", help="the frames scored (the rule's: development)")
    parser.add_argument("--pretraining", choices=["none", "segmentation"], default="none", help="the path networks' pretraining")
    parser.add_argument(
        "--runs-dir", type=Path, help="score RUNS_DIR/<model>-none/seed<k> where it exists instead of training it (data/runs)"
    )
    parser.add_argument(
        "--steering-dir", type=Path, help="score STEERING_DIR/seed<k> (PilotNet) where it exists instead of training it (data/steering)"
    )
    parser.add_argument("--merge", type=Path, nargs="+", metavar=("OUT", "IN"), help="join --json files of other seeds into OUT")
    parser.add_argument("--compare", type=Path, nargs=2, metavar=("REFERENCE", "CANDIDATE"), help="apply the rule to two --json files")
    parser.add_argument("--margin", type=float, default=0.02, help="non-inferiority margin in test IoU (path networks)")
    parser.add_argument("--mae-margin", type=float, default=0.01, help="non-inferiority margin in mean absolute error (PilotNet)")
    parser.add_argument("overrides", nargs="*", help="Hydra overrides of the train stage, after --")
    args = parser.parse_args()
    try:
        if args.compare:
            reference, candidate = (json.loads(p.read_text()) for p in args.compare)
            sys.exit(0 if compare(reference, candidate, args.margin, args.mae_margin) else 1)
        if args.merge:
            if len(args.merge) < 3:
                parser.error("--merge OUT IN [IN ...]: at least two files to join")
            args.merge[0].write_text(json.dumps(merge([json.loads(p.read_text()) for p in args.merge[1:]])) + "\n")
            return
    except ValueError as e:
        sys.exit(f"{'--compare' if args.compare else '--merge'}: {e}")
    if (args.runs_dir or args.steering_dir) and (args.overrides or args.test_set != "main"):
        parser.error("--runs-dir scores the pipeline's runs (the checkout's config, scored on the main test set): "
                     "give no overrides and --test-set main with it")  # fmt: skip
    print(f"overrides: {' '.join(args.overrides) or '(none: the laptop preset)'}")
    yardstick = yardstick_labels(args.labels_from.resolve() if args.labels_from else None, args.test_set)
    results = train_seeds(args, yardstick)
    prior = prior_counts(yardstick, args.test_set)
    print(f"\nmean-path prior: {iou(prior, list(prior)):.4f}\n")
    print(grid_head(["network", "mean IoU (PilotNet: MAE)", "standard deviation", "range"]))
    for model, row in results.items():
        ious = row["score"]
        spread = statistics.stdev(ious) if len(ious) > 1 else float("nan")
        print(grid_row([model, f"{statistics.mean(ious):.4f}", f"{spread:.4f}", f"{min(ious):.4f} to {max(ious):.4f}"]))
    if args.json:
        labels = str(args.labels_from) if args.labels_from else "own test labels"
        found = {"overrides": args.overrides, "labels": labels, "test_set": args.test_set, "pretraining": args.pretraining,
                 "prior": prior, "models": results}  # fmt: skip
        args.json.write_text(json.dumps(found) + "\n")


if __name__ == "__main__":
    main()
