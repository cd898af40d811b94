"""A training that failed on one seed: a seed whose test IoU lies far below its siblings'.

A network trained once may land far from where its other seeds land (a collapsed or stalled run);
pooled with the others it drags the network's figure down and widens every interval it is in, and a
user who trains once would get that network. So the evaluate stage lists, per network, every seed more than
FAILED_BELOW_MEDIAN IoU below the median of its network's seeds (the results page names them; the
metrics keep them under uncertainty.failed_seeds)."""

from __future__ import annotations

import statistics

FAILED_BELOW_MEDIAN = 0.05  # IoU: several times the spread of a healthy network's seeds (docs/conclusions.md)


def failed_seeds(ious: dict[int, float], margin: float = FAILED_BELOW_MEDIAN) -> list[int]:
    """The seeds (keys of `ious`: seed -> its test IoU) more than `margin` below the seeds' median."""
    if len(ious) < 2:
        return []
    median = statistics.median(ious.values())
    return [seed for seed, value in ious.items() if value < median - margin]
