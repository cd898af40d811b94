"""The odometry scale diagnosis of docs/odometry.md: scale ratio against depth, before and after.

    python benchmarks/odometry_scale.py [--kitti ../shared/data/kitti_seq1] [--rendered data/synthetic/seq_003]

For every step of each sequence, PnP is solved on the tracked stereo points of one depth band only
(the frame-to-frame front end, no refinement) and its translation compared with the true one: a
ratio above 1 means that band's points make the motion too long. The same is repeated with every
disparity raised by 0.2 px (the bias that explains the real footage). Then both estimators' per-step
scale ratios. Prints the tables and writes docs/images/odometry_scale.png.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import cv2
import numpy as np

from offroad_path.config import load_config
from offroad_path.config.label_schema import OdometryConfig
from offroad_path.odometry.features import FrontEnd
from offroad_path.odometry.sequence_trajectory import drift, run_odometry
from offroad_path.sequence import open_sequence

ROOT = Path(__file__).resolve().parents[1]
BANDS = [(0, 8), (8, 15), (15, 25), (25, 40), (40, 60)]


def band_ratios(seq, cfg: OdometryConfig, disparity_offset: float) -> list[float]:
    """Median over steps of |t_PnP| / |t_true| for points in each depth band."""
    front = FrontEnd(seq.calibration, cfg)
    ratios: list[list[float]] = [[] for _ in BANDS]
    for k in range(len(seq) - 1):
        left, right, after = seq.load_left(k, grey=True), seq.load_right(k, grey=True), seq.load_left(k + 1, grey=True)
        corners = front.corners(left, cfg.max_features, cfg.corner_quality)
        matched, ok = front.stereo_match(left, right, corners)
        pl, pr = corners[ok], matched[ok].copy()
        pr[:, 0] -= disparity_offset
        xyz = front.triangulate(pl, pr)
        true = np.linalg.inv(seq.poses[k + 1]) @ seq.poses[k]
        guess = front.project(xyz @ true[:3, :3].T + true[:3, 3])[0]  # the true motion as the tracker's start
        uv, tracked = front.track(left, after, pl, guess)
        for b, (near, far) in enumerate(BANDS):
            use = tracked & (xyz[:, 2] >= near) & (xyz[:, 2] < far)
            motion, inliers = front.pnp(xyz[use], uv[use])
            if motion is not None and inliers.sum() >= 10:
                ratios[b].append(np.linalg.norm(motion[:3, 3]) / np.linalg.norm(true[:3, 3]))
    return [float(np.median(r)) if r else float("nan") for r in ratios]


def step_ratios(seq, cfg: OdometryConfig) -> tuple[np.ndarray, float]:
    run = run_odometry(seq, cfg)
    est = np.linalg.norm(np.diff(run.poses[:, :3, 3], axis=0), axis=1)
    true = np.linalg.norm(np.diff(seq.poses[:, :3, 3], axis=0), axis=1)
    return est[true > 0.1] / true[true > 0.1], drift(run.poses, seq.poses, 20.0, run.pieces)[0].translation_drift_pct


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--kitti", default=str(ROOT.parent / "shared" / "data" / "kitti_seq1"))
    parser.add_argument("--rendered", default=str(ROOT / "data" / "synthetic" / "seq_003"))
    parser.add_argument("--out", default=str(ROOT / "docs" / "images" / "odometry_scale.png"))
    args = parser.parse_args()
    cv2.setNumThreads(1)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cfg = load_config().label.odometry
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    centres = [(a + b) / 2 for a, b in BANDS]
    boxes, labels = [], []
    for name, path in (("KITTI snippet (real)", args.kitti), ("rendered seq_003", args.rendered)):
        seq = open_sequence(path)
        for offset, style in ((0.0, "-o"), (0.2, "--s")):
            ratios = band_ratios(seq, OdometryConfig(**cfg), offset)
            table = ", ".join(f"{a}-{b} m {r:.4f}" for (a, b), r in zip(BANDS, ratios, strict=True))
            print(f"{name}, disparity +{offset:.1f} px: {table}")
            axes[0].plot(centres, ratios, style, label=f"{name}, disparity +{offset:.1f} px")
        for method in ("frame_to_frame", "windowed"):
            ratios, pct = step_ratios(seq, OdometryConfig(**{**cfg, "method": method}))
            spread = f"median {np.median(ratios):.4f}, {ratios.min():.4f} to {ratios.max():.4f}"
            print(f"{name}, {method}: drift {pct:.3f} %, per-step scale {spread}")
            boxes.append(ratios)
            labels.append(f"{name.split(' ')[0]}\n{method}\n{pct:.2f} %")
    axes[0].axhline(1.0, color="grey", lw=0.8)
    axes[0].set(xlabel="depth of the PnP points (m)", ylabel="estimated / true step length", title="Scale ratio by depth band")
    axes[0].legend(fontsize=7)
    axes[1].boxplot(boxes, showfliers=True)
    axes[1].set_xticks(range(1, len(labels) + 1), labels, fontsize=7)
    axes[1].axhline(1.0, color="grey", lw=0.8)
    axes[1].set(ylabel="estimated / true step length", title="Per-step scale and 20 m drift, before and after")
    fig.tight_layout()
    fig.savefig(args.out, dpi=110)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
