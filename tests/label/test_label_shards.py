"""Labelling across jobs: shards run by Hydra's submitit launcher (its local executor runs the code
path SLURM runs, without the scheduler), merged into exactly what one run writes."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from helpers import label_cfg, refused, snapshot

from offroad_path.label import label
from offroad_path.world.record import Drive, record_sequences

TINY = ("label.distance_m=4.0", "label.stride_m=1.0")


@pytest.fixture(scope="module")
def three_drives(compose_config, tmp_path_factory) -> Path:
    """Three 12-frame drives of the tiny world, each from its own seed."""
    root = tmp_path_factory.mktemp("three") / "recordings"
    world = compose_config("world.frames=12", "world.width=256", "world.height=144", "world.max_distance_m=40").world
    record_sequences(world, [Drive(f"drive_{i}", 40 + i) for i in range(3)], root, workers=1)
    return root


@pytest.fixture(scope="module")
def single_run(compose_config, three_drives, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("single")
    label(label_cfg(compose_config, three_drives, out, *TINY))
    return out


@pytest.fixture(scope="module")
def shard_folders(three_drives, tmp_path_factory) -> Path:
    """Two shards, each a job of a submitit_local multirun."""
    out = tmp_path_factory.mktemp("sharded")
    command = [sys.executable, "-m", "offroad_path.label", "-m", "hydra/launcher=submitit_local", f"hydra.sweep.dir={out / 'sweep'}",
               "hydra.launcher.cpus_per_task=1", f"label.in_dir={three_drives}", "label.workers=1", "mlflow.enabled=false", "threads=1",
               *TINY, "label.shards=2", "label.shard=0,1", f"label.out_dir={out / 'shards'}/${{label.shard}}"]  # fmt: skip
    subprocess.run(command, check=True, cwd=out, capture_output=True, text=True)
    return out / "shards"


@pytest.mark.slow(seconds=11)
def test_shards_merge_into_what_one_run_writes(compose_config, three_drives, single_run, shard_folders, tmp_path):
    assert sorted(json.loads((shard_folders / str(i) / "shard.json").read_text())["sequences"] for i in (0, 1)) == [
        ["drive_0", "drive_2"], ["drive_1"]]  # fmt: skip
    assert not (shard_folders.parent / "m.json").exists()  # a shard writes no metrics file of the run
    metrics = label(label_cfg(compose_config, three_drives, tmp_path, *TINY, f"label.merge_from={shard_folders}"))
    assert metrics["sequences"] == 3 and metrics["labels"] > 0
    assert snapshot(tmp_path / "labels") == snapshot(single_run / "labels")  # every label, pose, report and the summary
    assert (tmp_path / "m.json").read_bytes() == (single_run / "m.json").read_bytes()


@pytest.mark.slow(seconds=3)  # beside the merge test, which makes the shards it reads anyway
def test_a_merge_of_shards_that_do_not_make_the_run_is_refused(compose_config, three_drives, shard_folders, tmp_path, capsys):
    partial = tmp_path / "partial"
    shutil.copytree(shard_folders / "0", partial / "0")
    refused(label, label_cfg(compose_config, three_drives, tmp_path, *TINY, f"label.merge_from={partial}"), capsys, tmp_path,
            f"{partial / '0'}", "shard 0 of 2")  # fmt: skip
    other = label_cfg(compose_config, three_drives, tmp_path, "label.distance_m=5.0", "label.stride_m=1.0",
                      f"label.merge_from={shard_folders}")  # fmt: skip
    refused(label, other, capsys, tmp_path, "was labelled with another label config")
    refused(label, label_cfg(compose_config, three_drives, tmp_path, *TINY, "label.shards=2", "label.shard=2"), capsys, tmp_path,
            "label.shard=2", "less than label.shards")  # fmt: skip
