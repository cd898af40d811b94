"""Rectified stereo calibration from `calib.txt`: two 3x4 projection matrices, unkeyed or KITTI-keyed;
one camera's recording may give only its own (left) matrix."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from offroad_path.errors import InputError


@dataclass(frozen=True)
class StereoCalibration:
    P_left: np.ndarray  # (3, 4)
    P_right: np.ndarray | None  # (3, 4); None: one camera

    @property
    def K(self) -> np.ndarray:
        return self.P_left[:, :3].copy()

    @property
    def fx(self) -> float:
        return float(self.P_left[0, 0])

    @property
    def baseline_m(self) -> float:
        """Distance from the left to the right camera centre, from P_right = K [I | -B e_x]; 0 for one
        camera (every depth from it is then 0, unknown)."""
        if self.P_right is None:
            return 0.0
        return float((self.P_left[0, 3] - self.P_right[0, 3]) / self.P_left[0, 0])

    def to_text(self) -> str:
        return "".join(" ".join(f"{v:.12e}" for v in P.ravel()) + "\n" for P in (self.P_left, self.P_right) if P is not None)

    @classmethod
    def from_intrinsics(cls, K: np.ndarray, baseline_m: float) -> StereoCalibration:
        P_left = np.hstack([K, np.zeros((3, 1))])
        P_right = P_left.copy()
        P_right[0, 3] = -K[0, 0] * baseline_m
        return cls(P_left, P_right)


def read_calibration(path: Path, keys: tuple[str, str] | None, mono: bool = False) -> StereoCalibration:
    """Parse and check a rectified stereo calib.txt; `keys` picks keyed rows (e.g. P2, P3). For a
    `mono` recording one unkeyed (left) row is enough; two rows are read and checked as for stereo."""
    if mono and keys is None and len(rows := _lines(path)) == 1 and ":" not in rows[0]:
        P_left = _matrix(path, rows[0], "left")
        if P_left[0, 0] <= 0 or P_left[1, 1] <= 0:
            raise InputError(path, "focal lengths must be positive")
        return StereoCalibration(P_left, None)
    P_left, P_right = (_matrix(path, row, name) for row, name in zip(_projection_rows(path, keys), ("left", "right"), strict=True))
    calib = StereoCalibration(P_left, P_right)
    if not np.allclose(P_left[:, :3], P_right[:, :3], rtol=1e-6, atol=1e-6):
        raise InputError(path, "left and right matrices have different intrinsics: the pair is not rectified")
    if P_left[0, 0] <= 0 or P_left[1, 1] <= 0:
        raise InputError(path, "focal lengths must be positive")
    if not calib.baseline_m > 0:
        raise InputError(path, f"the right matrix has no baseline (B = {calib.baseline_m:g} m): P_right[0,3] must be -fx*B with B > 0")
    return calib


def _lines(path: Path) -> list[str]:
    try:
        return [line.strip() for line in path.read_text().splitlines() if line.strip()]
    except (OSError, UnicodeDecodeError) as e:
        raise InputError(path, f"cannot be read as text ({e})") from e


def _projection_rows(path: Path, keys: tuple[str, str] | None) -> list[str]:
    """The left and right rows of calib.txt: keyed ones (`keys`, else P0/P1 or P2/P3 when the file
    has keys), or the file's two unkeyed rows."""
    lines = _lines(path)
    keyed: dict[str, str] = {}
    unkeyed: list[str] = []
    for line in lines:
        head, sep, rest = line.partition(":")
        if sep:
            keyed[head.strip()] = rest
        else:
            unkeyed.append(line)
    if keys is None and not keyed:
        if len(unkeyed) != 2:
            raise InputError(path, f"must hold two rows of 12 numbers (P_left, P_right), found {len(unkeyed)} rows")
        return unkeyed
    if keys is None:
        keys = next((k for k in (("P0", "P1"), ("P2", "P3")) if k[0] in keyed and k[1] in keyed), None)
        if keys is None:
            raise InputError(path, f"has keyed rows {sorted(keyed)} but neither P0/P1 nor P2/P3")
    missing = [k for k in keys if k not in keyed]
    if missing:
        raise InputError(path, f"lacks the row(s) {', '.join(missing)}")
    return [keyed[k] for k in keys]


def _matrix(path: Path, row: str, name: str) -> np.ndarray:
    try:
        values = np.array([float(v) for v in row.split()])
    except ValueError as e:
        raise InputError(path, f"the {name} matrix has a value that is not a number ({e})") from e
    if values.size != 12:
        raise InputError(path, f"the {name} matrix has {values.size} numbers, expected 12")
    if not np.isfinite(values).all():
        raise InputError(path, f"the {name} matrix has a non-finite value")
    return values.reshape(3, 4)
