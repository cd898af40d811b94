"""A stop that lands while MLflow makes a stage's run is handled once the run is registered as open
(utils.tracking.stop_deferred): under load, a SIGTERM between the store's write and start_run's
return once left the run RUNNING for good."""

from __future__ import annotations

import os
import signal

import pytest

from offroad_path.utils.tracking import stop_deferred


@pytest.fixture
def recorded_sigterm():
    handled: list[int] = []
    previous = signal.signal(signal.SIGTERM, lambda signum, frame: handled.append(signum))
    yield handled
    signal.signal(signal.SIGTERM, previous)


def test_a_sigterm_inside_the_block_is_handled_when_it_ends(recorded_sigterm):
    with stop_deferred():
        os.kill(os.getpid(), signal.SIGTERM)
        for _ in range(1000):  # the interpreter runs a pending handler at the next instructions
            pass
        assert recorded_sigterm == []
    assert recorded_sigterm == [signal.SIGTERM]


def test_a_sigterm_after_the_block_is_handled_at_once_and_none_is_made_up(recorded_sigterm):
    with stop_deferred():
        pass
    assert recorded_sigterm == []
    os.kill(os.getpid(), signal.SIGTERM)
    for _ in range(1000):
        pass
    assert recorded_sigterm == [signal.SIGTERM]


def test_an_error_inside_the_block_still_hands_on_the_stop(recorded_sigterm):
    with pytest.raises(RuntimeError), stop_deferred():
        os.kill(os.getpid(), signal.SIGTERM)
        raise RuntimeError("the store failed")
    assert recorded_sigterm == [signal.SIGTERM]


def test_a_stop_while_mlflow_makes_the_stages_run_ends_that_run_killed(tmp_path, monkeypatch):
    """The SIGTERM lands just after the store wrote the run, before start_run returned (as it did
    under load in the suite): the stop's handler must find the run among the open ones."""
    import sqlite3

    from mlflow.tracking import MlflowClient
    from omegaconf import OmegaConf

    from offroad_path.utils.tracking import end_open_runs_killed, stage_run

    db = tmp_path / "mlflow.db"
    cfg = OmegaConf.create({"experiment_name": "x", "label": {"stride_m": 1.0},
                            "mlflow": {"enabled": True, "experiment": "x", "tracking_uri": f"sqlite:///{db}"}})  # fmt: skip
    made = MlflowClient.create_run

    def made_then_stopped(self, *args, **kwargs):
        run = made(self, *args, **kwargs)
        os.kill(os.getpid(), signal.SIGTERM)
        for _ in range(1000):  # a handler not held back runs here, inside start_run
            pass
        return run

    seen_by_the_stop: list[list[tuple[str]]] = []

    def stop(signum, frame):  # what the stage's handler does with MLflow, then the status it left
        end_open_runs_killed()
        with sqlite3.connect(db) as store:
            seen_by_the_stop.append(store.execute("select status from runs where name = 'label'").fetchall())

    previous = signal.signal(signal.SIGTERM, stop)
    monkeypatch.setattr(MlflowClient, "create_run", made_then_stopped)
    try:
        with stage_run(cfg, "label"):
            pass
    finally:
        signal.signal(signal.SIGTERM, previous)
    assert seen_by_the_stop == [[("KILLED",)]]


def test_a_run_whose_process_was_killed_outright_ends_killed_with_its_repro_parent(tmp_path):
    """SIGKILL leaves no handler to run: the killed stage's run stays RUNNING and the repro's parent as
    its last finished stage ended it. The next stage that logs ends both KILLED; a live process's run
    and another host's stay as they are."""
    import subprocess
    import sys

    from mlflow.tracking import MlflowClient
    from omegaconf import OmegaConf

    from offroad_path.utils.tracking import PROCESS_TAG, process_key, stage_run

    uri = f"sqlite:///{tmp_path / 'mlflow.db'}"
    cfg = OmegaConf.create(
        {"experiment_name": "x", "label": {"stride_m": 1.0}, "mlflow": {"enabled": True, "experiment": "x", "tracking_uri": uri}}
    )
    client = MlflowClient(uri)
    experiment = client.create_experiment("x")
    killed = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    gone = process_key(killed.pid)
    killed.kill()
    killed.wait()
    parent = client.create_run(experiment, tags={"stage": "dvc repro", "dvc_repro": "host-1-1"}).info.run_id
    client.set_terminated(parent, "FINISHED")
    stale = client.create_run(experiment, tags={"mlflow.parentRunId": parent, PROCESS_TAG: gone}).info.run_id
    alive = client.create_run(experiment, tags={PROCESS_TAG: process_key(os.getpid())}).info.run_id
    elsewhere = client.create_run(experiment, tags={PROCESS_TAG: "another-host-1-1"}).info.run_id
    with stage_run(cfg, "label"):
        pass
    status = {run: client.get_run(run).info.status for run in (stale, parent, alive, elsewhere)}
    assert status == {stale: "KILLED", parent: "KILLED", alive: "RUNNING", elsewhere: "RUNNING"}
