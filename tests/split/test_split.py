"""Splits: nothing held out has a neighbour in training; mirrored copies stay beside their frame."""

from __future__ import annotations

import json
import logging

import numpy as np
import pytest

from offroad_path.data.manifest import read_manifest
from offroad_path.data.splitting import Frame, split_frames
from offroad_path.split import split


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


def test_split_stage_writes_manifests_with_mirrored_pairs(compose_config, labelled_drive, tmp_path):
    # The drive has ~10 labels over 20 m: small blocks, so that all three parts get some.
    overrides = (f"split.labels_dir={labelled_drive}", f"split.out_dir={tmp_path / 'split'}", "split.block_m=4", "split.guard_m=3")
    summary = split(compose_config(*overrides))
    parts = {name: read_manifest(tmp_path / "split" / f"{name}.csv") for name in ("train", "val", "test")}
    labelled = len(list(labelled_drive.glob("*/label/*.png")))
    assert summary["frames"] == labelled
    assert sum(len(p) for p in parts.values()) == 2 * (labelled - summary["guarded_out"])
    for part in parts.values():
        by_frame = {}
        for sample in part:
            by_frame.setdefault(sample.f0, []).append(sample.mirrored)
        assert all(sorted(m) == [False, True] for m in by_frame.values())  # each frame with its mirror
    f0 = {name: {s.f0 for s in part} for name, part in parts.items()}
    assert not (f0["train"] & f0["test"]) and not (f0["train"] & f0["val"]) and parts["test"]
    sample = parts["train"][0]
    assert sample.image.endswith(f"image_l/{sample.f0:06d}.png") and sample.semantic.endswith(f"semantic/{sample.f0:06d}.png")
    assert sample.baseline_m == pytest.approx(0.21) and sample.fx == pytest.approx(305.089, abs=1e-3)
    assert json.loads((tmp_path / "split" / "summary.json").read_text()) == summary
    np.testing.assert_array_less(0, [len(p) for p in parts.values()])


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


def test_split_stage_takes_a_held_out_recording_as_test_and_refuses_another_split_value(compose_config, labelled_drive, tmp_path):
    import shutil

    from offroad_path.data.labels import read_label_run

    # A second copy of the drive's recording and labels, marked held out in its meta.json.
    labels = tmp_path / "labels"
    shutil.copytree(labelled_drive, labels)
    recording = read_label_run(labels)[0].sequence.root
    world = tmp_path / "recordings" / "world"
    shutil.copytree(recording, world)
    meta = json.loads((world / "meta.json").read_text())
    (world / "meta.json").write_text(json.dumps(meta | {"split": "test"}))
    run_summary = json.loads((labels / "summary.json").read_text())
    (entry,) = run_summary["sequences"]
    shutil.copytree(labels / entry["name"], labels / "world")
    run_summary["sequences"].append(entry | {"name": "world", "root": str(world)})
    (labels / "summary.json").write_text(json.dumps(run_summary))
    overrides = (f"split.labels_dir={labels}", f"split.out_dir={tmp_path / 'split'}", "split.block_m=4", "split.guard_m=3")
    summary = split(compose_config(*overrides))
    test = read_manifest(tmp_path / "split" / "test.csv")
    assert {s.sequence for s in test} == {"world"} and summary["test_worlds"] == ["world"]
    assert summary["samples"]["test"] == 2 * len(list((labels / "world" / "label").glob("*.png")))
    assert summary["test_blocks"] == len({int(d // 4) for d in read_label_run(labels)[1].distance()[[s.f0 for s in test]]})
    # A development world: held out too, but in development.csv alone (settings are chosen there).
    (world / "meta.json").write_text(json.dumps(meta | {"split": "test", "test_set": "development"}))
    summary = split(compose_config(*overrides))
    development = read_manifest(tmp_path / "split" / "development.csv")
    assert {s.sequence for s in development} == {"world"} and summary["development_worlds"] == ["world"]
    assert summary["test_worlds"] == [] and not any(s.sequence == "world" for name in ("train", "val", "test")
                                                     for s in read_manifest(tmp_path / "split" / f"{name}.csv"))  # fmt: skip
    (world / "meta.json").write_text(json.dumps(meta | {"split": "train"}))
    with pytest.raises(ValueError, match=r"world/meta\.json: \"split\" is 'train'; the only value it may take is \"test\""):
        split(compose_config(*overrides))


def test_no_frame_of_a_held_out_world_may_train_or_validate_any_network():
    from offroad_path.data.splitting import refuse_held_out_training

    refuse_held_out_training({"train": ["drive_000"], "val": ["drive_001"], "test": ["test_000"]}, {"test_000"}, "split")
    with pytest.raises(
        ValueError, match=r"PilotNet's split: frames of held-out worlds would train a network \(train: test_000; val: dev_000\)"
    ):
        refuse_held_out_training({"train": ["drive_000", "test_000"], "val": ["dev_000"]}, {"test_000", "dev_000"}, "PilotNet's split")
