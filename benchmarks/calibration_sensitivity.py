"""How far the odometry's drift moves when the calibration moves by far less than it is known to.

    python benchmarks/calibration_sensitivity.py SEQUENCE [SEQUENCE ...] [--draws 20] [--scale 1e-7] [--set KEY=VALUE ...]

Each sequence's odometry (the label stage's, `label.odometry`; --set overrides it, e.g.
label.odometry.method=frame_to_frame) runs with the calibration as given, then --draws times with
fx, fy, cx, cy and the baseline each scaled by 1 + s r, r drawn uniformly from [1e-8, --scale] and s
a random sign (seeded: the same draws every run). Prints the drift over 20 m as given, its range
over the draws and the spread (largest minus smallest, in percentage points): a stable estimator
moves its drift by about as little as the calibration moved.
"""

from __future__ import annotations

import argparse
import dataclasses

import cv2
import numpy as np
from common import positive_float, positive_int
from omegaconf import OmegaConf

from offroad_path.config import load_config
from offroad_path.config.label_schema import OdometryConfig
from offroad_path.odometry.perturb import jittered
from offroad_path.odometry.sequence_trajectory import drift, run_odometry
from offroad_path.report.tables import grid_head, grid_row
from offroad_path.sequence import open_sequence
from offroad_path.sequence.reader import Sequence


def perturbed(sequence: Sequence, scale: float, rng: np.random.Generator) -> Sequence:
    """`sequence` with its intrinsics and baseline each scaled by 1 +- a relative amount up to `scale`."""
    return dataclasses.replace(sequence, calibration=jittered(sequence.calibration, scale, rng))


def drift_pct(sequence: Sequence, cfg: OdometryConfig) -> float:
    run = run_odometry(sequence, cfg)
    found, problem = drift(run.poses, sequence.poses, 20.0, run.pieces)
    if problem:
        raise SystemExit(f"error: {sequence.root}: {problem}")
    return found.translation_drift_pct


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("sequences", nargs="+", help="sequence folders with true poses")
    parser.add_argument("--draws", type=positive_int, default=20)
    parser.add_argument("--scale", type=positive_float, default=1e-7, help="largest relative change of each calibration value")
    parser.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE", help="config overrides (label.odometry...)")
    args = parser.parse_args()
    cv2.setNumThreads(1)
    cfg = OdometryConfig(**OmegaConf.to_container(load_config(*args.set).label.odometry, resolve=True))
    print(f"odometry {cfg.method}, {args.draws} draws up to {args.scale:g} of each value")
    print(grid_head(["sequence", "drift as given", "range over the draws", "spread (points)"]))
    for root in args.sequences:
        sequence = open_sequence(root)
        rng = np.random.default_rng(0)
        given = drift_pct(sequence, cfg)
        drawn = [drift_pct(perturbed(sequence, args.scale, rng), cfg) for _ in range(args.draws)]
        spread = max([given, *drawn]) - min([given, *drawn])
        print(grid_row([root, f"{given:.3f} %", f"{min(drawn):.3f} to {max(drawn):.3f} %", f"{spread:.3f}"]), flush=True)


if __name__ == "__main__":
    main()
