"""Label-stage throughput: frames of stereo odometry per second, disparity and labels included.

    python benchmarks/label_speed.py [--in-dir data/synthetic]

Runs the real label stage (VO on every frame, StereoSGBM and the footprint label at every f0,
reports) over the rendered laptop sequences with MLflow off, on one worker and on one per core,
with each odometry method (`label.odometry.method`), all in one run so the figures compare.
Render the input first (`dvc repro synthesize` or `python -m offroad_path.synthesize`).
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

from hydra import compose, initialize_config_dir

from offroad_path.config import register_configs
from offroad_path.label import label
from offroad_path.sequence import find_sequences, open_sequence

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--in-dir", default=str(ROOT / "data" / "synthetic"))
    args = parser.parse_args()
    frames = sum(len(open_sequence(p)) for p in find_sequences(args.in_dir))
    register_configs()
    cores = os.cpu_count() or 1
    for method in ("frame_to_frame", "windowed"):
        for workers in sorted({1, cores}):
            with tempfile.TemporaryDirectory() as tmp, initialize_config_dir(str(ROOT / "conf"), version_base="1.3"):
                cfg = compose(
                    "config",
                    overrides=[f"label.in_dir={args.in_dir}", f"label.out_dir={tmp}/labels", f"label.metrics_path={tmp}/m.json",
                               f"label.workers={workers}", f"label.odometry.method={method}", "mlflow.enabled=false"],
                )  # fmt: skip
                start = time.perf_counter()
                metrics = label(cfg)
                elapsed = time.perf_counter() - start
            print(
                f"{method}, workers={workers}: {frames} frames, {metrics['labels']} labels in {elapsed:.1f} s: "
                f"{frames / elapsed:.1f} frames/s; drift {metrics['translation_drift_pct']:.3f} % "
                f"(worst sequence {metrics['translation_drift_pct_worst']:.3f} %), {metrics['vo_failed_steps']} failed steps"
            )


if __name__ == "__main__":
    main()
