"""Left/right pairing by timestamp, subsampling to a frame rate, and poses at frame times."""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from offroad_path.errors import InputError

SIDES = ("left", "right")


@dataclass
class SyncStats:
    left: int = 0  # messages seen
    right: int = 0
    pairs: int = 0
    worst_gap_s: float = 0.0  # the largest |t_left - t_right| of a pair
    nearest_miss_s: float = math.inf  # the smallest gap of a message left unpaired

    @property
    def unpaired(self) -> int:
        return self.left + self.right - 2 * self.pairs


def pair_by_stamp(
    messages: Iterable[tuple[str, float, Any]], tolerance_s: float, stats: SyncStats, names: dict[str, str], source: Path
) -> Iterator[tuple[float, Any, Any]]:
    """(left stamp, left payload, right payload) for every left and right message whose stamps are
    within tolerance_s, from ("left" | "right", stamp, payload) in recording order.

    Each side's stamps must rise. The earliest waiting left and right are paired or the earlier one
    is dropped: no later message of the other side can be nearer to it. With tolerance_s under half
    a frame period no message can pair with two others."""
    waiting: dict[str, deque] = {side: deque() for side in SIDES}
    last = dict.fromkeys(SIDES, -math.inf)
    for side, stamp, payload in messages:
        if stamp <= last[side]:
            raise InputError(source, f"{names[side]}: stamps do not rise ({stamp:.6f} s after {last[side]:.6f} s)")
        last[side] = stamp
        setattr(stats, side, getattr(stats, side) + 1)
        waiting[side].append((stamp, payload))
        while waiting["left"] and waiting["right"]:
            (tl, left), (tr, right) = waiting["left"][0], waiting["right"][0]
            if abs(tl - tr) <= tolerance_s:
                waiting["left"].popleft(), waiting["right"].popleft()
                stats.pairs += 1
                stats.worst_gap_s = max(stats.worst_gap_s, abs(tl - tr))
                yield tl, left, right
            else:
                stats.nearest_miss_s = min(stats.nearest_miss_s, abs(tl - tr))
                waiting["left" if tl < tr else "right"].popleft()


def check_pairing(stats: SyncStats, max_unpaired_fraction: float, tolerance_s: float, names: dict[str, str], source: Path) -> None:
    """Refuse a recording whose left and right streams do not match up."""
    counts = f"{stats.left} messages on {names['left']}, {stats.right} on {names['right']}"
    if stats.pairs == 0:
        nearest = (
            f"; the nearest left and right are {stats.nearest_miss_s * 1000:.1f} ms apart" if math.isfinite(stats.nearest_miss_s) else ""
        )
        raise InputError(source, f"no left/right pair within ingest.sync_tolerance_s = {tolerance_s:g} s ({counts}{nearest})")
    fraction = stats.unpaired / (stats.left + stats.right)
    if fraction > max_unpaired_fraction:
        raise InputError(
            source,
            f"{stats.unpaired} of {stats.left + stats.right} images have no partner within {tolerance_s:g} s ({counts}): "
            f"more than ingest.max_unpaired_fraction = {max_unpaired_fraction:g}; "
            "the streams are not synchronised or a camera dropped frames",
        )


class Subsampler:
    """Keeps a frame when at least 0.9 / fps has passed since the last kept one: at most `fps`
    frames per second (every third of a 30 fps stream for fps=10); fps None keeps every frame."""

    def __init__(self, fps: float | None):
        self.min_gap_s = 0.9 / fps if fps else 0.0
        self.last = -math.inf

    def keep(self, t: float) -> bool:
        if t - self.last < self.min_gap_s:
            return False
        self.last = t
        return True


def poses_at(times: np.ndarray, poses: np.ndarray, at: np.ndarray, source: Path, topic: str) -> np.ndarray:
    """(M, 4, 4) poses interpolated at `at` (linear position, spherical rotation) from (N, 4, 4)."""
    if len(times) < 2:
        raise InputError(source, f"{topic}: {len(times)} pose message(s); interpolation needs at least 2")
    order = np.argsort(times, kind="stable")
    times, poses = times[order], poses[order]
    keep = np.concatenate([[True], np.diff(times) > 0])
    times, poses = times[keep], poses[keep]
    if at[0] < times[0] or at[-1] > times[-1]:
        raise InputError(
            source,
            f"{topic}: the poses cover {times[0]:.3f} to {times[-1]:.3f} s, the frames {at[0]:.3f} to {at[-1]:.3f} s; "
            "record the odometry for the whole drive",
        )
    out = np.tile(np.eye(4), (len(at), 1, 1))
    out[:, :3, :3] = Slerp(times, Rotation.from_matrix(poses[:, :3, :3]))(at).as_matrix()
    out[:, :3, 3] = np.stack([np.interp(at, times, poses[:, i, 3]) for i in range(3)], axis=1)
    return out
