"""gpu/repro.sh and gpu/measure.sh check every argument before any work or folder: a refused run
leaves nothing behind that would refuse the corrected one."""

from __future__ import annotations

import shutil
import subprocess

import pytest
from helpers import ROOT


@pytest.fixture
def checkout(tmp_path):
    """The scripts and the pipeline files they check, in a folder of their own (nothing of the checkout's changes)."""
    for item in ("gpu", "tour", "rehearsal"):
        shutil.copytree(ROOT / item, tmp_path / item)
    return tmp_path


@pytest.mark.parametrize(
    ("script", "arguments", "says"),
    [
        ("repro.sh", ["--jobs", "0"], "--jobs: 0 is not a whole number above 0"),
        ("repro.sh", ["--jobs", "-1"], "--jobs: -1 is not a whole number above 0"),
        ("repro.sh", ["--jobs", "x"], "--jobs: x is not a whole number above 0"),
        ("repro.sh", ["--pipeline", "tour/params.yaml"], "--pipeline: tour/params.yaml is not a pipeline file"),
        ("repro.sh", ["--wheelhouse", "nowhere"], "--wheelhouse: nowhere is no folder"),
        ("repro.sh", ["--limit", "0"], "--limit: 0 is not a whole number of seconds above 0"),
        ("repro.sh", ["--limit"], "--limit: needs a value"),
        ("repro.sh", ["--archive", "nowhere/run.tgz"], "--archive: nowhere is no folder"),
        ("measure.sh", ["--limit", "-1", "--out", "m"], "--limit: -1 is not a whole number of seconds above 0"),
        ("measure.sh", ["--jobs", "0", "--out", "m"], "--jobs: 0 is not a whole number above 0"),
        ("measure.sh", ["--rehearse", "--wheelhouse", "nowhere", "--out", "m"], "--wheelhouse: nowhere is no folder"),
    ],
)
def test_a_bad_argument_is_refused_before_any_folder_is_made(checkout, script, arguments, says):
    run = subprocess.run(["bash", str(checkout / "gpu" / script), *arguments], cwd=checkout, capture_output=True, text=True)
    assert run.returncode == 2 and run.stderr.strip().startswith(f"error: {says}") and len(run.stderr.strip().splitlines()) == 1, run.stderr
    for made in ("gpu/metrics", "gpu/data", "rehearsal/metrics", "tour/metrics", "m"):
        assert not (checkout / made).exists(), made


def test_measure_refuses_an_earlier_archive_before_its_benchmarks(checkout):
    """gpu/repro.sh refuses to replace an archive; measure.sh says so before its benchmarks' minutes, and keeps it."""
    (checkout / "kept").mkdir()
    (checkout / "kept" / "run.tgz").write_bytes(b"an earlier slot's figures")
    run = subprocess.run(["bash", str(checkout / "gpu" / "measure.sh"), "--out", "kept"], cwd=checkout, capture_output=True, text=True)
    assert run.returncode == 2 and run.stderr.strip() == "error: --out: kept/run.tgz exists; name another folder", run.stderr
    assert (checkout / "kept" / "run.tgz").read_bytes() == b"an earlier slot's figures" and not (checkout / "gpu" / "metrics").exists()
