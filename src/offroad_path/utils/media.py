"""Images and videos written with OpenCV, checked. `cv2.imwrite` returns False and
`VideoWriter.write` returns nothing when the disk is full: unchecked, a run reports success over
missing frames and a truncated video. Here either failure is an OSError naming the file, which the
stage runner turns into one line and exit 2 (the stage's temporary folder is then removed)."""

from __future__ import annotations

import errno
from collections.abc import Sequence
from pathlib import Path

import cv2
import numpy as np


def _not_written(path: str | Path, what: str) -> OSError:
    return OSError(errno.EIO, f"{what} could not be written (a full disk or a folder that may not be written)", str(path))


def write_image(path: str | Path, image: np.ndarray, params: Sequence[int] = ()) -> None:
    """cv2.imwrite, OSError naming the file when nothing or not all of it was written."""
    if not cv2.imwrite(str(path), image, list(params)):
        raise _not_written(path, "the image")


class VideoFile:
    """cv2.VideoWriter as a context: frames in BGR; on a clean exit the file is read back and must
    hold every frame written, else OSError naming it (a full disk leaves a few KB of header)."""

    def __init__(self, path: str | Path, fps: float, size: tuple[int, int], fourcc: str = "mp4v"):
        self.path, self.frames = Path(path), 0
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._writer = cv2.VideoWriter(str(self.path), cv2.VideoWriter_fourcc(*fourcc), fps, size)
        if not self._writer.isOpened():
            raise _not_written(self.path, f"the video (OpenCV cannot open a {fourcc} writer here)")

    def write(self, bgr: np.ndarray) -> None:
        self._writer.write(bgr)
        self.frames += 1

    def close(self) -> None:
        self._writer.release()
        stored = cv2.VideoCapture(str(self.path))
        try:
            readable = int(stored.get(cv2.CAP_PROP_FRAME_COUNT)) if stored.isOpened() else 0
        finally:
            stored.release()
        if readable < self.frames:
            raise _not_written(self.path, f"the video ({readable} of {self.frames} frames readable)")

    def __enter__(self) -> VideoFile:
        return self

    def __exit__(self, kind, value, traceback) -> None:
        if kind is None:
            self.close()
        else:
            self._writer.release()
