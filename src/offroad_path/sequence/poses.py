"""KITTI-format pose files: one row of 12 numbers per frame, the 3x4 camera-to-world matrix."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from offroad_path.errors import InputError


def read_poses(path: Path, expected_rows: int | None = None) -> np.ndarray:
    """(N, 4, 4) camera-to-world poses, checked: 12 finite numbers per row, a rotation in each."""
    rows = []
    try:
        lines = path.read_text().splitlines()
    except (OSError, UnicodeDecodeError) as e:
        raise InputError(path, f"cannot be read as text ({e})") from e
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
    if expected_rows is not None and len(rows) != expected_rows:
        raise InputError(path, f"has {len(rows)} poses, expected {expected_rows} (one per frame)")
    poses = np.tile(np.eye(4), (len(rows), 1, 1))
    if rows:
        poses[:, :3, :] = np.asarray(rows).reshape(-1, 3, 4)
        ortho = np.abs(np.einsum("nji,njk->nik", poses[:, :3, :3], poses[:, :3, :3]) - np.eye(3)).max(axis=(1, 2))
        bad = np.flatnonzero(ortho > 1e-3)
        if len(bad):
            raise InputError(path, f"row {bad[0] + 1} is not a rotation (R^T R differs from I by {ortho[bad[0]]:.3g})")
    return poses


def poses_to_text(poses: np.ndarray) -> str:
    return "".join(" ".join(f"{v:.9e}" for v in pose[:3, :].ravel()) + "\n" for pose in poses)
