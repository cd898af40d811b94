"""The suite's own rule (tests/conftest.py): a test not marked slow whose body runs over the budget
is named at the end of the run, which still passes (a slower machine is no failure); a slow one may
take as long as it needs."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys

import pytest
from helpers import ROOT

PROBE = """import time

import pytest


def test_quick():
    pass


def test_dawdles():
    time.sleep(0.6)


@pytest.mark.slow(seconds=1)
def test_marked_slow():
    time.sleep(0.6)
"""


@pytest.mark.slow(seconds=5)
def test_a_test_not_marked_slow_over_the_budget_is_named_and_the_run_passes(tmp_path):
    for name in ("conftest.py", "helpers.py"):
        shutil.copy(ROOT / "tests" / name, tmp_path / name)
    (tmp_path / "test_probe.py").write_text(PROBE)

    command = [sys.executable, "-m", "pytest", "-n0", "-p", "no:cacheprovider", "-o", "addopts=", "--rootdir", tmp_path, tmp_path]
    env = {**os.environ, "OFFROAD_NOT_SLOW_BUDGET_S": "0.3"}
    run = subprocess.run(list(map(str, command)), capture_output=True, text=True, env=env, cwd=tmp_path)
    assert run.returncode == 0 and "3 passed" in run.stdout, run.stdout[-2000:]
    named = run.stdout.split("not marked slow, yet over 0.3 s")[1].split("\n=")[0]
    assert "test_probe.py::test_dawdles" in named and "test_marked_slow" not in named and "test_quick" not in named


def test_the_suite_timer_reads_each_tiers_counts_and_exit(tmp_path):
    """benchmarks/suite_time.py times a tier by pytest's own last line: its counts and seconds, with -q."""
    from suite_time import run_tier

    (tmp_path / "test_probe.py").write_text(
        "import pytest\n\ndef test_a():\n    pass\n\ndef test_b():\n    assert False\n\n@pytest.mark.slow\ndef test_c():\n    pass\n"
    )
    full, everyday = run_tier(tmp_path, "full"), run_tier(tmp_path, "everyday")
    assert (full["passed"], full["failed"], full["exit"]) == (2, 1, 1) and full["seconds"] >= 0
    assert (everyday["passed"], everyday["failed"], everyday["exit"]) == (1, 1, 1)
