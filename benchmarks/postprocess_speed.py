"""Post-processing speed: milliseconds per 512 x 288 confidence map.

    python benchmarks/postprocess_speed.py [--run unet-none] [--repeats 5]

Post-processes a run's real test-set maps (data/runs/<run>/predictions, written by `dvc repro`)
with their stereo depth, as the postprocess stage does, and prints the best and median time per
map over the repeats, with OpenCV on one thread and on its default thread count. The maps and
depth are loaded once beforehand: file reading is not timed.
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import cv2
import numpy as np

from offroad_path.config import load_config
from offroad_path.data.dataset import load_depth
from offroad_path.data.manifest import read_predictions_manifest
from offroad_path.postprocessing import PostprocessParams, postprocess

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--run", default="unet-none")
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    rows = read_predictions_manifest(ROOT / "data" / "runs" / args.run / "predictions" / "manifest.csv")
    maps = np.stack([np.load(ROOT / path).astype(np.float32) for _, path in rows])  # (N, H, W)
    depth = np.stack([load_depth(sample) for sample, _ in rows])
    params = PostprocessParams.from_config(load_config().postprocess)
    print(f"{len(maps)} maps of {maps.shape[2]} x {maps.shape[1]} from {args.run}")
    default_threads = cv2.getNumThreads()
    for threads in sorted({1, default_threads}):
        cv2.setNumThreads(threads)
        times = []
        for _ in range(args.repeats):
            start = time.perf_counter()
            postprocess(maps, depth, params)
            times.append((time.perf_counter() - start) / len(maps) * 1000)
        print(f"OpenCV threads {threads}: best {min(times):.2f} ms per map, median {statistics.median(times):.2f} ms")
    cv2.setNumThreads(default_threads)


if __name__ == "__main__":
    main()
