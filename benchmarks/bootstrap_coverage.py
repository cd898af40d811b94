"""Coverage of the evaluate stage's intervals when worlds, blocks and training seeds each shift a
score: the hierarchical bootstrap (test worlds, then their blocks, then seeds) with and without its
small-sample widening (statistics.bootstrap.small_sample_factor), against resampling blocks alone,
on simulated test sets whose truth is known.

    python benchmarks/bootstrap_coverage.py [--trials 200] [--worlds 7] [--seeds 2] [--level 0.95] [--paired]

Each trial: `--worlds` test worlds of 3 to 7 blocks, `--seeds` training seeds; a block's path rate
is 0.6 plus its world's effect, its own and the seed's (normal, the standard deviations of each
row); false positives and negatives 0.1-0.2 each. The truth: the population's pooled IoU, 0.6 / 0.9.
A seed's effect is a draw of the training's randomness, so the truth averages over it too. Prints
the share of intervals at `--level` that hold the truth. `--paired`: the intervals of a paired
difference, what the primaries are: a second method on the same blocks whose path rate is the
first's plus 0.02 and its own world, block and seed effects (half the first's sds, independent),
scored on the same draws; the truth, the two populations' pooled IoU difference (0.62 / 0.92 -
0.6 / 0.9, the effects having mean 0 and the rates staying inside the clip).
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from common import positive_int

from offroad_path.report.tables import grid_head, grid_row
from offroad_path.statistics.bootstrap import Draws, Resampling, paired_draws, score_draws
from offroad_path.statistics.scores import iou

SETTINGS = [(0.06, 0.05, 0.02), (0.04, 0.05, 0.01), (0.08, 0.03, 0.03), (0.0, 0.08, 0.0)]  # world, block, seed sd


def test_set(
    rng: np.random.Generator, sds: tuple[float, float, float], worlds: int, seeds: int, paired: bool = False
) -> tuple[np.ndarray, list[int]]:
    """(seeds, blocks, 4) counts and each block's world; paired: (2, seeds, blocks, 4), the second method's too."""
    world_sd, block_sd, seed_sd = sds
    n_blocks = rng.integers(3, 8, worlds)
    world_of = np.repeat(np.arange(worlds), n_blocks)
    size = rng.uniform(500, 1500, len(world_of))

    def rate(scale: float) -> np.ndarray:  # (seeds, blocks): a method's world, block and seed effects
        effect = rng.normal(0, scale * world_sd, worlds)[world_of] + rng.normal(0, scale * block_sd, len(world_of))
        return effect[None, :] + rng.normal(0, scale * seed_sd, seeds)[:, None]

    first = 0.6 + rate(1.0)
    rates = [first, first + 0.02 + rate(0.5)] if paired else [first]
    fp, fn = (size * rng.uniform(0.1, 0.2, len(world_of)) for _ in range(2))
    counts = [np.stack(np.broadcast_arrays(size * np.clip(r, 0.05, 0.95), fp, np.zeros_like(r), fn), axis=-1) for r in rates]
    return (np.stack(counts) if paired else counts[0]), list(world_of)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=positive_int, default=200)
    parser.add_argument("--worlds", type=positive_int, default=7, help="test worlds per simulated test set (at least 2)")
    parser.add_argument("--seeds", type=positive_int, default=2, help="training seeds")
    parser.add_argument("--level", type=float, default=0.95)
    parser.add_argument("--paired", action="store_true", help="the intervals of a paired difference of two methods")
    args = parser.parse_args()
    if args.worlds < 2:
        parser.error("--worlds: at least 2 (a bootstrap of one world has nothing to draw)")
    if not 0 < args.level < 1:
        parser.error("--level: between 0 and 1")
    truth = 0.62 / 0.92 - 0.6 / 0.9 if args.paired else 0.6 / 0.9
    kind = "paired differences" if args.paired else "scores"
    print(f"{kind}: {args.worlds} worlds x {args.seeds} seeds, {args.trials} trials, nominal {args.level:.0%}\n")
    print(grid_head(["world sd", "block sd", "seed sd", "hierarchical, widened", "hierarchical, percentile", "blocks only", "seconds"]))
    for world_sd, block_sd, seed_sd in SETTINGS:
        start, widened, plain, flat = time.perf_counter(), 0, 0, 0
        for trial in range(args.trials):
            sds = (world_sd, block_sd, seed_sd)
            sums, worlds = test_set(np.random.default_rng(2000 + trial), sds, args.worlds, args.seeds, args.paired)
            resampling = Resampling(1000, seed=trial, level=args.level)
            if args.paired:
                draws = paired_draws(sums[1], sums[0], iou, resampling, worlds)  # the second minus the first
                blocks_only = paired_draws(sums[1].sum(axis=0), sums[0].sum(axis=0), iou, resampling)
            else:
                draws, blocks_only = score_draws(sums, iou, resampling, worlds), score_draws(sums.sum(axis=0), iou, resampling)
            found = draws.interval()
            widened += found.low <= truth <= found.high
            percentile = Draws(draws.estimate, draws.values, draws.resampling).interval()  # worlds=0: no widening
            plain += percentile.low <= truth <= percentile.high
            flat_interval = blocks_only.interval()  # every block its own world
            flat += flat_interval.low <= truth <= flat_interval.high
        n = args.trials
        rates = [f"{widened / n:.1%}", f"{plain / n:.1%}", f"{flat / n:.1%}"]
        print(grid_row([f"{world_sd:g}", f"{block_sd:g}", f"{seed_sd:g}", *rates, f"{time.perf_counter() - start:.1f}"]))


if __name__ == "__main__":
    main()
