"""Splitting frames into training, validation and test: nothing held out has a neighbour in
training, held-out worlds are the whole test set."""

from __future__ import annotations

import logging

import pytest

from offroad_path.data.splitting import Frame, split_frames


def frames_along(sequences: int, count: int, spacing_m: float) -> list[Frame]:
    return [Frame(f"s{s}", i, i * spacing_m) for s in range(sequences) for i in range(count)]


def test_grouped_split_leaves_no_neighbour_in_training(compose_config):
    frames = frames_along(3, 100, 2.0)
    c = compose_config("split.test_fraction=0.1", "split.val_fraction=0.1", "split.block_m=20", "split.guard_m=10", "split.seed=3").split
    parts, guarded = split_frames(frames, c)
    assert 30 <= len(parts["test"]) <= 40 and 30 <= len(parts["val"]) <= 40
    assert guarded > 0 and len(parts["train"]) + len(parts["test"]) + len(parts["val"]) + guarded == 300
    for held in parts["test"] + parts["val"]:
        nearest = min(abs(t.travelled_m - held.travelled_m) for t in parts["train"] if t.sequence == held.sequence)
        assert nearest >= 10.0
    # Blocks stay whole: a 20 m block is all on one side.
    side = {(f.sequence, int(f.travelled_m // 20)): name for name, part in parts.items() for f in part}
    for name, part in parts.items():
        for f in part:
            assert side[(f.sequence, int(f.travelled_m // 20))] == name
    again, _ = split_frames(frames, c)
    assert again == parts


def test_random_split_is_the_papers_and_warns(compose_config, caplog):
    frames = frames_along(1, 100, 2.0)
    with caplog.at_level(logging.WARNING):
        parts, guarded = split_frames(frames, compose_config("split.strategy=random", "split.seed=0").split)
    assert "near-duplicate" in caplog.text and guarded == 0
    assert (len(parts["test"]), len(parts["val"]), len(parts["train"])) == (10, 10, 80)
    train = {f.travelled_m for f in parts["train"]}
    assert any(abs(f.travelled_m - t) <= 2.0 for f in parts["test"] for t in train)  # neighbours leak


def test_stretch_split_holds_out_the_last_stretch_of_each_recording_with_a_guard(compose_config):
    """strategy=stretch (experiment=own): of 0-198 m in 2 m steps, test is from 148.5 m (the last
    quarter of 198 m), validation from 118.8 m (the 15 % before), and training ends 10 m before that."""
    c = compose_config("split.strategy=stretch", "split.test_fraction=0.25", "split.val_fraction=0.15", "split.guard_m=10").split
    parts, guarded = split_frames(frames_along(2, 100, 2.0), c)
    for sequence in ("s0", "s1"):
        own = {name: sorted(f.travelled_m for f in part if f.sequence == sequence) for name, part in parts.items()}
        assert (own["test"][0], own["test"][-1], len(own["test"])) == (150.0, 198.0, 25)
        assert (own["val"][0], own["val"][-1], len(own["val"])) == (120.0, 148.0, 15)
        assert (own["train"][0], own["train"][-1], len(own["train"])) == (0.0, 110.0, 56)  # 112-118 m: within 10 m of 120
    assert guarded == 2 * 4


def test_unknown_strategy_lists_valid_ones(compose_config):
    with pytest.raises(ValueError, match="valid: grouped, stretch, random"):
        split_frames(frames_along(1, 10, 2.0), compose_config("split.strategy=kfold").split)


def test_held_out_worlds_are_the_whole_test_set(compose_config):
    drives = frames_along(3, 100, 2.0)
    worlds = [Frame(f"test_{s}", i, i * 2.0, held_out=True) for s in range(2) for i in range(30)]
    c = compose_config("split.test_fraction=0.1", "split.val_fraction=0.1", "split.block_m=20", "split.seed=3").split
    parts, _ = split_frames(drives + worlds, c)
    assert parts["test"] == worlds  # no block of a drive: test_fraction takes none while test worlds exist
    assert not any(f.held_out for f in parts["train"] + parts["val"])
    assert 30 <= len(parts["val"]) <= 40  # val_fraction of the drives' frames
    random, _ = split_frames(drives + worlds, compose_config("split.strategy=random", "split.seed=0").split)
    assert random["test"] == worlds and len(random["val"]) == 30
