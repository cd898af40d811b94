"""The odometry's self-calibrated disparity offset, against rigs with a known one.

    python benchmarks/disparity_offset.py [--offsets 0 -0.1 -0.2 -0.3] [--open 4] [--set KEY=VALUE ...]

Every sequence of --in-dir (the rendered laptop preset, test worlds included) and the real KITTI
snippet is seen through a rig whose right image is resampled by each --offsets value
(`offroad_path.sequence.misaligned`: observed disparity = true + offset), and the windowed VO is run
on it twice: with the offset estimated (the config's default) and taken as zero
(`label.odometry.disparity_offset_sigma_px=0`, the estimator before). With --open N, N drives of a
fast, open variant of the world are rendered first (few trees, bushes and obstacles, 2 m per frame)
and run the same way. Prints one table row per (recordings, rig offset, estimator): drift over 20 m
(mean and worst sequence) and the offset the estimator ended each sequence with (mean, range).
--set passes overrides to the config (e.g. label.odometry.disparity_offset_every=1).

What a resampled rig's offset is, as the odometry's stereo matcher sees it, is measured with
--matcher: every 10th frame's corners are matched left to right as the odometry matches them, and
the matched disparity compared with the true one from the rendered depth (where the depth is smooth
around the corner, nearer than 30 m); the table gives the median difference per rig offset.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import cv2
import numpy as np

from offroad_path.config import load_config
from offroad_path.config.label_schema import OdometryConfig
from offroad_path.odometry.features import FrontEnd
from offroad_path.odometry.sequence_trajectory import drift, run_odometry
from offroad_path.report.tables import grid_head, grid_row
from offroad_path.sequence import find_sequences, open_sequence
from offroad_path.sequence.misaligned import misaligned
from offroad_path.utils.parallel import map_processes

ROOT = Path(__file__).resolve().parents[1]
OPEN_WORLD = ["world.trees_per_hectare=3", "world.bushes_per_hectare=8", "world.obstacles_per_100m=0.5", "world.fps=2.5"]


def one_run(job: tuple[str, float, dict]) -> tuple[float, float | None]:
    """(drift %, the offset the estimator ended with) of one sequence through one rig."""
    cv2.setNumThreads(1)
    root, offset, cfg = job
    seq = misaligned(open_sequence(root), offset) if offset else open_sequence(root)
    run = run_odometry(seq, OdometryConfig(**cfg))
    result, problem = drift(run.poses, seq.poses, 20.0, run.pieces)
    if problem:
        raise RuntimeError(f"{root}: {problem}")
    return result.translation_drift_pct, run.disparity_offset_px


def matcher_offset(job: tuple[str, float, dict]) -> np.ndarray:
    """Matched minus true disparity of the corners of every 10th frame of a rendered sequence."""
    cv2.setNumThreads(1)
    root, offset, cfg = job
    seq = open_sequence(root)
    seq = misaligned(seq, offset) if offset else seq
    odometry = OdometryConfig(**cfg)
    front = FrontEnd(seq.calibration, odometry)
    found = []
    for k in range(0, len(seq), 10):
        left, right, depth = seq.load_left(k, grey=True), seq.load_right(k, grey=True), seq.load_depth(k)
        corners = front.corners(left, odometry.max_features, odometry.corner_quality)
        matched, ok = front.stereo_match(left, right, corners)
        u, v = np.round(corners).astype(int).T
        around = np.stack([depth[np.clip(v + dv, 0, depth.shape[0] - 1), np.clip(u + du, 0, depth.shape[1] - 1)]
                           for dv in (-1, 0, 1) for du in (-1, 0, 1)])  # fmt: skip
        z = depth[v, u]
        use = ok & (z > 0) & (z < 30) & (np.ptp(around, axis=0) < 0.02 * z)
        found.append(corners[use, 0] - matched[use, 0] - front.fx * front.baseline / z[use])
    return np.concatenate(found)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--in-dir", default=str(ROOT / "data" / "synthetic"))
    parser.add_argument("--kitti", default=str(ROOT.parent / "shared" / "data" / "kitti_seq1"))
    parser.add_argument("--offsets", type=float, nargs="+", default=[0.0, -0.1, -0.2, -0.3])
    parser.add_argument("--open", type=int, default=0, help="render this many drives of the open, fast world")
    parser.add_argument("--set", nargs="*", default=[], help="config overrides")
    parser.add_argument("--estimated-only", action="store_true", help="leave out the runs with the offset taken as 0")
    parser.add_argument("--matcher", action="store_true", help="only the offset the stereo matcher sees, from the depth maps")
    args = parser.parse_args()
    cfg = load_config(*args.set)
    if args.matcher:
        roots = [str(p) for p in find_sequences(args.in_dir)]
        print(grid_head(["rig offset (px)", "matched minus true disparity: median (px)", "corners"]))
        for offset in args.offsets:
            found = np.concatenate(map_processes(matcher_offset, [(root, offset, dict(cfg.label.odometry)) for root in roots]))
            print(grid_row([f"{offset:+.1f}", f"{np.median(found):+.3f}", f"{len(found)}"]), flush=True)
        return
    estimating = dict(cfg.label.odometry)
    fixed = estimating | {"disparity_offset_sigma_px": 0.0}
    with tempfile.TemporaryDirectory() as tmp:
        sets = {"rendered laptop preset": [str(p) for p in find_sequences(args.in_dir)]}
        if args.open:
            from offroad_path.world.record import Drive, record_sequences

            world = load_config(*args.set, *OPEN_WORLD).world
            record_sequences(world, [Drive(f"open_{i}", 1000 + i) for i in range(args.open)], Path(tmp))
            sets["open world, 2 m per frame"] = [str(p) for p in find_sequences(tmp)]
        if (Path(args.kitti) / "calib.txt").is_file():
            sets["KITTI snippet (real)"] = [args.kitti]
        print(
            grid_head(
                ["recordings", "rig offset (px)", "offset", "drift over 20 m: mean, worst (%)", "estimated offset: mean [min, max] (px)"]
            ),
            flush=True,
        )
        for title, roots in sets.items():
            for offset in args.offsets:
                estimators = [("estimated", estimating)] if args.estimated_only else [("taken as 0", fixed), ("estimated", estimating)]
                for name, odometry in estimators:
                    results = map_processes(one_run, [(root, offset, odometry) for root in roots])
                    drifts = [d for d, _ in results]
                    found = np.array([o for _, o in results if o is not None])
                    estimate = f"{found.mean():+.3f} [{found.min():+.3f}, {found.max():+.3f}]" if len(found) else "-"
                    drift = f"{np.mean(drifts):.3f}, {max(drifts):.3f}"
                    print(grid_row([f"{title} ({len(roots)})", f"{offset:+.1f}", name, drift, estimate]), flush=True)


if __name__ == "__main__":
    main()
