"""The planning table of the main test set: each primary's expected half-width and power by design
(main test worlds, training seeds), from variance components measured on development worlds, and
each design's cost on 2 cores.

    git show 985c4fc:metrics/evaluation.json > /tmp/retired.json   # the retired main test set's run
    git show 985c4fc:metrics/pipeline_time.json > /tmp/retired_time.json
    python benchmarks/test_set_design.py /tmp/retired.json /tmp/retired_time.json [--worlds 7 10 12 ...]

The components come from a run scored on worlds that now develop (the retired main test set, W0
worlds, S0 seeds): a paired difference's variance is sigma_w^2 / W + sigma_s^2 / S. sigma_s^2 per
seed: twice the pooled seed variance of the networks (two independently trained networks; a
network whose seeds differ by more than FLAG is left out of the pool, as a failed training), once
for a network against the prior, 0 for post-processing (the same network's maps; its whole spread
is counted as the worlds'). sigma_w^2: what the committed interval leaves, W0 (SE0^2 -
sigma_s^2 / S0), SE0 its half-width over z and the widening it was drawn with. The open loop's
seed component is not in the metrics: its whole spread is counted as the worlds'.

Power at Holm's strictest level alpha / m (m: the family), two-sided, with the interval's
small-sample widening at W worlds: Phi(effect / SE - z * widen(W)). Cost: the committed run's stage
times split into a part per main test world, per seed and the rest (COST_MODEL says which stages).
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

from scipy.stats import norm, t

from offroad_path.statistics.bootstrap import small_sample_factor

FLAG = 0.05  # a seed this far below its network's median is a failed training (offroad_path.statistics.seed_check)
LEVEL = 0.95
# (primary, comparison in the uncertainty section or steering_from_paths, seed variance: how many networks' worth)
PRIMARIES = [
    ("central_claim", "uncertainty/every_scratch_run_vs_mean_path_prior", 1),
    ("ranking", "uncertainty/fcn-none_vs_unet-none", 2),
    ("pretraining", "uncertainty/unet-segmentation_vs_unet-none", 2),
    ("postprocessing", "uncertainty/unet-none_postprocessed_vs_raw", 0),
    ("open_loop", "steering_from_paths/unet-none_vs_pilotnet", 0),
]
# Which stage times scale with what: a stage's time is split evenly over the worlds or seeds it covers.
PER_WORLD = ("drive",)  # every main test world, and nothing else
SHARED_BY_WORLDS = ("synthesize", "label", "evaluate")  # every rendered world: training drives, development, main, stress
PER_SEED = ("train_", "postprocess@", "train_steering@")


def seed_variance(uncertainty: dict) -> float:
    """Pooled per-seed IoU variance of the path networks (raw), leaving out a failed training."""
    sds = [v["seed_sd"] for k, v in uncertainty.items() if k.endswith(".raw") and "seed_sd" in v]
    kept = [sd for sd in sds if sd * math.sqrt(2) / 2 <= FLAG]  # two seeds: each is sd / sqrt(2) from the median
    return sum(sd**2 for sd in kept) / len(kept)


def components(evaluation: dict) -> dict[str, tuple[float, float, float]]:
    """primary -> (estimate, sigma_w^2, sigma_s^2) on the run's test set."""
    test = evaluation["uncertainty"]["test_set"]
    w0, s0 = test["worlds"], test["seeds"]
    var_net = seed_variance(evaluation["uncertainty"])
    widen0 = t.ppf(0.975, w0 - 1) / norm.ppf(0.975)  # the widening that run's intervals were drawn with
    out = {}
    for name, compare, networks in PRIMARIES:
        section, key = compare.split("/")
        row = evaluation[section][key]
        se0 = (row["high"] - row["low"]) / 2 / (norm.ppf(0.975) * widen0)
        seed = networks * var_net
        world = max(w0 * (se0**2 - seed / s0), 0.0)
        estimate = next(v for k, v in row.items() if k.endswith("difference"))
        out[name] = (estimate, world, seed)
    return out


def power(variance: tuple[float, float], worlds: int, seeds: int, effect: float, level: float) -> tuple[float, float]:
    """(the interval's expected half-width at `level`, the power for `effect`) at a design; variance: (sigma_w^2, sigma_s^2)."""
    se = math.sqrt(variance[0] / worlds + variance[1] / seeds)
    z = norm.ppf(1 - (1 - level) / 2) * small_sample_factor(worlds, level)
    return z * se, float(norm.cdf(effect / se - z))


def unit_costs(times: dict, worlds: dict[str, int], seeds: int) -> tuple[float, float, float]:
    """(seconds per main test world, per seed, the rest) from a run's stage times."""
    stages = times["stages"]
    rendered = sum(worlds.values())
    per_world = sum(v for k, v in stages.items() if k.startswith(PER_WORLD)) / worlds["main"]
    per_world += sum(v for k, v in stages.items() if k.startswith(SHARED_BY_WORLDS)) / rendered
    per_seed = sum(v for k, v in stages.items() if k.startswith(PER_SEED)) / seeds
    rest = times["total_s"] - per_world * worlds["main"] - per_seed * seeds
    return per_world, per_seed, rest


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("evaluation", type=Path, help="metrics/evaluation.json of a run on development worlds")
    parser.add_argument("pipeline_time", type=Path, help="that run's metrics/pipeline_time.json")
    parser.add_argument("--worlds", type=int, nargs="+", default=[7, 10, 12, 16, 21, 24])
    parser.add_argument("--seeds", type=int, nargs="+", default=[2, 5, 10])
    parser.add_argument("--family", type=int, default=2, help="Holm's family size: the strictest level is alpha / family")
    parser.add_argument("--alpha", type=float, default=0.05)
    parser.add_argument("--effect", type=float, default=0.02, help="the planning effect (IoU; normalised angle for the open loop)")
    parser.add_argument("--central-effect", type=float, default=0.10, help="the central claim's planning effect")
    parser.add_argument("--rendered", default="drives=16,development=7,main=7,stress=20", help="the run's worlds by kind")
    args = parser.parse_args()
    evaluation = json.loads(args.evaluation.read_text())
    found = components(evaluation)
    print("| primary | development estimate | world sd | seed sd (per seed) |")
    print("| --- | --- | --- | --- |")
    for name, (estimate, world, seed) in found.items():
        print(f"| {name} | {estimate:+.4f} | {math.sqrt(world):.4f} | {math.sqrt(seed):.4f} |")
    level = 1 - args.alpha / args.family
    effects = f"{args.effect}; central claim {args.central_effect}"
    print(f"\nHalf-width at the Holm level {level:.4f} and power for the planning effect ({effects}):\n")
    worlds = dict(item.split("=") for item in args.rendered.split(","))
    per_world, per_seed, rest = unit_costs(json.loads(args.pipeline_time.read_text()), {k: int(v) for k, v in worlds.items()},
                                           evaluation["uncertainty"]["test_set"]["seeds"])  # fmt: skip
    names = list(found)
    print("| worlds | seeds | " + " | ".join(names) + " | minutes on 2 cores |")
    print("| --- | --- | " + " | ".join("---" for _ in names) + " | --- |")
    for w in args.worlds:
        for s in args.seeds:
            cells = []
            for name in names:
                _, world, seed = found[name]
                effect = args.central_effect if name == "central_claim" else args.effect
                half, p = power((world, seed), w, s, effect, level)
                cells.append(f"±{half:.3f}, {100 * p:.0f} %")
            minutes = (rest + per_world * w + per_seed * s) / 60
            print(f"| {w} | {s} | " + " | ".join(cells) + f" | {minutes:.0f} |")
    print(f"\nunit costs: {per_world:.0f} s per main test world, {per_seed:.0f} s per seed, {rest:.0f} s the rest")


if __name__ == "__main__":
    main()
