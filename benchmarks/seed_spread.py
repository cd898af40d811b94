"""How much a network's laptop test IoU moves with the training seed alone, and what a preset change
costs and saves: each network trained from scratch once per seed, scored the evaluate stage's way.

    python benchmarks/seed_spread.py [--seeds 0 1 2] [--models segnet fcn unet] [-- trainer.max_epochs=4 ...]

Needs the split of a finished `dvc repro` (data/split, data/labels) in the working directory. Each
run is `python -m offroad_path.train pretraining=none seed=S` (MLflow off) into a temporary
folder, with any overrides after `--`; its test confidence maps are scored against the test labels
with the evaluate stage's pooled IoU at 0.5. Prints one row per run (IoU, epochs trained, seconds)
and, per network, the mean, the sample standard deviation and the range over the seeds.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from offroad_path.data.loading import load_labels, load_maps
from offroad_path.data.manifest import read_predictions_manifest
from offroad_path.evaluation.metrics import counts, pooled


def pooled_test_iou(run_dir: Path, threshold: float = 0.5) -> float:
    rows = read_predictions_manifest(run_dir / "predictions" / "manifest.csv", "train")
    samples, paths = [s for s, _ in rows], [p for _, p in rows]
    return pooled(counts(load_maps(paths), load_labels(samples), threshold)).iou


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--models", nargs="+", default=["segnet", "fcn", "unet"])
    parser.add_argument("overrides", nargs="*", help="Hydra overrides of the train stage, after --")
    args = parser.parse_args()
    print(f"overrides: {' '.join(args.overrides) or '(none: the laptop preset)'}")
    print("| network | seed | test IoU | epochs | seconds |\n| --- | --- | --- | --- | --- |")
    results: dict[str, list[float]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for model in args.models:
            for seed in args.seeds:
                out = Path(tmp) / f"{model}-{seed}"
                command = [sys.executable, "-m", "offroad_path.train", f"model={model}", "pretraining=none", f"seed={seed}",
                           f"train.out_dir={out}", "resume=false", "mlflow.enabled=false", *args.overrides]  # fmt: skip
                start = time.perf_counter()
                run = subprocess.run(command, capture_output=True, text=True)
                seconds = time.perf_counter() - start
                if run.returncode:
                    sys.exit(f"{' '.join(command)} failed:\n{run.stderr[-3000:]}")
                iou, epochs = pooled_test_iou(out), json.loads((out / "metrics.json").read_text())["epochs"]
                results.setdefault(model, []).append(iou)
                print(f"| {model} | {seed} | {iou:.4f} | {epochs} | {seconds:.0f} |", flush=True)
    print("\n| network | mean IoU | standard deviation | range |\n| --- | --- | --- | --- |")
    for model, ious in results.items():
        spread = statistics.stdev(ious) if len(ious) > 1 else float("nan")
        print(f"| {model} | {statistics.mean(ious):.4f} | {spread:.4f} | {min(ious):.4f} to {max(ious):.4f} |")


if __name__ == "__main__":
    main()
