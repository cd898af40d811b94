"""Which frames get a label (Holder & Breckon 2018, Sec. III-A).

A label at frame f0 is the footprint of the vehicle over frames f0+1..fn, where fn is the first
frame more than D metres (straight line) from f0. The paper restarts at the frame midway between
f0 and fn; a fixed stride along the driven path gives denser labels where footage is scarce.
"""

from __future__ import annotations

import numpy as np

from offroad_path.config.label_schema import FRAME_STRATEGIES
from offroad_path.geometry.path import distance_along, label_end

STRATEGIES = FRAME_STRATEGIES


def select_segments(
    positions: np.ndarray,
    distance_m: float,
    strategy: str,
    stride_m: float,
    min_motion_m: float,
) -> list[tuple[int, int]]:
    # No defaults: the values are conf/label's (distance_m, strategy, stride_m, min_motion_m).
    """(f0, fn) pairs for camera centres `positions` (N, 3); fn is the first frame beyond distance_m."""
    if strategy not in STRATEGIES:
        raise ValueError(f"unknown frame selection strategy {strategy!r}; valid: {', '.join(STRATEGIES)}")
    positions = np.asarray(positions, float)
    steps = np.linalg.norm(np.diff(positions, axis=0), axis=1)
    moving = np.flatnonzero(steps > min_motion_m)
    if len(moving) == 0:
        return []
    travelled = distance_along(positions)
    segments = []
    f0 = start = int(moving[0])
    while f0 < len(positions) - 1:
        fn = label_end(positions, f0, distance_m)
        if fn is None:
            break
        segments.append((f0, fn))
        if strategy == "midway":
            f0 = max((f0 + fn) // 2, f0 + 1)
        else:
            # The k-th label starts k strides along the path from the first: no rounding drift. A
            # stride shorter than the frames' spacing skips the marks that would pick f0 again.
            mark = max(len(segments), int((travelled[f0] - travelled[start]) // stride_m) + 1)
            ahead = np.flatnonzero(travelled[f0 + 1 :] >= travelled[start] + mark * stride_m - 1e-9)
            if len(ahead) == 0:
                break
            f0 = f0 + 1 + int(ahead[0])
    return segments
