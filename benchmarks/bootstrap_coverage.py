"""Coverage of the evaluate stage's intervals when worlds, blocks and training seeds each shift a
score: the hierarchical bootstrap (test worlds, then their blocks, then seeds) against resampling
blocks alone, on simulated test sets whose truth is known.

    python benchmarks/bootstrap_coverage.py [--trials 200]

Each trial: 8 test worlds of 3 to 7 blocks, 3 training seeds; a block's path rate is 0.6 plus its
world's effect, its own and the seed's (normal, the standard deviations of each row); false
positives and negatives 0.1-0.2 each. The truth: the population's pooled IoU, 0.6 / 0.9. Prints the
share of 95 % intervals that hold it (the same construction as tests/test_bootstrap.py's).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from offroad_path.statistics.bootstrap import Resampling, interval, score_draws
from offroad_path.statistics.scores import iou

SETTINGS = [(0.06, 0.05, 0.02), (0.04, 0.05, 0.01), (0.08, 0.03, 0.03), (0.0, 0.08, 0.0)]  # world, block, seed sd


def test_set(rng: np.random.Generator, world_sd: float, block_sd: float, seed_sd: float) -> tuple[np.ndarray, list[int]]:
    n_blocks = rng.integers(3, 8, 8)
    world_of = np.repeat(np.arange(8), n_blocks)
    size = rng.uniform(500, 1500, len(world_of))
    effect = rng.normal(0, world_sd, 8)[world_of] + rng.normal(0, block_sd, len(world_of))
    tp = size * np.clip(0.6 + effect[None, :] + rng.normal(0, seed_sd, 3)[:, None], 0.05, 0.95)
    fp, fn = (np.broadcast_to(size * rng.uniform(0.1, 0.2, len(world_of)), tp.shape) for _ in range(2))
    return np.stack([tp, fp, np.zeros_like(tp), fn], axis=-1), list(world_of)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=200)
    args = parser.parse_args()
    truth = 0.6 / 0.9
    print("| world sd | block sd | seed sd | hierarchical coverage | blocks only | seconds |\n| --- | --- | --- | --- | --- | --- |")
    for world_sd, block_sd, seed_sd in SETTINGS:
        start, hierarchical, flat = time.perf_counter(), 0, 0
        for trial in range(args.trials):
            sums, worlds = test_set(np.random.default_rng(2000 + trial), world_sd, block_sd, seed_sd)
            found = score_draws(sums, iou, Resampling(1000, seed=trial), worlds).interval()
            hierarchical += found.low <= truth <= found.high
            blocks_only = interval(sums.sum(axis=0), iou, Resampling(1000, seed=trial))
            flat += blocks_only.low <= truth <= blocks_only.high
        print(f"| {world_sd:g} | {block_sd:g} | {seed_sd:g} | {hierarchical / args.trials:.1%} | {flat / args.trials:.1%} | "
              f"{time.perf_counter() - start:.1f} |")  # fmt: skip


if __name__ == "__main__":
    main()
