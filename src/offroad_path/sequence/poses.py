"""KITTI-format pose files: one row of 12 numbers per frame, the 3x4 camera-to-world matrix."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from offroad_path.errors import InputError


def read_poses(
    path: Path, expected_rows: int | None = None, max_steps_m: np.ndarray | None = None, speed_setting: str = "label.poses.max_speed_mps"
) -> np.ndarray:
    """(N, 4, 4) camera-to-world poses, checked: 12 finite numbers per row, a rotation in each (R^T R = I
    and det R = +1: a mirrored frame is no pose), and, with max_steps_m (N - 1,), no step from one pose
    to the next longer than it allows."""
    rows = _rows(path)
    if expected_rows is not None and len(rows) != expected_rows:
        raise InputError(path, f"has {len(rows)} poses, expected {expected_rows} (one per frame)")
    poses = np.tile(np.eye(4), (len(rows), 1, 1))
    if rows:
        poses[:, :3, :] = np.asarray(rows).reshape(-1, 3, 4)
        _check_rotations(path, poses[:, :3, :3])
    if max_steps_m is not None and len(poses) > 1:
        steps = np.linalg.norm(np.diff(poses[:, :3, 3], axis=0), axis=1)
        if len(far := np.flatnonzero(~(steps <= max_steps_m))):
            i = far[0]
            raise InputError(path, f"row {i + 2} is {steps[i]:.3g} m from row {i + 1}, more than {max_steps_m[i]:.3g} m at {speed_setting}")
    return poses


def _rows(path: Path) -> list[list[float]]:
    """The file's rows of 12 finite numbers (blank lines skipped); InputError naming the first bad row."""
    try:
        lines = path.read_text().splitlines()
    except (OSError, UnicodeDecodeError) as e:
        raise InputError(path, f"cannot be read as text ({e})") from e
    rows = []
    for number, line in enumerate(lines, start=1):
        if not line.strip():
            continue
        try:
            values = [float(v) for v in line.split()]
        except ValueError as e:
            raise InputError(path, f"row {number} has a value that is not a number ({e})") from e
        if len(values) != 12:
            raise InputError(path, f"row {number} has {len(values)} numbers, expected 12")
        if not np.isfinite(values).all():
            raise InputError(path, f"row {number} has a non-finite value")
        rows.append(values)
    return rows


def _check_rotations(path: Path, rotations: np.ndarray) -> None:
    ortho = np.abs(np.einsum("nji,njk->nik", rotations, rotations) - np.eye(3)).max(axis=(1, 2))
    if len(bad := np.flatnonzero(~(ortho <= 1e-3))):
        raise InputError(path, f"row {bad[0] + 1} is not a rotation (R^T R differs from I by {ortho[bad[0]]:.3g})")
    det = np.linalg.det(rotations)
    if len(mirrored := np.flatnonzero(det < 0)):
        i = mirrored[0]
        raise InputError(path, f"row {i + 1} is a reflection, not a rotation (det R = {det[i]:.3g}: a column negated?)")


def max_steps(times: np.ndarray | None, frames: int, max_speed_mps: float) -> np.ndarray:
    """(frames - 1,) the longest step between consecutive poses at `max_speed_mps`: over each frame
    interval of times.txt, or over 1 s per frame for a sequence without one."""
    dt = np.diff(times) if times is not None and len(times) == frames else np.ones(max(frames - 1, 0))
    return max_speed_mps * np.maximum(dt, 0.0)


def poses_to_text(poses: np.ndarray) -> str:
    return "".join(" ".join(f"{v:.9e}" for v in pose[:3, :].ravel()) + "\n" for pose in poses)
