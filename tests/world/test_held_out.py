"""Held-out test worlds: a main test set drawn as the training drives are, and stress sets drawn to show each hard case."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from offroad_path.looks import axis_values
from offroad_path.world.conditions import frame_conditions
from offroad_path.world.groups import GROUPS
from offroad_path.world.held_out import (
    DEVELOPMENT_STREAM,
    MIN_FRAMES,
    RETIRED_STREAM,
    choose_held_out_worlds,
    held_out_seed,
    stress_seed,
    survey,
)
from offroad_path.world.record import sequence_seed
from offroad_path.world.scene import build_world


def test_test_world_seeds_are_never_training_or_development_seeds():
    training = {sequence_seed(0, i) for i in range(1000)}
    tests = {held_out_seed(0, i, 5) for i in range(1000)}
    development = {held_out_seed(0, i, DEVELOPMENT_STREAM) for i in range(1000)}
    stress = {stress_seed(0, name, i) for name in ("dappled", "off_track") for i in range(1000)}
    assert not training & tests and not (training | tests) & stress and len(stress) == 2000
    assert not development & (training | tests | stress) and len(development) == 1000
    # the development set is the stream the earlier runs' main test set was drawn from (spawn key 1)
    assert held_out_seed(0, 5, DEVELOPMENT_STREAM) == int(np.random.SeedSequence([0, 5], spawn_key=(1,)).generate_state(1)[0])


@pytest.mark.slow(seconds=7)
def test_survey_counts_blocks_and_groups_over_the_labelled_frames(compose_config):
    cfg = compose_config("synthesize.test_worlds.block_m=20", "synthesize.test_worlds.horizon_m=20")
    c, seed = cfg.synthesize.test_worlds, held_out_seed(0, 0, 5)
    blocks, groups = survey(cfg.world, seed, c)
    world = build_world(cfg.world, seed)
    s = world.frame_s - world.frame_s[0]
    labelled = s <= s[-1] - 20
    assert blocks == int(s[labelled][-1] // 20) + 1  # the blocks are consecutive from the start
    rows = [r for r, keep in zip(frame_conditions(world, cfg.world), labelled, strict=True) if keep]
    assert groups == tuple(k for k, _, test in GROUPS if sum(map(test, rows)) >= MIN_FRAMES)
    assert "all" in groups and len(groups) < len(GROUPS)  # one world does not show everything
    # The survey builds its worlds without textures: the same world in everything else.
    bare = build_world(cfg.world, seed, textures=False)
    assert not bare.textures.keys() - {"dapple"} and world.textures.keys() - bare.textures.keys()
    for name in ("materials", "shadow", "poses", "palette", "steering", "wear"):
        assert np.array_equal(getattr(bare, name), getattr(world, name)), name
    assert np.array_equal(bare.terrain.heights, world.terrain.heights) and bare.look == world.look
    assert all(np.array_equal(getattr(bare.sky, f.name), getattr(world.sky, f.name)) for f in dataclasses.fields(world.sky))
    assert np.array_equal(bare.objects.arrays().params, world.objects.arrays().params)


@pytest.mark.slow(seconds=40)
def test_the_main_set_is_drawn_as_training_is_and_each_stress_set_shows_its_case(compose_config):
    c = compose_config(
        "synthesize.test_worlds.min_blocks=3", "synthesize.test_worlds.per_stress=1", "synthesize.test_worlds.development_blocks=2",
        "synthesize.test_worlds.retired_blocks=2", "synthesize.test_worlds.stress_sets=[held_out_look,outside_look]",
    ).synthesize.test_worlds  # fmt: skip
    cfg = compose_config().world
    chosen = choose_held_out_worlds(cfg, c, master_seed=0, workers=2)
    main = [w for w in chosen if w.test_set == "main"]
    # the main set: the first candidates in seed order, until the blocks are there, whatever they show
    assert [w.index for w in main] == list(range(len(main))) and sum(w.blocks for w in main[:-1]) < 3 <= sum(w.blocks for w in main)
    assert all(
        w.seed == held_out_seed(0, w.index, c.main_stream) and w.draw == "training" and w.name == f"test_{w.index:03d}" for w in main
    )
    retired = [w for w in chosen if w.retired]  # the retired main test set's worlds develop now, named apart
    assert retired and all(w.test_set == "development" and w.name == f"retired_{w.index:03d}" for w in retired)
    assert all(w.seed == held_out_seed(0, w.index, RETIRED_STREAM) for w in retired) and sum(w.blocks for w in retired) >= 2
    development = [w for w in chosen if w.test_set == "development" and not w.retired]
    assert [w.index for w in development] == list(range(len(development))) and sum(w.blocks for w in development) >= 2
    assert all(w.seed == held_out_seed(0, w.index, DEVELOPMENT_STREAM) and w.name == f"dev_{w.index:03d}" for w in development)
    assert not {w.seed for w in development} & {w.seed for w in main}
    stress = {w.test_set: w for w in chosen if w.test_set not in ("main", "development")}
    assert list(stress) == ["held_out_look", "outside_look"]
    for name, world in stress.items():
        assert name in world.groups and world.seed == stress_seed(0, name, world.index) and world.name == f"stress_{name}_{world.index:03d}"
    assert [stress[k].draw for k in stress] == ["held_out", "full_variety"]
    # every look a main world shows is of the training distribution
    for world in main:
        look = build_world(cfg, world.seed, world.draw).look
        assert look.track not in ("grass_track", "none") and look.light != "hazy" and not look.outside


@pytest.mark.slow(seconds=5)
def test_a_stress_set_the_weights_cannot_hold_is_left_out(compose_config, caplog):
    c = compose_config(
        "synthesize.test_worlds.min_blocks=1",
        "synthesize.test_worlds.development_blocks=0",
        "synthesize.test_worlds.retired_blocks=0",
        "synthesize.test_worlds.stress_sets=[outside_look]",
    ).synthesize.test_worlds
    every = compose_config(
        *(f"world.appearance.weights.{axis}.{value}=1.0" for axis in ("track", "light") for value in axis_values()[axis])
    ).world
    chosen = choose_held_out_worlds(every, c, master_seed=0, workers=1)
    assert {w.test_set for w in chosen} == {"main"} and "stress set outside_look" in caplog.text


@pytest.mark.slow(seconds=11)
def test_too_few_candidates_is_an_error_naming_the_set(compose_config):
    world = compose_config("world.frames=40").world  # a short drive: one block, quick to survey
    # Every set runs out (dev, main and a stress set, surveyed together): the first is named.
    c = compose_config(
        "synthesize.test_worlds.max_candidates=1", "synthesize.test_worlds.min_blocks=50", "synthesize.test_worlds.stress_sets=[dappled]"
    ).synthesize.test_worlds
    with pytest.raises(
        ValueError, match=r"test_worlds\.development_blocks: 1 candidate worlds hold fewer than 30 blocks; raise max_candidates"
    ):
        choose_held_out_worlds(world, c, master_seed=0, workers=1)
    c = compose_config(
        "synthesize.test_worlds.max_candidates=1", "synthesize.test_worlds.min_blocks=50", "synthesize.test_worlds.development_blocks=0",
        "synthesize.test_worlds.retired_blocks=0",
        "synthesize.test_worlds.stress_sets=[]",
    ).synthesize.test_worlds  # fmt: skip
    with pytest.raises(ValueError, match=r"test_worlds\.min_blocks: 1 candidate worlds hold fewer than 50 blocks; raise max_candidates"):
        choose_held_out_worlds(world, c, master_seed=0, workers=1)
    c = compose_config(
        "synthesize.test_worlds.max_candidates=1", "synthesize.test_worlds.min_blocks=1", "synthesize.test_worlds.development_blocks=0",
        "synthesize.test_worlds.retired_blocks=0",
        "synthesize.test_worlds.stress_sets=[shadow_water]", "synthesize.test_worlds.per_stress=2",
    ).synthesize.test_worlds  # fmt: skip
    with pytest.raises(ValueError, match=r"give stress set shadow_water [01] of 2 worlds; raise max_candidates or lower per_stress"):
        choose_held_out_worlds(world, c, master_seed=0, workers=1)
    none = compose_config("synthesize.test_worlds.min_blocks=0").synthesize.test_worlds
    assert choose_held_out_worlds(world, none, master_seed=0) == []
