"""The split stage: manifests with mirrored copies beside their frame, held-out recordings as the test set."""

from __future__ import annotations

import json

import numpy as np
import pytest

from offroad_path.data.manifest import read_manifest
from offroad_path.split import split


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
