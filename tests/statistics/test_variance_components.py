"""The planning table's variance components (benchmarks/test_set_design.py) recover the components a
simulated test set was drawn with, and the planned power is what simulated test sets reject."""

from __future__ import annotations

import numpy as np
import pytest
from test_set_design import components, power


def simulated(rng: np.random.Generator, worlds: int, blocks: int, seeds: int, sds: dict[str, float]) -> tuple[dict, dict]:
    """Two methods' per-world and per-block IoU per seed whose difference has the given components."""
    world = rng.normal(0.0, sds["world"], worlds)
    seed = rng.normal(0.0, sds["seed"], seeds)
    interaction = rng.normal(0.0, sds["world_x_seed"], (worlds, seeds))
    block = rng.normal(0.0, sds["block"], (worlds, blocks))
    a = {"block": {}, "world": {}}
    for w in range(worlds):
        for b in range(blocks):
            a["block"][f"w{w}", b] = 0.8 + 0.02 + world[w] + block[w, b] + seed + interaction[w]
        a["world"][f"w{w}"] = 0.8 + 0.02 + world[w] + block[w].mean() + seed + interaction[w]
    prior = {"block": {k: np.full(1, 0.8) for k in a["block"]}, "world": {k: np.full(1, 0.8) for k in a["world"]}}
    return a, prior


def test_the_components_are_those_the_differences_were_drawn_with():
    rng = np.random.default_rng(0)
    truth = {"world": 0.03, "block": 0.05, "seed": 0.01, "world_x_seed": 0.008}
    found = [components(*simulated(rng, 40, 5, 8, truth)) for _ in range(60)]
    for name, sd in truth.items():
        assert np.mean([f[name] for f in found]) == pytest.approx(sd**2, rel=0.25), name
    assert np.mean([f["estimate"] for f in found]) == pytest.approx(0.02, abs=0.005)
    # with the seed variance left out, the seeds' component reads 0, not the others' noise
    quiet = [components(*simulated(rng, 40, 5, 8, truth | {"seed": 0.0})) for _ in range(60)]
    assert np.mean([f["seed"] for f in quiet]) < 0.2 * truth["seed"] ** 2


def test_the_planned_power_is_what_simulated_designs_reject():
    rng = np.random.default_rng(1)
    c = {"world": 0.012**2, "block": 0.0, "seed": 0.01**2, "world_x_seed": 0.0}
    half, planned = power(c, 12, 5, effect=0.02, level=0.975)
    se = np.sqrt(c["world"] / 12 + c["seed"] / 5)
    estimates = 0.02 + rng.normal(0.0, se, 20000)
    assert np.mean(np.abs(estimates) > half) == pytest.approx(planned, abs=0.02)
    assert 0.3 < planned < 0.99  # a design between the extremes, so the check above can fail
