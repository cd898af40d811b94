"""How much a network's laptop test IoU moves with the training seed alone, and whether a preset
change is admissible under the seed rule: each network trained from scratch once per seed, scored
the evaluate stage's way.

    python benchmarks/seed_spread.py [--seeds 0 1 2] [--models segnet fcn unet] [--json OUT] [--labels-from CHECKOUT]
        [--runs-dir data/runs] [-- overrides]
    python benchmarks/seed_spread.py --compare REFERENCE.json CANDIDATE.json

Needs the split of a finished `dvc repro` (data/split, data/labels) in the working directory. Each
run is `python -m offroad_path.train pretraining=none seed=S` (MLflow off) into a temporary
folder, with any overrides after `--`; its test confidence maps are scored against the test labels
with the evaluate stage's pooled IoU at 0.5. Prints one row per run (IoU, epochs trained, seconds)
and, per network, the mean, the sample standard deviation and the range over the seeds. `--json`
also writes each run's per-image counts and the mean-path prior's. `--labels-from CHECKOUT` scores
against another checkout's test labels instead (its data/split/test.csv; frames matched by
sequence, frame and mirroring, maps resized bilinearly to the labels' size): a preset that renders
the same test worlds at another size is then scored on the same yardstick as the reference.
`--runs-dir data/runs` scores the pipeline's own runs (seed 0 of `dvc repro`) instead of training
them again; only valid when the overrides are none (the runs were made with the checkout's config).

`--compare` applies the rule for changes that alter results (benchmarks/README.md): per network,
the candidate is admissible when its mean IoU over the seeds is at least the reference's minus
one standard error of the paired (by seed) difference, and no seed collapses (every seed's IoU
above the mean-path prior's), both on the test images both files scored.
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
from scipy import stats

from offroad_path.data.loading import load_labels, load_maps
from offroad_path.data.manifest import Sample, read_manifest, read_predictions_manifest
from offroad_path.evaluation.metrics import counts, mean_path, pooled


def key(sample: Sample) -> str:
    return f"{sample.sequence}/{sample.f0}/{int(sample.mirrored)}"


def yardstick_labels(root: Path | None) -> dict[str, str] | None:
    """Test label files of another checkout's split (root/data/split/test.csv) by frame key, or None: each run's own."""
    if root is None:
        return None
    return {key(s): str(root / s.label) for s in read_manifest(root / "data" / "split" / "test.csv")}


def test_counts(run_dir: Path, yardstick: dict[str, str] | None, threshold: float = 0.5) -> dict[str, list[int]]:
    """Per test image (by frame key) the counts tp, fp, tn, fn of the run's maps, against its own test
    labels or, with a yardstick, against those (maps resized bilinearly to their size; frames it lacks left out)."""
    rows = read_predictions_manifest(run_dir / "predictions" / "manifest.csv", "train")
    if yardstick is not None:
        rows = [(replace(s, label=yardstick[key(s)]), p) for s, p in rows if key(s) in yardstick]
    samples, labels = [s for s, _ in rows], load_labels([s for s, _ in rows])
    maps = load_maps([p for _, p in rows])
    if maps.shape != labels.shape:
        maps = np.stack([cv2.resize(m, labels.shape[:0:-1], interpolation=cv2.INTER_LINEAR) for m in maps])
    per_image = counts(maps, labels, threshold)
    return {key(s): c.tolist() for s, c in zip(samples, per_image, strict=True)}


def prior_counts(yardstick: dict[str, str] | None, threshold: float = 0.5) -> dict[str, list[int]]:
    """The mean-path prior (this checkout's average training label) painted on every test frame, scored as the runs are."""
    prior = mean_path(load_labels(read_manifest(Path("data/split/train.csv")))) > threshold
    test = read_manifest(Path("data/split/test.csv"))
    if yardstick is not None:
        test = [s for s in test if key(s) in yardstick]
        test = [replace(s, label=yardstick[key(s)]) for s in test]
    labels = load_labels(test)
    prior = cv2.resize(prior.astype(np.uint8), labels.shape[:0:-1], interpolation=cv2.INTER_NEAREST).astype(np.float32)
    per_image = counts(np.broadcast_to(prior, labels.shape).astype(np.float32), labels, threshold)
    return {key(s): c.tolist() for s, c in zip(test, per_image, strict=True)}


def iou(per_image: dict[str, list[int]], keys: list[str]) -> float:
    return pooled(np.array([per_image[k] for k in keys])).iou


def train_seeds(
    models: list[str], seeds: list[int], overrides: list[str], yardstick: dict[str, str] | None, runs_dir: Path | None
) -> dict[str, dict]:
    print("| network | seed | test IoU | epochs | seconds |\n| --- | --- | --- | --- | --- |")
    results: dict[str, dict] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for model in models:
            for seed in seeds:
                out, seconds = Path(tmp) / f"{model}-{seed}", 0.0
                done = Path(runs_dir or tmp) / f"{model}-none" / f"seed{seed}"
                if (done / "metrics.json").is_file():  # the pipeline's own run, with the same config
                    out = done
                else:
                    command = [sys.executable, "-m", "offroad_path.train", f"model={model}", "pretraining=none", f"seed={seed}",
                               f"train.out_dir={out}", "resume=false", "mlflow.enabled=false", *overrides]  # fmt: skip
                    start = time.perf_counter()
                    run = subprocess.run(command, capture_output=True, text=True)
                    seconds = time.perf_counter() - start
                    if run.returncode:
                        sys.exit(f"{' '.join(command)} failed:\n{run.stderr[-3000:]}")
                per_image, epochs = test_counts(out, yardstick), json.loads((out / "metrics.json").read_text())["epochs"]
                row = results.setdefault(model, {"seeds": [], "iou": [], "epochs": [], "seconds": [], "counts": []})
                for name, value in zip(row, (seed, iou(per_image, list(per_image)), epochs, round(seconds, 1), per_image), strict=True):
                    row[name].append(value)
                print(f"| {model} | {seed} | {row['iou'][-1]:.4f} | {epochs} | {seconds:.0f} |", flush=True)
    return results


def compare(reference: dict, candidate: dict) -> bool:
    """Print the rule's table per network, on the test frames both files scored; True when every network is admissible."""
    runs = [c for file in (reference, candidate) for model in file["models"].values() for c in model["counts"]]
    keys = sorted(set.intersection(*(set(c) for c in [*runs, candidate["prior"]])))
    print(f"reference: {' '.join(reference['overrides']) or '(none)'}\ncandidate: {' '.join(candidate['overrides']) or '(none)'}")
    print(f"scored against: {candidate['labels']}; {len(keys)} test images both scored "
          f"(reference {len(reference['prior'])}, candidate {len(candidate['prior'])})")  # fmt: skip
    prior = iou(candidate["prior"], keys)
    print(f"mean-path prior: {prior:.4f}\n")
    print("| network | reference mean | candidate mean | paired differences (seeds in order) | mean ± sd | standard error | "
          "95 % interval | lowest seed | admissible |\n| --- | --- | --- | --- | --- | --- | --- | --- | --- |")  # fmt: skip
    admissible_all = True
    for model, ref in reference["models"].items():
        new = candidate["models"].get(model)
        if new is None or new["seeds"] != ref["seeds"]:
            sys.exit(f"--compare: {model} was not run with the same seeds in both files")
        old_iou, new_iou = ([iou(c, keys) for c in row["counts"]] for row in (ref, new))
        diffs = [b - a for a, b in zip(old_iou, new_iou, strict=True)]
        n, mean_d = len(diffs), statistics.mean(diffs)
        sd = statistics.stdev(diffs) if n > 1 else math.nan
        se = sd / math.sqrt(n)
        half = float(stats.t.ppf(0.975, n - 1)) * se
        ok = mean_d >= -se and min(new_iou) > prior
        admissible_all &= ok
        print(f"| {model} | {statistics.mean(old_iou):.4f} | {statistics.mean(new_iou):.4f} | "
              f"{', '.join(f'{d:+.3f}' for d in diffs)} | {mean_d:+.4f} ± {sd:.4f} | {se:.4f} | "
              f"[{mean_d - half:+.4f}, {mean_d + half:+.4f}] | {min(new_iou):.4f} | {'yes' if ok else 'no'} |")  # fmt: skip
    return admissible_all


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--models", nargs="+", default=["segnet", "fcn", "unet"])
    parser.add_argument("--json", type=Path, help="write each run's per-image counts and the prior's here")
    parser.add_argument("--labels-from", type=Path, metavar="CHECKOUT", help="score against this checkout's test labels")
    parser.add_argument(
        "--runs-dir", type=Path, help="score RUNS_DIR/<model>-none/seed<k> where it exists instead of training it (data/runs)"
    )
    parser.add_argument("--compare", type=Path, nargs=2, metavar=("REFERENCE", "CANDIDATE"), help="apply the seed rule to two --json files")
    parser.add_argument("overrides", nargs="*", help="Hydra overrides of the train stage, after --")
    args = parser.parse_args()
    if args.compare:
        reference, candidate = (json.loads(p.read_text()) for p in args.compare)
        sys.exit(0 if compare(reference, candidate) else 1)
    if args.runs_dir and args.overrides:
        parser.error("--runs-dir scores runs made with the checkout's config: give no overrides with it")
    print(f"overrides: {' '.join(args.overrides) or '(none: the laptop preset)'}")
    yardstick = yardstick_labels(args.labels_from.resolve() if args.labels_from else None)
    results = train_seeds(args.models, args.seeds, args.overrides, yardstick, args.runs_dir)
    prior = prior_counts(yardstick)
    print(f"\nmean-path prior: {iou(prior, list(prior)):.4f}\n")
    print("| network | mean IoU | standard deviation | range |\n| --- | --- | --- | --- |")
    for model, row in results.items():
        ious = row["iou"]
        spread = statistics.stdev(ious) if len(ious) > 1 else float("nan")
        print(f"| {model} | {statistics.mean(ious):.4f} | {spread:.4f} | {min(ious):.4f} to {max(ious):.4f} |")
    if args.json:
        labels = str(args.labels_from) if args.labels_from else "own test labels"
        args.json.write_text(json.dumps({"overrides": args.overrides, "labels": labels, "prior": prior, "models": results}) + "\n")


if __name__ == "__main__":
    main()
