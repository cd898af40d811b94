"""The benchmarks validate their arguments as the stages do: one line naming the argument, exit 2,
before any work."""

from __future__ import annotations

import subprocess
import sys

import pytest
from helpers import ROOT


@pytest.mark.parametrize(
    ("script", "arguments", "says"),
    [
        ("learning_curve.py", ["--drives", "0"], "--drives: 0 is not a number of drives"),
        ("learning_curve.py", ["--drives", "-1"], "--drives: -1 is not a number of drives"),
        ("learning_curve.py", ["--models", "nonet"], "--models: unknown 'nonet'; valid: segnet, fcn, unet"),
        ("learning_curve.py", ["--seeds", "-5"], "--seeds: -5 is negative"),
        ("recipe_search.py", ["--recipes", "nope"], "--recipes: unknown 'nope'"),
        ("recipe_search.py", ["--val-every", "2"], "--val-every: 2.0 is not in (0, 1]"),
    ],
)
def test_a_bad_argument_is_one_line_and_exit_2(script, arguments, says, tmp_path):
    run = subprocess.run([sys.executable, str(ROOT / "benchmarks" / script), *arguments, "--work", str(tmp_path / "w")],
                         capture_output=True, text=True, timeout=120)  # fmt: skip
    lines = run.stderr.strip().splitlines()
    assert run.returncode == 2 and len(lines) == 1 and lines[0].startswith(f"error: {says}"), run.stderr
    assert not (tmp_path / "w").exists()


@pytest.mark.parametrize("script", ["label_cpu.py", "learning_curve.py", "seed_spread.py", "pipeline_time.py"])
def test_help_prints_and_writes_nothing(script, tmp_path):
    """`--help` is help: once, a benchmark took it for its work folder and ran, writing into `./--help`."""
    run = subprocess.run([sys.executable, str(ROOT / "benchmarks" / script), "--help"], capture_output=True, text=True, cwd=tmp_path,
                         timeout=120)  # fmt: skip
    assert run.returncode == 0 and "usage:" in run.stdout, run.stderr[-800:]
    assert list(tmp_path.iterdir()) == []
