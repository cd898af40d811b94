"""Held-out test worlds: drawn from a seed stream of their own, kept while they add blocks or conditions."""

from __future__ import annotations

import pytest

from offroad_path.world.conditions import frame_conditions
from offroad_path.world.groups import GROUPS
from offroad_path.world.held_out import MIN_FRAMES, choose_held_out_worlds, held_out_seed, survey
from offroad_path.world.record import sequence_seed
from offroad_path.world.scene import build_world


def test_test_world_seeds_are_never_training_seeds():
    training = {sequence_seed(0, i) for i in range(1000)}
    assert not training & {held_out_seed(0, i) for i in range(1000)}


@pytest.mark.slow(seconds=7)
def test_survey_counts_blocks_and_groups_over_the_labelled_frames(compose_config):
    cfg = compose_config("synthesize.test_worlds.block_m=20", "synthesize.test_worlds.horizon_m=20")
    c, seed = cfg.synthesize.test_worlds, held_out_seed(0, 0)
    blocks, groups = survey(cfg.world, seed, c)
    world = build_world(cfg.world, seed)
    s = world.frame_s - world.frame_s[0]
    labelled = s <= s[-1] - 20
    assert blocks == int(s[labelled][-1] // 20) + 1  # the blocks are consecutive from the start
    rows = [r for r, keep in zip(frame_conditions(world, cfg.world), labelled, strict=True) if keep]
    assert groups == tuple(k for k, _, test in GROUPS if sum(map(test, rows)) >= MIN_FRAMES)
    assert "all" in groups and len(groups) < len(GROUPS)  # one world does not show everything


@pytest.mark.slow(seconds=36)
def test_the_chosen_worlds_show_every_group_and_each_adds_one_lacking(compose_config):
    c = compose_config("synthesize.test_worlds.per_condition=1", "synthesize.test_worlds.min_blocks=1").synthesize.test_worlds
    cfg = compose_config().world
    chosen = choose_held_out_worlds(cfg, c, master_seed=0, workers=2)
    assert {k for w in chosen for k in w.groups} == {k for k, _, _ in GROUPS}
    assert [w.index for w in chosen] == sorted(w.index for w in chosen) and chosen[0].index == 0
    for i, world in enumerate(chosen[1:], start=1):
        shown = {k for w in chosen[:i] for k in w.groups}
        assert set(world.groups) - shown  # kept only for a group the earlier ones lack
    assert [w.name for w in chosen][:1] == ["test_000"]
    assert all(w.seed == held_out_seed(0, w.index) for w in chosen)


def test_too_few_candidates_is_an_error_naming_what_is_lacking(compose_config):
    c = compose_config("synthesize.test_worlds.max_candidates=1", "synthesize.test_worlds.min_blocks=50").synthesize.test_worlds
    with pytest.raises(
        ValueError,
        match=r"synthesize\.test_worlds: 1 candidate worlds do not make the test set \(\d+ of 50 blocks, .*shadow in \d of 3 worlds",
    ):
        choose_held_out_worlds(compose_config().world, c, master_seed=0, workers=1)
    none = compose_config("synthesize.test_worlds.min_blocks=0").synthesize.test_worlds
    assert choose_held_out_worlds(compose_config().world, none, master_seed=0) == []
