"""The benchmarks validate their arguments as the stages do: one line naming the argument, exit 2,
before any work."""

from __future__ import annotations

import pytest
from helpers import ROOT, command


@pytest.mark.parametrize(
    ("script", "arguments", "says"),
    [
        ("learning_curve.py", ["--drives", "0"], "--drives: 0 is not a number of drives"),
        ("learning_curve.py", ["--drives", "-1"], "--drives: -1 is not a number of drives"),
        ("learning_curve.py", ["--models", "nonet"], "--models: unknown 'nonet'; valid: segnet, fcn, unet"),
        ("learning_curve.py", ["--seeds", "-5"], "--seeds: -5 is negative"),
        ("recipe_search.py", ["--recipes", "nope"], "--recipes: unknown 'nope'"),
        ("recipe_search.py", ["--val-every", "2"], "--val-every: 2.0 is not in (0, 1]"),
        ("recipe_search.py", ["--seeds", "0", "0"], "--seeds: 0 is listed twice"),
        ("learning_curve.py", ["--seeds", "1", "1"], "--seeds: 1 is listed twice"),
    ],
)
def test_a_bad_argument_is_one_line_and_exit_2(script, arguments, says, tmp_path):
    run = command(str(ROOT / "benchmarks" / script), *arguments, "--work", tmp_path / "w")
    lines = run.stderr.strip().splitlines()
    assert run.returncode == 2 and len(lines) == 1 and lines[0].startswith(f"error: {says}"), run.stderr
    assert not (tmp_path / "w").exists()


@pytest.mark.parametrize(
    ("arguments", "says"),
    [
        (["--models", "nonet"], "--models: unknown 'nonet'; valid: fcn, segnet, unet"),
        (["--processes", "2", "0"], "--processes: 0 is not a positive count"),
    ],
)
def test_the_gpu_probe_refuses_a_bad_argument_before_any_step(arguments, says, tmp_path):
    run = command(str(ROOT / "benchmarks" / "gpu_training.py"), *arguments, "--json", tmp_path / "figures.json")
    assert run.returncode == 2 and run.stderr.strip() == f"error: {says}" and run.stdout == ""
    assert not (tmp_path / "figures.json").exists()


@pytest.mark.parametrize("script", ["recipe_search.py", "learning_curve.py"])
def test_a_development_set_of_one_world_is_refused_before_training(script, tmp_path):
    """Once every search on one development world trained, then failed on its interval (AttributeError)."""
    from offroad_path.data.manifest import Sample, write_manifest

    split = tmp_path / "data" / "split"
    split.mkdir(parents=True)
    rows = [Sample("dev_000", f0, False, "i.png", "l.png", "", "", 100.0, 0.2) for f0 in (0, 5, 10)]
    for part in ("train", "val", "development"):
        write_manifest(split / f"{part}.csv", rows if part == "development" else [])
    arguments = ["--data", str(tmp_path / "data"), "--work", str(tmp_path / "w")]
    run = command(str(ROOT / "benchmarks" / script), *arguments)
    lines = run.stderr.strip().splitlines()
    assert run.returncode == 2 and len(lines) == 1, run.stderr
    assert lines[0].startswith(f"error: {split / 'development.csv'}: 1 development world(s)") and "at least 2" in lines[0]
    assert not (tmp_path / "w").exists()


@pytest.mark.parametrize(
    "script", ["label_cpu.py", "learning_curve.py", "seed_spread.py", "pipeline_time.py", "gpu_training.py", "suite_time.py"]
)
def test_help_prints_and_writes_nothing(script, tmp_path):
    """`--help` is help: once, a benchmark took it for its work folder and ran, writing into `./--help`."""
    run = command(str(ROOT / "benchmarks" / script), "--help", cwd=tmp_path)
    assert run.returncode == 0 and "usage:" in run.stdout, run.stderr[-800:]
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    ("arguments", "says"),
    [(["--draws", "0"], "--draws: '0' is not a whole number of at least 1"), (["--scale", "-1"], "--scale: '-1' is not a number above 0")],
)
def test_the_calibration_benchmark_refuses_no_draws_or_a_negative_scale_before_the_odometry(arguments, says, tmp_path):
    """Not after minutes of odometry with a ValueError of min() or of the random draw."""
    run = command(str(ROOT / "benchmarks" / "calibration_sensitivity.py"), str(tmp_path), *arguments)
    assert run.returncode == 2 and says in run.stderr.strip().splitlines()[-1] and run.stdout == ""
