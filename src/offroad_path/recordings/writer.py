"""Write a raw stereo source as a rectified sequence in this project's layout (docs/design.md):
image_l/, image_r/, calib.txt, times.txt, meta.json, poses.txt when the source has poses, and
preview.jpg, a contact sheet of rectified pairs with horizontal lines. A source of one camera
(ingest.mono) writes image_l/ only, undistorted, and a calib.txt of its one projection."""

from __future__ import annotations

import json
import logging
from pathlib import Path

import cv2
import numpy as np
from omegaconf import DictConfig

from offroad_path import __version__
from offroad_path.errors import InputError
from offroad_path.geometry.path import path_length
from offroad_path.recordings.rectify import Rectifier, Undistorter, contact_sheet, epipolar_error
from offroad_path.recordings.sources import BagSource, VideoSource
from offroad_path.recordings.sync import Subsampler
from offroad_path.sequence.meta import FOOTPRINT, GENERATOR, INGESTED
from offroad_path.sequence.png import FAST_PNG
from offroad_path.sequence.poses import poses_to_text
from offroad_path.utils.media import write_image

log = logging.getLogger(__name__)
CHECKED_PAIRS = 8  # pairs spread over the drive whose epipolar error is measured
PREVIEW_PAIRS = 4


def rectified_poses(camera_poses: np.ndarray, rectifier: Rectifier | Undistorter) -> np.ndarray:
    """Raw left camera poses to rectified left camera poses, relative to the first (KITTI's
    convention): a point x_rect is R_left^T x_rect in the raw camera."""
    to_raw = np.eye(4)
    to_raw[:3, :3] = rectifier.R_left.T
    poses = camera_poses @ to_raw
    return np.linalg.inv(poses[0])[None] @ poses


def write_sequence(source: BagSource | VideoSource, c: DictConfig, out: Path) -> dict:
    """Rectify every kept pair of `source` into `out`; returns what meta.json says."""
    output_size = (c.width, c.height)
    if source.mono:
        rectifier, subs = Undistorter(source.camera, source.input_size, output_size, c.alpha), ("image_l",)
    else:
        rectifier, subs = Rectifier(source.rig, source.input_size, output_size, c.alpha), ("image_l", "image_r")
    for sub in subs:
        (out / sub).mkdir()
    sampler = Subsampler(c.fps)
    times = []
    for t, raw_left, raw_right in source.pairs(sampler.keep):
        name = f"{len(times):06d}.png"
        for sub, image in zip(subs, rectifier(raw_left, raw_right), strict=True):
            write_image(out / sub / name, image, FAST_PNG)
        times.append(t)
    if len(times) < 2:
        what = "frame(s)" if source.mono else "stereo pair(s) after synchronisation and"
        raise InputError(source.path, f"yields {len(times)} {what} after ingest.fps; a sequence needs at least 2")
    times = np.asarray(times)
    calibration = rectifier.calibration
    (out / "calib.txt").write_text(calibration.to_text())
    (out / "times.txt").write_text("".join(f"{t:.6f}\n" for t in times - times[0]))
    meta = {GENERATOR: INGESTED, "generator_version": __version__} | source.describe()
    camera_poses = source.camera_poses(times)
    if camera_poses is not None:
        poses = rectified_poses(camera_poses, rectifier)
        (out / "poses.txt").write_text(poses_to_text(poses))
        meta["distance_m"] = path_length(poses)
    check = None if source.mono else _epipolar(out, len(times), c)
    meta |= {
        "frames": len(times),
        "start_stamp_s": float(times[0]),
        "fps": (len(times) - 1) / float(times[-1] - times[0]) if times[-1] > times[0] else None,
        "width": c.width,
        "height": c.height,
        "alpha": c.alpha,
        "baseline_m": calibration.baseline_m,
        "fx": calibration.fx,
        "raw_size": list(source.input_size),
        "rectified_pitch_change_deg": rectifier.pitch_change_deg,
        "epipolar_error_px": check,
    } | _footprint(c, rectifier)
    (out / "meta.json").write_text(json.dumps(meta, indent=2) + "\n")
    _preview(out, len(times), subs)
    return meta


def _footprint(c: DictConfig, rectifier: Rectifier) -> dict:
    """The vehicle footprint for meta.json, in the rectified camera: its pitch includes the
    rectifying rotation (the raw camera's pitch when the user gave none)."""
    values = {meta_key: c.footprint[key] for key, meta_key in FOOTPRINT.items() if c.footprint[key] is not None}
    values["camera_pitch_deg"] = float(c.footprint.camera_pitch_deg or 0.0) + rectifier.pitch_change_deg
    return values


def _spread(count: int, n: int) -> list[int]:
    return sorted({int(i) for i in np.linspace(0, count - 1, min(n, count))})


def _read_pair(out: Path, i: int, subs: tuple[str, ...] = ("image_l", "image_r")) -> tuple[np.ndarray, ...]:
    return tuple(cv2.imread(str(out / sub / f"{i:06d}.png"), cv2.IMREAD_UNCHANGED) for sub in subs)


def _epipolar(out: Path, count: int, c: DictConfig) -> float | None:
    """The median vertical disparity over pairs spread along the drive; warns loudly above the limit."""
    checks = [epipolar_error(*_read_pair(out, i), max_disparity_px=c.width / 4) for i in _spread(count, CHECKED_PAIRS)]
    checks = [e for e in checks if e is not None]
    if not checks:
        log.warning("%s: too few features match between left and right to measure the rectification; check preview.jpg", out.name)
        return None
    error = float(np.median([e.median_px for e in checks]))
    if error > c.max_epipolar_px:
        log.warning(
            "RECTIFICATION IS POOR: matched features lie %.2f px apart vertically (median; limit ingest.max_epipolar_px = %g). "
            "The calibration does not fit this recording; stereo depth and visual odometry will be wrong. See preview.jpg.",
            error,
            c.max_epipolar_px,
        )
    return error


def _preview(out: Path, count: int, subs: tuple[str, ...]) -> None:
    sheet = contact_sheet([_read_pair(out, i, subs) for i in _spread(count, PREVIEW_PAIRS)])
    write_image(out / "preview.jpg", sheet, [cv2.IMWRITE_JPEG_QUALITY, 85])
