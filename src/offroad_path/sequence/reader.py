"""Reading recordings: this project's layout (see docs/design.md) and KITTI's odometry layout, stereo
or one camera (no right folder: a mono sequence, labelled from poses that come from elsewhere).

Everything is validated on opening, so that a later stage never meets a half-good sequence:
every error names the file and says what is wrong with it.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
from PIL import UnidentifiedImageError
from PIL.PngImagePlugin import PngImageFile

from offroad_path.errors import InputError
from offroad_path.sequence.calibration import StereoCalibration, read_calibration
from offroad_path.sequence.poses import read_poses

MAX_IMAGE_PIXELS = 50_000_000  # default cap on an image's declared size (8K is 33 million)
MIN_IMAGE_SIDE = 32  # pixels: the networks' coarsest features are 32 pixels apart; a smaller image is no camera's view
# (left folder, right folder, calib keys) in order of preference; None keys: two unkeyed rows.
LAYOUTS = (("image_l", "image_r", None), ("image_2", "image_3", ("P2", "P3")), ("image_0", "image_1", ("P0", "P1")))


@dataclass
class Sequence:
    root: Path
    left: list[Path]
    right: list[Path] | None  # None: one camera (a mono sequence)
    calibration: StereoCalibration
    image_size: tuple[int, int]  # (width, height)
    poses: np.ndarray | None = None  # (N, 4, 4) left camera to world
    poses_path: Path | None = None
    times: np.ndarray | None = None
    meta: dict = field(default_factory=dict)
    depth: list[Path] | None = None
    semantic: list[Path] | None = None
    steering: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.left)

    @property
    def name(self) -> str:
        return self.root.name

    def load_left(self, i: int, grey: bool = False) -> np.ndarray:
        return read_image(self.left[i], grey)

    @property
    def mono(self) -> bool:
        return self.right is None

    def require_stereo(self, what: str) -> None:
        """InputError naming the missing right images when this sequence has one camera."""
        if self.right is None:
            raise InputError(self.root, f"has one camera (no right images): {what} needs a stereo pair")

    def load_right(self, i: int, grey: bool = False) -> np.ndarray:
        self.require_stereo("the right image")
        return read_image(self.right[i], grey)

    def load_depth(self, i: int) -> np.ndarray:
        """Ground-truth depth in metres (float32), 0 where there is none."""
        if self.depth is None:
            raise InputError(self.root / "depth", "this sequence has no ground-truth depth")
        raw = cv2.imread(str(self.depth[i]), cv2.IMREAD_UNCHANGED)
        if raw is None or raw.dtype != np.uint16 or raw.ndim != 2:
            raise InputError(self.depth[i], "not a single-channel 16-bit PNG")
        return raw.astype(np.float32) / 1000.0

    def load_semantic(self, i: int) -> np.ndarray:
        if self.semantic is None:
            raise InputError(self.root / "semantic", "this sequence has no semantic maps")
        raw = cv2.imread(str(self.semantic[i]), cv2.IMREAD_UNCHANGED)
        if raw is None or raw.ndim != 2:
            raise InputError(self.semantic[i], "not a single-channel PNG")
        return raw


def read_image(path: Path, grey: bool = False) -> np.ndarray:
    """An image as RGB (H, W, 3) uint8, or grey (H, W) uint8."""
    image = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE if grey else cv2.IMREAD_COLOR)
    if image is None:
        raise InputError(path, "cannot be decoded as an image")
    return image if grey else cv2.cvtColor(image, cv2.COLOR_BGR2RGB)


def png_size(path: Path) -> tuple[int, int]:
    """(width, height) from a PNG header, read by Pillow's PNG plugin without decoding the image
    (not Image.open, which refuses a huge size with its own error before the caller can name the
    setting that limits it)."""
    try:
        with PngImageFile(path) as image:
            return image.size
    except (SyntaxError, UnidentifiedImageError) as e:  # Pillow's word for a bad signature or header
        raise InputError(path, "is not a PNG file (bad signature or header)") from e
    except OSError as e:
        raise InputError(path, f"cannot be read ({e.strerror or e})") from e


def find_sequences(root: str | Path) -> list[Path]:
    """Sequence folders under root (root itself if it is one), sorted by path."""
    root = Path(root)
    if not root.is_dir():
        raise InputError(root, "is not a directory")
    if (root / "calib.txt").is_file():
        return [root]
    found = sorted(p.parent for p in root.rglob("calib.txt"))
    # A folder of left images with no calibration beside it is a recording, not something to skip.
    for left in sorted(p for layout in LAYOUTS for p in root.rglob(layout[0]) if p.is_dir()):
        if not (left.parent / "calib.txt").is_file() and left.parent not in found:
            raise InputError(left.parent / "calib.txt", f"is missing: {left.parent} has {left.name}/ but no calibration")
    if not found:
        raise InputError(root, "holds no sequence (no calib.txt below it)")
    return found


def sequence_names(roots: list[Path], in_dir: Path) -> list[str]:
    """Output folder names of sequences found under in_dir: the path below it (KITTI's sequences/05
    becomes sequences_05)."""
    return ["_".join(root.relative_to(in_dir).parts) or root.name for root in roots]


def open_sequence(root: str | Path) -> Sequence:
    root = Path(root)
    calib_path = root / "calib.txt"
    if not calib_path.is_file():
        raise InputError(calib_path, "is missing")
    layout = next((layout for layout in LAYOUTS if (root / layout[0]).is_dir()), None)
    if layout is None:
        raise InputError(root, "has no image_l/, image_2/ or image_0/ folder of left images")
    left_dir, right_dir, keys = layout
    mono = not (root / right_dir).is_dir()
    calibration = read_calibration(calib_path, keys, mono=mono)
    left, right = (_left_images(root / left_dir), None) if mono else _stereo_pairs(root / left_dir, root / right_dir)
    image_size = _common_size(left + (right or []))
    _check_principal_point(calib_path, calibration, image_size)
    n = len(left)

    poses_path = _find_poses(root)
    poses = read_poses(poses_path, expected_rows=n) if poses_path else None
    times = read_times(root / "times.txt", n) if (root / "times.txt").is_file() else None
    steering = _read_column(root / "steering.txt", n) if (root / "steering.txt").is_file() else None
    meta = _read_meta(root / "meta.json")
    depth = _frames_like(root / "depth", left)
    semantic = _frames_like(root / "semantic", left)
    return Sequence(root, left, right, calibration, image_size, poses, poses_path, times, meta, depth, semantic, steering)


def _check_principal_point(path: Path, calibration: StereoCalibration, image_size: tuple[int, int]) -> None:
    """The principal point lies in the middle half of the images (a real lens's is within a few per
    cent of the centre): a calibration made for another image size (images resized, or cropped, after
    calibrating) would otherwise project every label off the image, and the label stage drop them all."""
    w, h = image_size
    cx, cy = calibration.K[0, 2], calibration.K[1, 2]
    if not (w / 4 <= cx <= 3 * w / 4 and h / 4 <= cy <= 3 * h / 4):
        raise InputError(
            path,
            f"principal point ({cx:.1f}, {cy:.1f}) px lies outside the middle half of the {w}x{h} images: "
            "the calibration is for another image size (resized or cropped images need their own calibration)",
        )


def _left_images(left_dir: Path) -> list[Path]:
    left = sorted(left_dir.glob("*.png"))
    if not left:
        raise InputError(left_dir, "holds no PNG images")
    return left


def _stereo_pairs(left_dir: Path, right_dir: Path) -> tuple[list[Path], list[Path]]:
    left = _left_images(left_dir)
    right = sorted(right_dir.glob("*.png"))
    left_names = [p.name for p in left]
    right_names = [p.name for p in right]
    if left_names != right_names:
        missing = sorted(set(left_names) - set(right_names))
        extra = sorted(set(right_names) - set(left_names))
        what = (
            f"lacks {len(missing)} right image(s) of the left ones, first {missing[0]}"
            if missing
            else f"has {len(extra)} image(s) with no left partner, first {extra[0]}"
        )
        raise InputError(right_dir, f"{what} ({len(left)} left, {len(right)} right)")
    return left, [right_dir / name for name in left_names]


def check_pixels(path: Path, width: int, height: int, max_pixels: int = MAX_IMAGE_PIXELS) -> None:
    """Refuse, from its header, an image too large to decode safely (a decompression bomb), or too
    small to be a camera's view of the ground ahead (under MIN_IMAGE_SIDE pixels on a side)."""
    if width * height > max_pixels:
        raise InputError(path, f"declares {width}x{height} pixels, more than the {max_pixels:,} allowed; it is not decoded")
    if min(width, height) < MIN_IMAGE_SIDE:
        raise InputError(path, f"is {width}x{height} pixels: a camera image has at least {MIN_IMAGE_SIDE} on each side")


def _common_size(paths: list[Path]) -> tuple[int, int]:
    size = png_size(paths[0])
    check_pixels(paths[0], *size)
    for p in paths[1:]:
        if (s := png_size(p)) != size:
            raise InputError(p, f"is {s[0]}x{s[1]}, but {paths[0]} is {size[0]}x{size[1]}: every image must have one size")
    return size


def _find_poses(root: Path) -> Path | None:
    for candidate in (root / "poses.txt", root / "poses" / f"{root.name}.txt", root.parent.parent / "poses" / f"{root.name}.txt"):
        if candidate.is_file():
            return candidate
    return None


def _read_column(path: Path, expected_rows: int) -> np.ndarray:
    try:
        values = np.loadtxt(path, dtype=np.float64, ndmin=1)
    except ValueError as e:
        raise InputError(path, f"is not one number per line ({e})") from e
    if values.ndim != 1 or len(values) != expected_rows:
        raise InputError(path, f"has {len(values)} rows of one number, expected {expected_rows} (one per frame)")
    if not np.isfinite(values).all():
        raise InputError(path, f"has a non-finite value at row {int(np.flatnonzero(~np.isfinite(values))[0]) + 1}")
    return values


FRAME_INTERVAL_S = (1e-3, 10.0)  # the median time between frames a times.txt in seconds can give
UNITS = {"milliseconds": 1e-3, "microseconds": 1e-6, "nanoseconds": 1e-9}


def read_times(path: Path, expected_rows: int) -> np.ndarray:
    """times.txt: one time in seconds per frame, each after the one before; InputError naming the
    file, the row or the unit it looks to be in (a pose-jump check reads speeds from these)."""
    times = _read_column(path, expected_rows)
    if len(times) < 2:
        return times
    steps = np.diff(times)
    if len(back := np.flatnonzero(~(steps > 0))):
        i = back[0]
        raise InputError(
            path, f"row {i + 2} ({times[i + 1]:.9g}) is not after row {i + 1} ({times[i]:.9g}): one time per frame, increasing"
        )
    low, high = FRAME_INTERVAL_S
    if not low <= (median := float(np.median(steps))) <= high:
        unit = next((name for name, scale in UNITS.items() if low <= median * scale <= high), None)
        raise InputError(
            path,
            f"frames are {median:.6g} apart (median): times are in seconds, a frame every {low:g} to {high:g} s"
            + (f"; these look like {unit}" if unit else ""),
        )
    return times


def _read_meta(path: Path) -> dict:
    if not path.is_file():
        return {}
    try:
        meta = json.loads(path.read_text())
    except json.JSONDecodeError as e:
        raise InputError(path, f"is not valid JSON ({e})") from e
    if not isinstance(meta, dict):
        raise InputError(path, "must hold a JSON object")
    return meta


def _frames_like(folder: Path, left: list[Path]) -> list[Path] | None:
    if not folder.is_dir():
        return None
    paths = [folder / p.name for p in left]
    missing = [p for p in paths if not p.is_file()]
    if missing:
        raise InputError(folder, f"lacks {len(missing)} of the {len(left)} frames, first {missing[0].name}")
    return paths
