"""Post-processing speed: milliseconds per 512 x 288 confidence map.

    python benchmarks/postprocess_speed.py [--run unet-none] [--repeats 5]

Post-processes a run's real test-set maps (data/runs/<run>/seed0/predictions, written by `dvc repro`)
with their stereo depth, as the postprocess stage does, and prints the best and median time per
map over the repeats, with OpenCV on one thread and on its default thread count, with the exact
blur (blur_scale 1) and with the default half-resolution one; and how far the second moves the
maps and each image's IoU at 0.5. The maps and depth are loaded once beforehand: file reading is
not timed.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np

from offroad_path.config import load_config
from offroad_path.data.loading import load_depth, load_labels
from offroad_path.data.manifest import read_predictions_manifest
from offroad_path.inference.path_filter import PostprocessParams, postprocess

ROOT = Path(os.environ.get("OFFROAD_ROOT", Path(__file__).resolve().parents[1]))  # a checkout that ran `dvc repro`


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--run", default="unet-none")
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    os.chdir(ROOT)  # the manifests' paths are relative to the repository
    rows = read_predictions_manifest(Path("data") / "runs" / args.run / "predictions" / "manifest.csv")
    maps = np.stack([np.load(path).astype(np.float32) for _, path in rows])  # (N, H, W)
    depth = np.stack([load_depth(sample) for sample, _ in rows])
    labels = load_labels([sample for sample, _ in rows])
    params = PostprocessParams.from_config(load_config().postprocess)
    print(f"{len(maps)} maps of {maps.shape[2]} x {maps.shape[1]} from {args.run}")
    default_threads = cv2.getNumThreads()
    outputs = {}
    for blur_scale in (1, params.blur_scale):
        for threads in sorted({1, default_threads}):
            cv2.setNumThreads(threads)
            times = []
            for _ in range(args.repeats):
                start = time.perf_counter()
                outputs[blur_scale] = postprocess(maps, depth, replace(params, blur_scale=blur_scale))
                times.append((time.perf_counter() - start) / len(maps) * 1000)
            print(f"blur_scale {blur_scale}, OpenCV threads {threads}: best {min(times):.2f} ms per map, "
                  f"median {statistics.median(times):.2f} ms")  # fmt: skip
    cv2.setNumThreads(default_threads)
    exact, fast = outputs[1], outputs[params.blur_scale]
    ious = [[(p & t).sum() / max((p | t).sum(), 1) for p, t in zip(out > 0.5, labels, strict=True)] for out in (exact, fast)]
    print(f"blur_scale {params.blur_scale} against the exact blur: largest confidence difference {np.abs(fast - exact).max():.4f}, "
          f"largest change of an image's IoU {np.abs(np.subtract(*ious)).max():.4f}")  # fmt: skip


if __name__ == "__main__":
    main()
