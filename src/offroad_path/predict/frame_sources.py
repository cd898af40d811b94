"""Where predict's frames come from: a folder of images, a stereo sequence, a video file, or a ROS
bag (ROS 1, ROS 2 or MCAP; its stereo pair rectified as ingest rectifies it)."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from omegaconf import DictConfig, OmegaConf

from offroad_path.errors import InputError
from offroad_path.geometry.stereo import compute_disparity, depth_from_disparity, sgbm
from offroad_path.recordings.video import check_complete
from offroad_path.sequence.reader import MAX_IMAGE_PIXELS, check_pixels, open_sequence, png_size

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp")


@dataclass
class Frame:
    name: str  # output file stem
    image: np.ndarray  # RGB (H, W, 3) uint8
    depth: np.ndarray | None = None  # metres (H, W), 0 unknown; stereo sequences and bags only
    header: Any = None  # a bag's: the left image message's std_msgs/Header (stamp, frame_id)


@dataclass
class FrameSource:
    kind: str  # folder | sequence | video | bag
    path: Path
    count: int | None  # None: unknown until read
    fps: float | None
    frames: Iterator[Frame]
    K: np.ndarray | None = None  # a bag's rectified left camera (3, 3), at the frames' size
    pitch_change_deg: float = 0.0  # a bag's: how much further down the rectified camera looks than the raw one


def is_bag(path: Path) -> bool:
    return path.suffix.lower() in (".bag", ".mcap") if path.is_file() else (path / "metadata.yaml").is_file()


def open_source(
    path: str | Path,
    disparity_cfg=None,
    max_frames: int | None = None,
    max_pixels: int = MAX_IMAGE_PIXELS,
    ingest: DictConfig | None = None,
) -> FrameSource:
    """Frames of `path`; stereo depth (StereoSGBM with disparity_cfg) for sequences and bags when
    given a config. Every image's declared size is checked against max_pixels before anything is
    decoded. A bag is read with `ingest`'s topics, calibration and rectified size."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"{path}: no such folder, video or bag")
    if path.is_dir() and (path / "calib.txt").is_file():
        return _sequence(path, disparity_cfg, max_frames, max_pixels)
    if is_bag(path):
        return _bag(path, ingest, disparity_cfg, max_frames)
    if path.is_dir():
        return _folder(path, max_frames, max_pixels)
    return _video(path, max_frames, max_pixels)


def image_size(path: Path) -> tuple[int, int]:
    """(width, height) from an image file's header, without decoding its pixels."""
    if path.suffix.lower() == ".png":
        return png_size(path)
    from PIL import Image

    try:
        with Image.open(path) as image:
            return image.size
    except Image.DecompressionBombError as e:  # Pillow's own cap, far above ours, refuses it first
        raise ValueError(f"{path}: declares too many pixels; it is not decoded ({e})") from e
    except (OSError, SyntaxError, ValueError) as e:
        raise ValueError(f"{path}: cannot be read as an image ({e})") from e


def _limit(n: int, max_frames: int | None) -> int:
    return n if max_frames is None else min(n, max_frames)


def _folder(path: Path, max_frames: int | None, max_pixels: int) -> FrameSource:
    files = sorted(p for p in path.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
    named: dict[str, Path] = {}
    for file in files:  # outputs are named by stem: two images of one stem would overwrite each other's
        if (other := named.setdefault(file.stem, file)) != file:
            raise InputError(file, f"has the name of {other.name}; both would be written as {file.stem}.png: rename or remove one")
    files = files[: _limit(len(files), max_frames)]
    if not files:
        raise ValueError(f"{path}: holds no images ({', '.join(IMAGE_SUFFIXES)})")
    for file in files:
        check_pixels(file, *image_size(file), max_pixels)

    def frames() -> Iterator[Frame]:
        for file in files:
            image = cv2.imread(str(file), cv2.IMREAD_COLOR)
            if image is None:
                raise ValueError(f"{file}: cannot be decoded as an image")
            yield Frame(file.stem, cv2.cvtColor(image, cv2.COLOR_BGR2RGB))

    return FrameSource("folder", path, len(files), None, frames())


def _sequence(path: Path, disparity_cfg, max_frames: int | None, max_pixels: int) -> FrameSource:
    seq = open_sequence(path)  # validates calibration, pairs, sizes
    check_pixels(seq.left[0], *seq.image_size, max_pixels)
    n = _limit(len(seq), max_frames)
    fps = None
    if seq.times is not None and len(seq.times) > 1 and np.median(np.diff(seq.times)) > 0:
        fps = float(1.0 / np.median(np.diff(seq.times)))
    matcher = sgbm(disparity_cfg) if disparity_cfg is not None and not seq.mono else None  # one camera: no depth mask

    def frames() -> Iterator[Frame]:
        for i in range(n):
            depth = None
            if matcher is not None:
                disparity = compute_disparity(matcher, seq.load_left(i, grey=True), seq.load_right(i, grey=True))
                depth = depth_from_disparity(disparity, seq.calibration.fx, seq.calibration.baseline_m)
            yield Frame(f"{i:06d}", seq.load_left(i), depth)

    return FrameSource("sequence", path, n, fps, frames())


def _bag(path: Path, ingest: DictConfig, disparity_cfg, max_frames: int | None) -> FrameSource:
    """The bag's stereo pairs, rectified at ingest.width x ingest.height; the pair's topics from
    ingest.topics, or found by themselves (Bag.stereo_pair)."""
    from offroad_path.recordings.bags import Bag
    from offroad_path.recordings.rectify import Rectifier
    from offroad_path.recordings.sources import BagSource

    topics = {"left": ingest.topics.left, "right": ingest.topics.right}
    if not (topics["left"] and topics["right"]) and not ingest.calibration:
        with Bag(path) as bag:
            topics["left"], topics["right"] = bag.stereo_pair()
    source = BagSource(OmegaConf.merge(ingest, {"bag": str(path), "topics": topics}))
    try:
        rectify = Rectifier(source.rig, source.input_size, (ingest.width, ingest.height), ingest.alpha)
    except BaseException:
        source.close()
        raise
    matcher, calibration = (sgbm(disparity_cfg) if disparity_cfg is not None else None), rectify.calibration

    def frames() -> Iterator[Frame]:
        try:
            for i, (_, header, raw_left, raw_right) in enumerate(source.headed_pairs(lambda t: True)):
                if max_frames is not None and i >= max_frames:
                    break
                left, right = rectify(raw_left, raw_right)
                grey = [image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY) for image in (left, right)]
                depth = None
                if matcher is not None:
                    depth = depth_from_disparity(compute_disparity(matcher, *grey), calibration.fx, calibration.baseline_m)
                rgb = cv2.cvtColor(left, cv2.COLOR_GRAY2RGB if left.ndim == 2 else cv2.COLOR_BGR2RGB)
                yield Frame(f"{i:06d}", rgb, depth, header)
        finally:
            source.close()

    return FrameSource("bag", path, None, None, frames(), calibration.K, rectify.pitch_change_deg)


def _video(path: Path, max_frames: int | None, max_pixels: int) -> FrameSource:
    capture = cv2.VideoCapture(str(path))
    if capture.isOpened():
        try:
            check_pixels(path, int(capture.get(cv2.CAP_PROP_FRAME_WIDTH)), int(capture.get(cv2.CAP_PROP_FRAME_HEIGHT)), max_pixels)
        except ValueError:
            capture.release()
            raise
    ok, first = capture.read() if capture.isOpened() else (False, None)
    if not ok:
        capture.release()
        raise ValueError(f"{path}: not a readable video (OpenCV could not decode a frame)")
    fps = capture.get(cv2.CAP_PROP_FPS) or None
    count = int(capture.get(cv2.CAP_PROP_FRAME_COUNT)) or 1  # a container's count; decoding may find fewer

    declared = int(capture.get(cv2.CAP_PROP_FRAME_COUNT))

    def frames() -> Iterator[Frame]:
        image, i = first, 0
        try:
            while image is not None and (max_frames is None or i < max_frames):
                yield Frame(f"{i:06d}", cv2.cvtColor(image, cv2.COLOR_BGR2RGB))
                ok, image = capture.read()
                image, i = (image if ok else None), i + 1
            if image is None:  # the video ended, not max_frames
                check_complete(path, i, declared)
        finally:
            capture.release()

    return FrameSource("video", path, _limit(count, max_frames), fps, frames())
