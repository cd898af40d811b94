"""The README's own-data recipe, run as written (its code block, read from README.md) on a real MCAP
bag of the test drive, in a copy of the checkout holding the committed metrics: every stage works
and nothing is written into the checkout's data/ or metrics/ (the recipe as written once
replaced the committed results, then failed on evaluate)."""

from __future__ import annotations

import os
import re
import shlex
import shutil
import subprocess
import sys

import pytest
from conftest import TINY_TRAINING
from helpers import ROOT, snapshot

# What the test adds to the README's commands: its bag's names, and sizes a test can afford.
RENAMED = {"field.bag": "{bag}", "/odometry/filtered": "/odom", "ingest.fps=10": "ingest.fps=5"}
SMALLER = {
    "offroad_path.split": ("split.block_m=2", "split.guard_m=0"),  # 9 labels of a 40 m drive: blocks of 2 m, or all are test
    "offroad_path.train": (*TINY_TRAINING, "trainer.max_epochs=1"),
}


def recipe() -> list[str]:
    """The README's own-data commands, one per line (continuations joined)."""
    text = (ROOT / "README.md").read_text()
    block = re.search(r"```bash\n(ROOT=\$HOME/field.*?)```", text, re.S)
    assert block, "README.md: the own-data recipe's code block (ROOT=$HOME/field ...) is missing"
    return [line.split("  #")[0].strip() for line in block.group(1).replace("\\\n", " ").splitlines() if line.strip()]


@pytest.mark.slow(seconds=120)
def test_the_readmes_own_data_recipe_runs_and_leaves_the_checkout_alone(raw_drive, rig, drive, tmp_path):
    pytest.importorskip("rosbags")
    from raw_rig import body_poses, write_bag

    checkout = tmp_path / "checkout"  # a copy: the code, the config and the committed metrics with their markers
    for item in ("src", "conf", "metrics"):
        shutil.copytree(ROOT / item, checkout / item)
    before = snapshot(checkout)
    bag = write_bag(tmp_path / "field_mcap", "mcap", raw_drive, rig, poses=body_poses(drive / "drive"))
    lines = recipe()
    assert lines[0].startswith("ROOT=$HOME/field; OWN=")
    env = {
        **os.environ,
        "PYTHONPATH": str(checkout / "src"),
        "ROOT": str(tmp_path / "field"),
        "OWN": f"paths=own paths.root={tmp_path / 'field'}",
    }
    for line in lines[1:]:
        for old, new in RENAMED.items():
            line = line.replace(old, new.format(bag=bag))
        command = [
            sys.executable if word == "python" else word
            for word in shlex.split(os.path.expandvars(line.replace("$OWN", env["OWN"]).replace("$ROOT", env["ROOT"])))
        ]
        command += [*SMALLER.get(command[2], ()), "mlflow.enabled=false"] if command[2] != "offroad_path.sequence" else []
        run = subprocess.run(command, cwd=checkout, env=env, capture_output=True, text=True)
        assert run.returncode == 0, f"{line}\n{run.stderr[-1500:]}"
    assert snapshot(checkout) == before  # nothing under the checkout's data/ or metrics/, nothing replaced
    field = tmp_path / "field"
    assert (field / "recordings" / "recording" / "calib.txt").is_file()
    assert (field / "data" / "runs" / "unet-none" / "seed0" / "checkpoints" / "best.ckpt").is_file()
    assert (field / "metrics" / "evaluation.json").is_file() and (field / "metrics" / "label.json").is_file()
