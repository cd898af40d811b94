"""The planning table of the main test set: variance components of each primary's paired difference
measured on development worlds, and from them each design's expected half-width, power at Holm's
strictest level and cost on 2 cores.

    python benchmarks/seed_spread.py --seeds 0 1 2 3 4 --models segnet fcn unet --json /tmp/none.json
    python benchmarks/seed_spread.py --seeds 0 1 2 3 4 --models unet --pretraining segmentation --json /tmp/seg.json
    git show REV:metrics/evaluation.json > /tmp/retired.json      # the last run scored on the retired main
    git show REV:metrics/pipeline_time.json > /tmp/retired_time.json   # test set (REV: CHANGELOG.md names it)
    python benchmarks/test_set_design.py /tmp/none.json /tmp/seg.json --retired /tmp/retired.json \
        --times /tmp/retired_time.json [--family 3] [--worlds 7 12 20] [--seeds 2 5 10]

Components (method of moments, Searle et al. 1992, ch. 4), from seed_spread's per-image counts on
the development worlds (--seeds runs of each network, trained as the pipeline trains them): each
world's pooled IoU difference per seed, d[w, s] (a network against the mean-path prior: the prior
has no seeds). sigma_ws^2: the world x seed interaction (the two-way residual); sigma_s^2: the
spread of the seeds' means over worlds less sigma_ws^2 / W; sigma_b^2: blocks within a world (the
split's block_m, seeds averaged); sigma_w^2: the spread of the worlds' means less sigma_b^2 / B and
sigma_ws^2 / S. Then an estimate over W worlds of B blocks and S seeds has the variance
sigma_w^2 / W + sigma_b^2 / (W B) + sigma_s^2 / S + sigma_ws^2 / (W S). Post-processing and the
open loop are not in those runs: their spread is the retired run's interval (--retired), counted
wholly as the worlds'.

Power at Holm's strictest level alpha / family, two-sided, with the intervals' small-sample widening
at W worlds and S seeds as the reports draw it: Phi(effect / SE - z * widen). Cost: the retired run's stage times (--times) split
into seconds per main test world, per seed and the rest.
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
from pathlib import Path

import numpy as np
from scipy.stats import norm, t

from offroad_path.config import load_config
from offroad_path.data.labels import read_label_run
from offroad_path.report.tables import grid_head, grid_row
from offroad_path.statistics.bootstrap import two_level_factor
from offroad_path.statistics.scores import Scores

BLOCKS_PER_WORLD = 4.5  # the main test set's mean (stream 5's first 20 worlds: 91 blocks)
# primary -> (a, b) of the seed runs (b "prior": the mean-path prior); the central claim: its weakest member
FROM_SEEDS = {
    "central_claim": [("segnet-none", "prior"), ("fcn-none", "prior"), ("unet-none", "prior")],
    "ranking": [("fcn-none", "unet-none")],
    "pretraining": [("unet-segmentation", "unet-none")],
}
FROM_RETIRED = {"postprocessing": "uncertainty/unet-none_postprocessed_vs_raw", "open_loop": "steering_from_paths/unet-none_vs_pilotnet"}
PLANNING_EFFECT = {"central_claim": 0.10}  # the others: --effect
PER_WORLD = ("drive",)  # stage times spent per main test world
SHARED_BY_WORLDS = ("synthesize", "label", "evaluate")  # spent per rendered world
PER_SEED = ("train_", "postprocess@", "train_steering@")


def world_seed_ious(counts: list[dict[str, list[int]]], blocks: dict[str, tuple[str, int]]) -> dict:
    """{(world, block): (S,) IoU} and {world: (S,) IoU} of per-seed per-image counts (frame key -> tp, fp, tn, fn)."""
    by_block: dict[tuple[str, int], np.ndarray] = {}
    by_world: dict[str, np.ndarray] = {}
    for frame, where in blocks.items():
        per_seed = np.array([c[frame] for c in counts], np.float64)
        by_block[where] = by_block.get(where, 0) + per_seed
        by_world[where[0]] = by_world.get(where[0], 0) + per_seed
    return {"block": {k: np.array([Scores.of(c).iou for c in v]) for k, v in by_block.items()},
            "world": {k: np.array([Scores.of(c).iou for c in v]) for k, v in by_world.items()}}  # fmt: skip


def components(a: dict, b: dict) -> dict[str, float]:
    """Variance components of the difference a - b (world_seed_ious of each; a side of one seed is broadcast)."""
    worlds = sorted(a["world"])
    d = np.stack([a["world"][w] - b["world"][w] for w in worlds])  # (W, S)
    n_worlds, n_seeds = d.shape
    residual = d - d.mean(1, keepdims=True) - d.mean(0, keepdims=True) + d.mean()
    ws = float((residual**2).sum() / ((n_worlds - 1) * (n_seeds - 1)))
    seed = max(float(d.mean(0).var(ddof=1)) - ws / n_worlds, 0.0)
    per_block = {k: float(np.mean(a["block"][k] - b["block"][k])) for k in a["block"]}
    within, sizes = [], []
    for w in worlds:
        values = [v for (world, _), v in per_block.items() if world == w]
        if len(values) > 1:
            within.append(statistics.variance(values))
            sizes.append(len(values))
    block = float(np.mean(within)) if within else 0.0
    world = max(float(d.mean(1).var(ddof=1)) - block / float(np.mean(sizes)) - ws / n_seeds, 0.0)
    return {
        "estimate": float(d.mean()),
        "world": world,
        "block": block,
        "seed": seed,
        "world_x_seed": ws,
        "worlds": n_worlds,
        "seeds": n_seeds,
    }


def from_seed_runs(files: list[Path], block_m: float, labels_dir: Path) -> dict[str, dict[str, float]]:
    if not files:
        return {}
    runs, prior = {}, None
    for path in files:
        found = json.loads(path.read_text())
        if found.get("test_set") != "development":
            raise SystemExit(f"{path}: not scored on the development set (seed_spread.py --test-set development)")
        prior = found["prior"]
        for model, row in found["models"].items():
            runs[f"{model}-{found.get('pretraining', 'none')}"] = row["counts"]
    distance = {run.name: run.distance() for run in read_label_run(labels_dir)}
    blocks = {}
    for frame in prior:
        sequence, f0, _ = frame.split("/")
        blocks[frame] = (sequence, int(distance[sequence][int(f0)] // block_m))
    ious = {name: world_seed_ious(counts, blocks) for name, counts in runs.items()}
    ious["prior"] = world_seed_ious([prior], blocks)
    out = {}
    for primary, pairs in FROM_SEEDS.items():
        if all(a in ious for a, _ in pairs) and all(b in ious for _, b in pairs):
            found = [components(ious[a], ious[b]) for a, b in pairs]
            out[primary] = min(found, key=lambda c: c["estimate"])  # the intersection-union test's weakest member
    return out


def from_retired(evaluation: dict, seed_sds: dict[str, float]) -> dict[str, dict[str, float]]:
    """A comparison's whole spread in the retired run's interval (drawn with t(n - 1) / z), as the
    worlds', but for an assumed per-seed sd (seed_sds: primary -> sd), whose share it then leaves."""
    worlds = evaluation["uncertainty"]["test_set"]["worlds"]
    widen = t.ppf(0.975, worlds - 1) / norm.ppf(0.975)
    out = {}
    for primary, compare in FROM_RETIRED.items():
        section, key = compare.split("/")
        row = evaluation[section][key]
        se = (row["high"] - row["low"]) / 2 / (norm.ppf(0.975) * widen)
        estimate = next(v for k, v in row.items() if k.endswith("difference"))
        seed = seed_sds.get(primary, 0.0) ** 2
        out[primary] = {
            "estimate": estimate,
            "world": max(worlds * (se**2 - seed / evaluation["uncertainty"]["test_set"]["seeds"]), 0.0),
            "block": 0.0,
            "seed": seed,
            "world_x_seed": 0.0,
            "worlds": worlds,
            "seeds": 0,
        }
    return out


def power(c: dict[str, float], worlds: int, seeds: int, effect: float, level: float) -> tuple[float, float]:
    """(the interval's expected half-width at `level`, the power for `effect`) at a design: the
    estimate's spread from the components, the interval's widening as the reports draw it
    (two_level_factor, from the bootstrap's expected variance at each level, (n - 1) / n of the true)."""
    world = c["world"] / worlds + c["block"] / (worlds * BLOCKS_PER_WORLD) + c["world_x_seed"] / (worlds * seeds)
    seed = c["seed"] / seeds
    se = math.sqrt(world + seed)
    widen = two_level_factor(world * (worlds - 1) / worlds, seed * (seeds - 1) / seeds, worlds, seeds, level)
    z = norm.ppf(1 - (1 - level) / 2) * widen * math.sqrt((world * (worlds - 1) / worlds + seed * (seeds - 1) / seeds) / (world + seed))
    return z * se, float(norm.cdf(effect / se - z))


def unit_costs(times: dict, worlds: dict[str, int], seeds: int) -> tuple[float, float, float]:
    """(seconds per main test world, per seed, the rest) from a run's stage times."""
    stages = times["stages"]
    per_world = sum(v for k, v in stages.items() if k.startswith(PER_WORLD)) / worlds["main"]
    per_world += sum(v for k, v in stages.items() if k.startswith(SHARED_BY_WORLDS)) / sum(worlds.values())
    per_seed = sum(v for k, v in stages.items() if k.startswith(PER_SEED)) / seeds
    return per_world, per_seed, times["total_s"] - per_world * worlds["main"] - per_seed * seeds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("spread", type=Path, nargs="*", help="seed_spread.py --json files scored on the development set")
    parser.add_argument("--retired", type=Path, required=True, help="the retired main test set's metrics/evaluation.json")
    parser.add_argument("--times", type=Path, required=True, help="that run's metrics/pipeline_time.json")
    parser.add_argument("--rendered", default="drives=16,development=7,main=7,stress=20", help="that run's worlds by kind")
    parser.add_argument("--worlds", type=int, nargs="+", default=[7, 10, 12, 16, 20, 24])
    parser.add_argument("--seeds", type=int, nargs="+", default=[2, 5, 10])
    parser.add_argument("--family", type=int, default=3, help="Holm's family: the strictest level is alpha / family")
    parser.add_argument("--alpha", type=float, default=0.05)
    parser.add_argument("--effect", type=float, default=0.02, help="the planning effect (IoU; normalised angle for the open loop)")
    parser.add_argument("--assume-seed-sd", nargs="*", default=[], metavar="PRIMARY=SD",
                        help="an assumed per-seed sd of a primary the seed runs do not measure (the open loop)")  # fmt: skip
    args = parser.parse_args()
    cfg = load_config()
    retired = json.loads(args.retired.read_text())
    assumed = {name: float(sd) for name, sd in (item.split("=") for item in args.assume_seed_sd)}
    found = from_retired(retired, assumed) | from_seed_runs(args.spread, cfg.split.block_m, Path(cfg.split.labels_dir))
    print(grid_head(["primary", "estimate", "world sd", "block sd", "seed sd", "world x seed sd", "measured on"]))
    for name, c in found.items():
        where = (
            f"{c['worlds']} development worlds, {c['seeds']} seeds" if c["seeds"] else f"the retired run's interval ({c['worlds']} worlds)"
        )
        where += f"; seed sd assumed {assumed[name]:g}" if name in assumed else ""
        sds = [f"{math.sqrt(c[k]):.4f}" for k in ("world", "block", "seed", "world_x_seed")]
        print(grid_row([name, f"{c['estimate']:+.4f}", *sds, where]))
    level = 1 - args.alpha / args.family
    rendered = {k: int(v) for k, v in (item.split("=") for item in args.rendered.split(","))}
    per_world, per_seed, rest = unit_costs(json.loads(args.times.read_text()), rendered, retired["uncertainty"]["test_set"]["seeds"])
    names = list(found)
    effects = ", ".join(f"{n} {PLANNING_EFFECT.get(n, args.effect):g}" for n in names)
    print(f"\nHalf-width at Holm's strictest level ({level:.4f}, family {args.family}) and power for the planning effect ({effects}):\n")
    print(grid_head(["worlds", "seeds", *names, "minutes on 2 cores"]))
    for w in args.worlds:
        for s in args.seeds:
            cells = []
            for name in names:
                half, p = power(found[name], w, s, PLANNING_EFFECT.get(name, args.effect), level)
                cells.append(f"±{half:.3f}, {100 * p:.0f} %")
            print(grid_row([w, s, *cells, f"{(rest + per_world * w + per_seed * s) / 60:.0f}"]))
    print(f"\nunit costs: {per_world:.0f} s per main test world, {per_seed:.0f} s per seed, {rest:.0f} s the rest (the retired run)")


if __name__ == "__main__":
    main()
