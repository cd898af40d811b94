"""tools/parallel_repro.py runs a pipeline's independent stages side by side through real DVC, in a
fresh git + DVC repository: two stages that need only the first overlap in time, the last waits for
both, and the lock and outputs are those of one `dvc repro`; a failed stage stops what depends on it."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml
from helpers import git
from parallel_repro import main

# Each stage writes its output and the wall-clock times it ran between (seconds since the epoch).
STAGE = (
    '{python} -c "import pathlib, sys, time; t = time.time(); time.sleep({sleep}); '
    "pathlib.Path('{out}').write_text(f'{{t}} {{time.time()}}\\n' + ''.join(pathlib.Path(d).read_text() for d in sys.argv[1:]))\" {deps}"
)


def pipeline(repo, stages: dict[str, tuple[list[str], float, bool]]) -> None:
    """stages: name -> (the stages it reads, seconds it sleeps, whether it fails)."""
    spec = {}
    for name, (deps, sleep, fails) in stages.items():
        cmd = STAGE.format(python=sys.executable, sleep=sleep, out=f"{name}.txt", deps=" ".join(f"{d}.txt" for d in deps))
        spec[name] = {"cmd": cmd + (" && exit 3" if fails else ""), "deps": [f"{d}.txt" for d in deps] or None, "outs": [f"{name}.txt"]}
        spec[name] = {k: v for k, v in spec[name].items() if v is not None}
    (repo / "dvc.yaml").write_text(yaml.safe_dump({"stages": spec}, sort_keys=False))
    git(repo, "init", "-q")
    subprocess.run([sys.executable, "-m", "dvc", "init", "-q"], cwd=repo, check=True)


def ran(repo, stage: str) -> tuple[float, float]:
    start, end = (repo / f"{stage}.txt").read_text().splitlines()[0].split()
    return float(start), float(end)


@pytest.mark.slow(seconds=8)
def test_independent_stages_run_side_by_side_and_the_lock_is_one_repros(tmp_path, capsys):
    pipeline(tmp_path, {"first": ([], 0, False), "left": (["first"], 3, False), "right": (["first"], 3, False),
                        "last": (["left", "right"], 0, False)})  # fmt: skip
    timing = tmp_path / "metrics" / "pipeline_time.json"
    assert main([str(tmp_path / "dvc.yaml"), "--jobs", "2", "--json", str(timing)]) == 0
    (left_start, left_end), (right_start, right_end) = ran(tmp_path, "left"), ran(tmp_path, "right")
    assert left_start < right_end and right_start < left_end, "left and right ran one after the other"
    assert ran(tmp_path, "first")[1] <= min(left_start, right_start) and ran(tmp_path, "last")[0] >= max(left_end, right_end)
    lock = yaml.safe_load((tmp_path / "dvc.lock").read_text())["stages"]
    assert set(lock) == {"first", "left", "right", "last"}
    status = subprocess.run([sys.executable, "-m", "dvc", "status"], cwd=tmp_path, capture_output=True, text=True)
    assert "up to date" in status.stdout, status.stdout + status.stderr
    timed = json.loads(timing.read_text())
    assert set(timed["stages"]) == {"first", "left", "right", "last"} and timed["jobs"] == 2
    assert timed["complete"] is True and timed["unfinished"] == []
    assert timed["total_s"] >= timed["stages"]["left"] >= 3 and timed["total_s"] < timed["stages"]["left"] + timed["stages"]["right"] + 5


def test_a_failed_stage_stops_what_depends_on_it_and_names_itself(tmp_path, capsys):
    pipeline(tmp_path, {"first": ([], 0, False), "broken": (["first"], 0, True), "after": (["broken"], 0, False)})
    timing = tmp_path / "pipeline_time.json"
    assert main([str(tmp_path / "dvc.yaml"), "--jobs", "2", "--json", str(timing)]) == 1
    timed = json.loads(timing.read_text())
    assert timed["complete"] is False and set(timed["stages"]) == {"first", "broken"}
    assert "error: stage broken failed" in capsys.readouterr().err
    assert not (tmp_path / "after.txt").exists()
    assert set(yaml.safe_load((tmp_path / "dvc.lock").read_text())["stages"]) == {"first"}


@pytest.mark.slow(seconds=6)
def test_a_run_stopped_by_a_time_limit_keeps_the_times_of_the_stages_it_finished(tmp_path):
    """A device's time limit sends SIGTERM: the stage times written so far stay, marked incomplete,
    the stopped stage named unfinished. Run from the pipeline's own folder, where DVC's stage
    addresses carry no file name (the tool once found no stage there and ran none)."""
    pipeline(tmp_path, {"first": ([], 0, False), "long": (["first"], 60, False)})
    timing = tmp_path / "pipeline_time.json"
    tool = Path(__file__).resolve().parents[2] / "tools" / "parallel_repro.py"
    log = tmp_path / "pipeline_time.log"
    run = subprocess.Popen([sys.executable, str(tool), str(tmp_path / "dvc.yaml"), "--json", str(timing), "--log", str(log)], cwd=tmp_path)
    deadline = time.monotonic() + 60
    while not (timing.is_file() and "first" in json.loads(timing.read_text())["stages"]) and time.monotonic() < deadline:
        time.sleep(0.2)
    time.sleep(1.0)  # long's dvc has started its command
    run.send_signal(signal.SIGTERM)
    assert run.wait(timeout=60) == 128 + signal.SIGTERM
    timed = json.loads(timing.read_text())
    assert timed["complete"] is False and timed["unfinished"] == ["long"] and set(timed["stages"]) == {"first"}
    assert not (tmp_path / "long.txt").exists()
    assert "[first] Running stage 'first'" in log.read_text()  # the stopped run's log is kept


def test_bad_arguments_are_one_line_and_exit_2(tmp_path, capsys):
    (tmp_path / "dvc.yaml").write_text("stages: {}\n")
    assert main([str(tmp_path / "dvc.yaml"), "--jobs", "0"]) == 2
    assert main([str(tmp_path / "missing" / "dvc.yaml")]) == 2
    assert main([str(tmp_path / "dvc.yaml")]) == 2  # no DVC repository around it
    err = capsys.readouterr().err.splitlines()
    assert err[0].startswith("error: --jobs 0") and err[1].startswith("error: ") and "dvc.yaml" in err[1]
    assert err[2] == f"error: {tmp_path / 'dvc.yaml'}: not in a DVC repository (dvc init)"


def test_the_gpu_pipelines_graph_is_read_with_every_matrix_stage_and_its_upstream():
    """The real gpu/dvc.yaml: every stage, `foreach` and `matrix` expanded, each depending on stages of the
    same pipeline only; a pretrained training waits for its network's pretraining, evaluate for every
    post-processing."""
    from helpers import ROOT
    from parallel_repro import stage_graph

    order, upstream = stage_graph(ROOT, "gpu/dvc.yaml")
    assert len(order) == len(set(order)) == len(upstream) and order[:3] == ["synthesize", "label", "split"]
    assert set().union(*upstream.values()) <= set(order) and not upstream["synthesize"]
    trained = [s for s in order if s.startswith("train_pretrained@")]
    assert trained and all(f"pretrain@{s.split('@')[1].split('-')[0]}" in upstream[s] for s in trained)
    assert {s for s in order if s.startswith("postprocess@")} <= upstream["evaluate"]
