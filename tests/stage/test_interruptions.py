"""Stages killed at several points (SIGKILL and SIGTERM), then run again: the outputs are byte for byte
those of an uninterrupted run, no process of the killed run is left, no temporary folder either."""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import shutil
import signal
import subprocess
import sys
import time
import uuid
from collections.abc import Callable
from pathlib import Path

import pytest
from helpers import dvc_command, saved_epochs, tagged_processes, tiny_repo

from offroad_path.errors import EXIT_INTERRUPTED

ROOT = Path(__file__).resolve().parents[2]


def files(root: Path) -> dict[str, str]:
    """Hash of every file under root; paths of root inside a file (manifests) count as the same."""
    return {
        str(p.relative_to(root)): hashlib.sha256(p.read_bytes().replace(str(root).encode(), b"<out>")).hexdigest()
        for p in sorted(root.rglob("*"))
        if p.is_file()
    }


def start(args: list[str], tag: str, stderr: Path | None = None) -> subprocess.Popen:
    env = {**os.environ, "OFFROAD_TEST_TAG": tag}
    errors = subprocess.DEVNULL if stderr is None else stderr.open("w")
    return subprocess.Popen([sys.executable, "-m", *args], cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=errors)


def finish(args: list[str]) -> None:
    run = subprocess.run([sys.executable, "-m", *args], cwd=ROOT, capture_output=True, text=True)
    assert run.returncode == 0, run.stderr[-3000:]


def interrupt(
    args: list[str], how: signal.Signals, after_s: float, ready: Callable[[], bool] = lambda: True, stderr: Path | None = None
) -> int:
    """Start the command, wait until ready() and then after_s, send `how`, and check that the run and
    every process it started are gone (its error output into `stderr` when given); its exit status."""
    tag = uuid.uuid4().hex
    began = time.monotonic()
    process = start(args, tag, stderr)
    deadline = time.monotonic() + 300
    while not ready() and process.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)
    time.sleep(after_s)
    assert process.poll() is None, f"the run ended before the signal, {time.monotonic() - began:.1f} s in: the test missed its point"
    process.send_signal(how)
    status = process.wait(timeout=120)
    # A SIGKILL'd parent's workers get SIGKILL from the kernel; one still starting (importing) ends
    # as soon as it has (2 to 4 s with 6 busy processes on 2 cores; before that was mended, it went on
    # to do its first job, for up to a minute).
    deadline = time.monotonic() + 20
    while tagged_processes(tag) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not tagged_processes(tag), "a process of the stopped run is still alive"
    return status


@pytest.fixture(scope="module")
def two_drives(drive, tmp_path_factory) -> Path:
    recordings = tmp_path_factory.mktemp("two") / "recordings"
    shutil.copytree(drive / "drive", recordings / "a")
    shutil.copytree(drive / "drive", recordings / "b")
    return recordings


@pytest.mark.slow(seconds=35)
def test_label_killed_anywhere_then_rerun_gives_the_uninterrupted_labels(two_drives, tmp_path):
    def args(out: Path) -> list[str]:
        return ["offroad_path.label", f"label.in_dir={two_drives}", f"label.out_dir={out / 'labels'}",
                f"label.metrics_path={out / 'm.json'}", "label.workers=2", "mlflow.enabled=false"]  # fmt: skip

    reference = tmp_path / "reference"
    finish(args(reference))
    expected = files(reference)
    labels = len(list((reference / "labels").glob("*/label/*.png")))
    assert labels > 10

    def written(out: Path, count: int) -> Callable[[], bool]:
        """Ready once the run's temporary folder exists and holds `count` labels: a point in the
        run's work, whatever the machine's load (a signal timed from an earlier run missed under load)."""

        def ready() -> bool:
            folders = list(out.glob(".labels.tmp-*"))
            return bool(folders) and sum(len(list(f.glob("*/label/*.png"))) for f in folders) >= count

        return ready

    # Mid-way through the labels (a worker killed while it starts: the test of map_processes below).
    # SIGINT is Ctrl-C: one line, no traceback, exit 130.
    points = [(signal.SIGKILL, 0.4), (signal.SIGTERM, 0.2), (signal.SIGINT, 0.3)]
    for i, (how, share) in enumerate(points):
        out = tmp_path / f"run{i}"
        status = interrupt(args(out), how, 0.0, ready=written(out, round(share * labels)), stderr=tmp_path / f"stderr{i}")
        if how != signal.SIGKILL:  # a stopped stage cleans up after itself
            assert not list(out.glob(".labels*"))
        if how == signal.SIGINT and status == 0:  # the labels take a second or two: Ctrl-C after the last is a finished run
            assert files(out) == expected
        elif how == signal.SIGINT:
            assert status == EXIT_INTERRUPTED
            assert (tmp_path / f"stderr{i}").read_text().strip().splitlines()[-1:] == ["interrupted: unfinished outputs removed"]
        finish(args(out))
        assert files(out) == expected
        assert not list(out.glob(".labels*"))  # a killed run's temporary folder is gone after the next run


def workers_of(pid: int) -> list[int]:
    """The worker processes a stage started (not multiprocessing's resource tracker)."""
    found = []
    for child in Path(f"/proc/{pid}/task/{pid}/children").read_text().split():
        if b"spawn_main" in Path(f"/proc/{child}/cmdline").read_bytes():
            found.append(int(child))
    return found


def label_args(recordings: Path, out: Path) -> list[str]:
    return ["offroad_path.label", f"label.in_dir={recordings}", f"label.out_dir={out / 'labels'}", f"label.metrics_path={out / 'm.json'}",
            "label.workers=2", "mlflow.enabled=false"]  # fmt: skip


ORPHAN = """
import os, signal, sys, threading, time
from pathlib import Path
from offroad_path.utils.parallel import map_processes

if __name__ == "__mp_main__":  # a worker that starts slowly: its parent is dead before it is ready
    Path(sys.argv[1], f"started{os.getpid()}").touch()
    time.sleep(3)


def job(i):
    Path(sys.argv[1], f"done{i}").touch()


def kill_once_both_started():
    while len(list(Path(sys.argv[1]).glob("started*"))) < 2:
        time.sleep(0.01)
    os.kill(os.getpid(), signal.SIGKILL)


if __name__ == "__main__":
    threading.Thread(target=kill_once_both_started, daemon=True).start()
    map_processes(job, [0, 1], workers=2)
"""


@pytest.mark.slow(seconds=4)
def test_a_worker_whose_parent_was_killed_while_it_started_does_not_do_its_job(tmp_path):
    script = tmp_path / "orphan.py"
    script.write_text(ORPHAN)
    tag = uuid.uuid4().hex
    run = subprocess.run([sys.executable, str(script), str(tmp_path)], env={**os.environ, "OFFROAD_TEST_TAG": tag})
    assert run.returncode == -signal.SIGKILL
    assert len(list(tmp_path.glob("started*"))) == 2  # killed while both workers were starting
    deadline = time.monotonic() + 30
    while tagged_processes(tag) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not tagged_processes(tag)
    assert not list(tmp_path.glob("done*"))  # its first job was already in its pipe


@pytest.mark.slow(seconds=20)
def test_a_label_worker_killed_from_outside_ends_the_stage_with_its_sequence_named(two_drives, tmp_path):
    tag = uuid.uuid4().hex
    env = {**os.environ, "OFFROAD_TEST_TAG": tag}
    process = subprocess.Popen([sys.executable, "-m", *label_args(two_drives, tmp_path)], cwd=ROOT, env=env, stderr=subprocess.PIPE,
                               stdout=subprocess.DEVNULL, text=True)  # fmt: skip
    deadline = time.monotonic() + 120
    while not list(tmp_path.glob(".labels.tmp-*/*/label/*.png")) and time.monotonic() < deadline:  # the workers are labelling
        time.sleep(0.05)
    workers = workers_of(process.pid)
    assert len(workers) == 2, workers
    os.kill(workers[0], signal.SIGKILL)  # as the out-of-memory killer does
    killed = time.monotonic()
    _, err = process.communicate(timeout=30)
    assert time.monotonic() - killed < 30 and process.returncode == 2, err[-2000:]
    lines = [line for line in err.splitlines() if line.startswith("error: ")]
    assert len(lines) == 1 and "SIGKILL" in lines[0] and any(str(two_drives / name) in lines[0] for name in ("a", "b")), lines
    deadline = time.monotonic() + 10
    while tagged_processes(tag) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not tagged_processes(tag)
    assert sorted(p.name for p in tmp_path.iterdir()) == []  # no labels, no metrics, no temporary folder, no lock


@pytest.mark.slow(seconds=20)
def test_a_stage_stopped_by_sigterm_ends_its_mlflow_run_killed(two_drives, tmp_path):
    """Once a stopped stage's run stayed RUNNING in MLflow for good: its handler exits without MLflow."""
    import sqlite3

    db = tmp_path / "mlflow.db"
    args = [arg for arg in label_args(two_drives, tmp_path) if not arg.startswith("mlflow.")]
    args += ["mlflow.enabled=true", f"mlflow.tracking_uri=sqlite:///{db}"]

    def running() -> bool:
        if not db.exists():
            return False
        with contextlib.suppress(sqlite3.OperationalError), sqlite3.connect(db) as store:
            return bool(store.execute("select 1 from runs where status = 'RUNNING' and name = 'label'").fetchall())
        return False

    interrupt(args, signal.SIGTERM, 0.5, ready=running)  # past the run's start-up logging: a signal inside it raced
    with sqlite3.connect(db) as store:
        assert store.execute("select status from runs where name = 'label'").fetchall() == [("KILLED",)]


@pytest.mark.slow(seconds=40)
def test_two_label_runs_into_one_folder_one_refused_one_complete(two_drives, tmp_path):
    first = subprocess.Popen([sys.executable, "-m", *label_args(two_drives, tmp_path)], cwd=ROOT, stderr=subprocess.PIPE,
                             stdout=subprocess.DEVNULL, text=True)  # fmt: skip
    deadline = time.monotonic() + 120
    while not (tmp_path / ".labels.lock").exists() and first.poll() is None and time.monotonic() < deadline:
        time.sleep(0.02)
    second = subprocess.run([sys.executable, "-m", *label_args(two_drives, tmp_path)], cwd=ROOT, capture_output=True, text=True)
    _, err = first.communicate(timeout=300)
    assert first.returncode == 0, err[-2000:]
    assert second.returncode == 2
    lines = [line for line in second.stderr.splitlines() if line.startswith("error: ")]
    assert len(lines) == 1 and f"process {first.pid}" in lines[0] and "label.out_dir" in lines[0], lines
    summary = json.loads((tmp_path / "labels" / "summary.json").read_text())
    assert json.loads((tmp_path / "m.json").read_text()) == summary["metrics"]  # the metrics are those of the labels beside them
    assert summary["metrics"]["labels"] == len(list((tmp_path / "labels").glob("*/label/*.png")))
    assert not list(tmp_path.glob(".labels.*"))


@pytest.mark.slow(seconds=55)
def test_training_killed_anywhere_then_resumed_ends_as_an_uninterrupted_run(split_dir, tiny_overrides, tmp_path):
    def args(out: Path) -> list[str]:
        return ["offroad_path.train", *tiny_overrides, f"data.split_dir={split_dir}", f"train.out_dir={out / 'run'}", "model=unet",
                "trainer.max_epochs=6", "callbacks.early_stopping.patience=10", "mlflow.enabled=false"]  # fmt: skip

    reference = tmp_path / "reference"
    finish(args(reference))
    expected = files(reference / "run")
    assert json.loads((reference / "run" / "metrics.json").read_text())["global_step"] > 0
    # (signal, epochs saved before it, then a delay): before any checkpoint, and mid-way through a
    # later epoch (tests/training/test_ddp.py kills a run after its first epoch is saved)
    points = [(signal.SIGKILL, 0, 2.0), (signal.SIGTERM, 3, 0.0)]
    for i, (how, epochs, delay) in enumerate(points):
        out = tmp_path / f"run{i}"
        interrupt(args(out), how, delay, ready=lambda out=out, epochs=epochs: saved_epochs(out) >= epochs)
        assert not (out / "run").exists()  # nothing is published before the run ends
        finish(args(out))
        assert files(out / "run") == expected


@pytest.mark.slow(seconds=40)
def test_a_stage_ends_with_the_dvc_repro_stopped_by_sigterm(tmp_path):
    """DVC, stopped by SIGTERM, does not pass the signal on to its stage's command: the stage ends
    anyway (it watches DVC), leaves no process, no output and no lock behind."""
    repo = tiny_repo(tmp_path / "repo")
    tiny = repo / "conf" / "experiment" / "tiny.yaml"
    tiny.write_text(tiny.read_text().replace("frames: 12", "frames: 400"))  # a synthesis long enough to be stopped midway
    tag = uuid.uuid4().hex
    command = dvc_command(repo, "repro", "-s", "synthesize")
    dvc = subprocess.Popen(**command | {"env": {**command["env"], "OFFROAD_TEST_TAG": tag}},
                           stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)  # fmt: skip
    deadline = time.monotonic() + 120

    def stage_started() -> bool:
        return any(b"offroad_path.synthesize" in Path(f"/proc/{pid}/cmdline").read_bytes() for pid in tagged_processes(tag))

    while not stage_started() and dvc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.1)
    time.sleep(3)  # past the stage's start-up, into the synthesis
    assert dvc.poll() is None and stage_started(), "the stage ended before the signal: the test missed its point"
    dvc.send_signal(signal.SIGTERM)
    dvc.wait(timeout=60)
    deadline = time.monotonic() + 20
    while tagged_processes(tag) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not tagged_processes(tag), "the stage outlived the dvc repro that ran it"
    assert not (repo / "data" / "synthetic").exists()
    assert not list(repo.rglob(".*.lock"))
