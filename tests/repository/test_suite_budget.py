"""The suite's own rule (tests/conftest.py): a test not marked slow whose body runs over the budget
fails the run and is named; a slow one may take as long as it needs."""

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


@pytest.mark.slow(seconds=9)
def test_a_test_not_marked_slow_over_the_budget_fails_the_run(tmp_path):
    for name in ("conftest.py", "helpers.py"):
        shutil.copy(ROOT / "tests" / name, tmp_path / name)
    (tmp_path / "test_probe.py").write_text(PROBE)

    def probe(budget_s: str) -> subprocess.CompletedProcess:
        command = [sys.executable, "-m", "pytest", "-n0", "-p", "no:cacheprovider", "-o", "addopts=", "--rootdir", tmp_path, tmp_path]
        env = {**os.environ, "OFFROAD_NOT_SLOW_BUDGET_S": budget_s}
        return subprocess.run(list(map(str, command)), capture_output=True, text=True, env=env, cwd=tmp_path)

    tight = probe("0.3")
    assert tight.returncode == 1 and "3 passed" in tight.stdout, tight.stdout[-2000:]
    named = tight.stdout.split("not marked slow, yet over 0.3 s")[1].split("\n=")[0]
    assert "test_probe.py::test_dawdles" in named and "test_marked_slow" not in named and "test_quick" not in named
    easy = probe("5")
    assert easy.returncode == 0, easy.stdout[-2000:]
