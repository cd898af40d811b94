"""Why the windowed odometry solves its bundle adjustment with GTSAM: the same windows solved by
GTSAM and by SciPy's least_squares (sparse finite-difference Jacobian), speed and accuracy.

    python benchmarks/bundle_adjustment.py [--sequences data/synthetic/seq_003 ../shared/data/kitti_seq1]

Runs the windowed VO over each sequence twice: once as shipped (GTSAM Levenberg-Marquardt,
sequential Cholesky) and once with every window solved by `scipy.optimize.least_squares`
(trust-region reflective, Huber loss, the same weights, the same iteration budget, the Jacobian's
sparsity given so that finite differences cost one residual evaluation per group of columns).
Prints milliseconds per window and the 20 m drift of each.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import ClassVar

import cv2
import numpy as np
from scipy.optimize import least_squares
from scipy.sparse import lil_matrix

from offroad_path.config import load_config
from offroad_path.config.label_schema import OdometryConfig
from offroad_path.odometry.sequence_trajectory import drift, run_odometry
from offroad_path.odometry.windowed import WindowedOdometry
from offroad_path.sequence import open_sequence

ROOT = Path(__file__).resolve().parents[1]


class Timed(WindowedOdometry):
    """The shipped estimator, with its bundle adjustment timed."""

    seconds: ClassVar[list[float]] = []

    def _adjust(self) -> None:
        start = time.perf_counter()
        super()._adjust()
        self.seconds.append(time.perf_counter() - start)


class SciPyWindows(Timed):
    """The same windows solved by scipy.optimize.least_squares."""

    seconds: ClassVar[list[float]] = []

    def _adjust(self) -> None:
        if len(self._window) < 2:
            return
        start = time.perf_counter()
        landmarks, count = np.unique(np.concatenate([kf.ids for kf in self._window]), return_counts=True)
        shared = landmarks[count >= 2]
        obs = self._observations(shared)
        if not len(obs):
            return
        kf_i, pt_i = obs[:, 0].astype(int), obs[:, 1].astype(int)
        n_free = len(self._window) - 1  # the oldest keyframe is held fixed
        fixed = np.linalg.inv(self._poses[self._window[0].frame])

        def unpack(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
            rot = np.empty((n_free + 1, 3, 3))
            trans = np.empty((n_free + 1, 3))
            rot[0], trans[0] = fixed[:3, :3], fixed[:3, 3]
            for f in range(n_free):
                rot[f + 1] = cv2.Rodrigues(x[6 * f : 6 * f + 3])[0]
                trans[f + 1] = x[6 * f + 3 : 6 * f + 6]
            return rot, trans, x[6 * n_free :].reshape(-1, 3)

        f = self.front

        def residuals(x: np.ndarray) -> np.ndarray:
            rot, trans, points = unpack(x)
            p = np.einsum("nij,nj->ni", rot[kf_i], points[pt_i]) + trans[kf_i]  # (M, 3) in each camera
            z = np.maximum(p[:, 2], 1e-3)
            u = f.fx * p[:, 0] / z + f.cx
            return np.concatenate(
                [u - obs[:, 2], (u - f.fx * f.baseline / z - obs[:, 3]) / obs[:, 5], f.fy * p[:, 1] / z + f.cy - obs[:, 4]]
            )

        x0 = []
        for kf in self._window[1:]:
            world_to_camera = np.linalg.inv(self._poses[kf.frame])
            x0 += [*cv2.Rodrigues(world_to_camera[:3, :3])[0][:, 0], *world_to_camera[:3, 3]]
        x0 = np.concatenate([x0, self._points[shared].ravel()])
        sparsity = jacobian_sparsity(kf_i, pt_i, n_free, len(x0))
        result = least_squares(
            residuals, x0, jac_sparsity=sparsity, loss="huber", f_scale=self.cfg.huber_px, method="trf",
            x_scale="jac", max_nfev=self.cfg.window_iterations * 2,
        )  # fmt: skip
        rot, trans, points = unpack(result.x)
        for i, kf in enumerate(self._window[1:], start=1):
            world_to_camera = np.eye(4)
            world_to_camera[:3, :3], world_to_camera[:3, 3] = rot[i], trans[i]
            self._poses[kf.frame] = np.linalg.inv(world_to_camera)
        self._points[shared] = points
        self.seconds.append(time.perf_counter() - start)

    def _observations(self, shared: np.ndarray) -> np.ndarray:
        """(M, 6): keyframe index, index into `shared`, uL, uR, v, the right image's sigma."""
        obs = []
        for i, kf in enumerate(self._window):
            sigma = 2.0 ** (self._noise_levels(np.maximum(kf.uv_l[:, 0] - kf.uv_r[:, 0], 1e-3)) / 2)
            for j in np.flatnonzero(np.isin(kf.ids, shared)):
                obs.append((i, np.searchsorted(shared, kf.ids[j]), kf.uv_l[j, 0], kf.uv_r[j, 0], kf.uv_l[j, 1], sigma[j]))
        return np.array(obs)


def jacobian_sparsity(kf_i: np.ndarray, pt_i: np.ndarray, n_free: int, n_params: int) -> lil_matrix:
    """Which parameters each residual (uL, uR, v blocks of M rows) depends on: its keyframe's six
    (none for the fixed one) and its landmark's three."""
    sparsity = lil_matrix((3 * len(kf_i), n_params), dtype=int)
    rows = np.arange(len(kf_i))
    free = kf_i > 0
    for block in range(3):
        for c in range(3):
            sparsity[block * len(kf_i) + rows, 6 * n_free + 3 * pt_i + c] = 1
        for c in range(6):
            sparsity[block * len(kf_i) + rows[free], 6 * (kf_i[free] - 1) + c] = 1
    return sparsity


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    default = [str(ROOT / "data" / "synthetic" / "seq_003"), str(ROOT.parent / "shared" / "data" / "kitti_seq1")]
    parser.add_argument("--sequences", nargs="+", default=default)
    args = parser.parse_args()
    cv2.setNumThreads(1)
    import offroad_path.odometry.sequence_trajectory as trajectory

    cfg = OdometryConfig(**load_config().label.odometry)
    for path in args.sequences:
        seq = open_sequence(path)
        for name, estimator in (("gtsam", Timed), ("scipy", SciPyWindows)):
            estimator.seconds.clear()
            trajectory.ESTIMATORS["windowed"] = estimator  # run_odometry builds this class
            run = run_odometry(seq, cfg)
            result = drift(run.poses, seq.poses, 20.0, run.pieces)[0]
            print(
                f"{Path(path).name} {name}: {1000 * np.mean(estimator.seconds):.1f} ms per window over {len(estimator.seconds)} windows, "
                f"drift {result.translation_drift_pct:.3f} %, scale ratio {result.scale_ratio_min:.4f} to {result.scale_ratio_max:.4f}"
            )
    trajectory.ESTIMATORS["windowed"] = WindowedOdometry


if __name__ == "__main__":
    main()
