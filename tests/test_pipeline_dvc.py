"""`dvc repro` on a tiny preset in a temporary copy of the repository: runs every stage, then
runs nothing, then reruns what a config edit touches."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from offroad_path.sequence import find_sequences

ROOT = Path(__file__).resolve().parents[1]


def dvc(repo: Path, *args: str) -> str:
    env = dict(os.environ)
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env['PATH']}"  # `python` in dvc.yaml is this one
    env["PYTHONPATH"] = str(repo / "src")  # the copy's code, not the installed checkout's
    run = subprocess.run([sys.executable, "-m", "dvc", *args], cwd=repo, env=env, capture_output=True, text=True)
    assert run.returncode == 0, run.stdout + run.stderr
    return run.stdout


@pytest.fixture
def repo_copy(tmp_path) -> Path:
    repo = tmp_path / "repo"
    for item in ("conf", "src", "dvc.yaml", ".dvcignore"):
        (shutil.copytree if (ROOT / item).is_dir() else shutil.copy)(ROOT / item, repo / item)
    laptop = repo / "conf" / "experiment" / "laptop.yaml"
    preset = yaml.safe_load(laptop.read_text())
    preset["world"].update(frames=3, width=160, height=96)
    preset["synthesize"]["sequences"] = 2
    laptop.write_text("# @package _global_\n" + yaml.safe_dump(preset))
    subprocess.run([sys.executable, "-m", "dvc", "init", "--no-scm", "-q"], cwd=repo, check=True)
    return repo


def test_repro_runs_then_is_up_to_date_then_follows_a_config_edit(repo_copy):
    out = dvc(repo_copy, "repro")
    assert "Running stage 'synthesize'" in out and "Running stage 'label'" in out
    assert len(find_sequences(repo_copy / "data" / "synthetic")) == 2
    assert sorted(p.name for p in (repo_copy / "data" / "labels").iterdir()) == ["seq_000", "seq_001", "summary.json"]
    assert json.loads((repo_copy / "metrics" / "label.json").read_text())["sequences"] == 2
    assert "Data and pipelines are up to date" in dvc(repo_copy, "repro")
    world = repo_copy / "conf" / "world" / "default.yaml"
    world.write_text(world.read_text().replace("hill_height_m: 4.0", "hill_height_m: 2.0"))
    assert "Running stage 'synthesize'" in dvc(repo_copy, "repro")
