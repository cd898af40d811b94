"""Two video files of a stereo pair of free-running cameras (the paper's GoPro rig): their time
offset, from the frame-difference signals of both, and the frame pairs it implies."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from offroad_path.errors import InputError

SIGNAL_SIZE = (64, 36)  # frames are compared at this size: motion, not detail, aligns the videos


@dataclass
class VideoInfo:
    path: Path
    fps: float
    frames: int
    size: tuple[int, int]  # (width, height)


def probe(path: Path) -> VideoInfo:
    if not path.is_file():
        raise InputError(path, "is missing (ingest.videos)")
    capture = cv2.VideoCapture(str(path))
    try:
        ok, frame = capture.read()
        if not capture.isOpened() or not ok:
            raise InputError(path, "cannot be opened as a video by OpenCV (FFmpeg)")
        fps = capture.get(cv2.CAP_PROP_FPS)
        if not fps > 0:
            raise InputError(path, "gives no frame rate")
        return VideoInfo(path, fps, int(capture.get(cv2.CAP_PROP_FRAME_COUNT)), (frame.shape[1], frame.shape[0]))
    finally:
        capture.release()


def check_complete(path: Path, decoded: int, declared: int) -> None:
    """A video that decodes to fewer frames than its container declares (1 % and a frame of slack
    for containers that estimate the count) is truncated or damaged: InputError."""
    if declared > 0 and decoded < 0.99 * declared - 1:
        raise InputError(path, f"its container declares {declared} frames but only {decoded} decode: truncated or damaged")


def frames(path: Path, start: int = 0) -> Iterator[np.ndarray]:
    """Every decoded frame (BGR) from index `start` on; InputError at the end when the video
    decodes to fewer frames than it declares."""
    capture = cv2.VideoCapture(str(path))
    declared, decoded = int(capture.get(cv2.CAP_PROP_FRAME_COUNT)), 0
    try:
        for _ in range(start):
            if not capture.grab():
                check_complete(path, decoded, declared)
                return
            decoded += 1
        while True:
            ok, frame = capture.read()
            if not ok:
                check_complete(path, decoded, declared)
                return
            decoded += 1
            yield frame
    finally:
        capture.release()


def motion_signal(path: Path, max_frames: int) -> np.ndarray:
    """Mean absolute difference of consecutive frames (small and grey), per frame."""
    previous, signal = None, []
    for k, frame in enumerate(frames(path)):
        if k >= max_frames:
            break
        small = cv2.resize(cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY), SIGNAL_SIZE, interpolation=cv2.INTER_AREA).astype(np.float32)
        signal.append(0.0 if previous is None else float(np.abs(small - previous).mean()))
        previous = small
    return np.asarray(signal[1:])


@dataclass
class Offset:
    frames: int  # the right video's frame index minus the left's for one instant
    correlation: float  # normalised correlation of the two motion signals at that offset
    runner_up: float  # the best correlation at any other offset more than one frame away


def estimate_offset(left: np.ndarray, right: np.ndarray, max_offset: int, min_overlap: int = 20) -> Offset | None:
    """The shift of `right` against `left` that best correlates the two motion signals; None when
    no shift leaves min_overlap frames in common."""
    scores = {}
    for shift in range(-max_offset, max_offset + 1):
        a = left[max(0, -shift) :]
        b = right[max(0, shift) :]
        n = min(len(a), len(b))
        if n < min_overlap:
            continue
        a, b = a[:n] - a[:n].mean(), b[:n] - b[:n].mean()
        scale = np.sqrt((a * a).sum() * (b * b).sum())
        scores[shift] = float((a * b).sum() / scale) if scale > 0 else 0.0
    if not scores:
        return None
    best = max(scores, key=scores.get)
    others = [v for k, v in scores.items() if abs(k - best) > 1]
    return Offset(best, scores[best], max(others, default=0.0))
