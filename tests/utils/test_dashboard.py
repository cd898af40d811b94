"""The MLflow dashboard as a user opens it: the experiment is a model-training one, each
training run is named with its seed, and the stages of one `dvc repro` are children of one parent
run. Real SQLite stores and a real DVC repo."""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import signal
import socket
import sqlite3
import subprocess
import sys
import time
import urllib.parse
import urllib.request
from collections.abc import Callable, Iterator
from pathlib import Path

import mlflow
import mlflow.models
import pytest
from helpers import git

# What a DVC stage runs here: the parent run its MLflow runs would get, a second of work, the end the
# stage runner gives the parent (stage.run_stage), and the time it ended, into the stage's output.
STAGE = (
    "from omegaconf import OmegaConf; from offroad_path.utils.tracking import pipeline_parent, dvc_repro_process, end_pipeline_parent;"
    "import json, sys, time;"
    "cfg = OmegaConf.create({{'mlflow': {{'enabled': True, 'experiment': 'offroad-path', 'tracking_uri': 'sqlite:///{db}'}}}});"
    "parent = pipeline_parent(cfg); time.sleep(1); end_pipeline_parent(cfg, failed=False);"
    "json.dump({{'parent': parent, 'repro': dvc_repro_process(), 'ended_ms': time.time() * 1000}}, open(sys.argv[1], 'w'))"
)


def dvc_pipeline(tmp_path: Path, stages: dict) -> Path:
    """A git + DVC repository under tmp_path whose dvc.yaml holds `stages`."""
    repo = tmp_path / "repo"
    repo.mkdir()
    git(repo, "init", "-q")
    subprocess.run([sys.executable, "-m", "dvc", "init", "-q"], cwd=repo, check=True)
    (repo / "dvc.yaml").write_text(json.dumps({"stages": stages}))
    return repo


@pytest.mark.slow(seconds=18)
def test_the_stages_of_one_dvc_repro_share_one_parent_run(tmp_path):
    db = tmp_path / "mlflow.db"
    command = f'{sys.executable} -c "{STAGE.format(db=db)}"'
    repo = dvc_pipeline(tmp_path, {name: {"cmd": f"{command} {name}.json", "outs": [f"{name}.json"]} for name in ("first", "second")})
    subprocess.run([sys.executable, "-m", "dvc", "repro", "-q"], cwd=repo, check=True, capture_output=True)
    first, second = (json.loads((repo / f"{name}.json").read_text()) for name in ("first", "second"))
    assert first["parent"] and (first["parent"], first["repro"]) == (second["parent"], second["repro"])  # found by the second stage
    with sqlite3.connect(db) as store:
        name, status, start, end = store.execute(
            "select name, status, start_time, end_time from runs where run_uuid = ?", (first["parent"],)
        ).fetchone()
        (repro,) = store.execute("select value from tags where run_uuid = ? and key = 'dvc_repro'", (first["parent"],)).fetchone()
    assert name.startswith("dvc repro ") and repro == first["repro"] and status == "FINISHED"
    # the parent spans the repro: from the first stage's start to the last stage's end (2 s of work)
    assert first["ended_ms"] < end <= second["ended_ms"] and end - start >= 2000
    subprocess.run([sys.executable, "-m", "dvc", "repro", "-q", "-f"], cwd=repo, check=True, capture_output=True)
    assert json.loads((repo / "first.json").read_text())["parent"] != first["parent"]  # the next repro: a parent of its own


@pytest.mark.slow(seconds=30)
def test_a_stage_refused_before_any_work_ends_the_repros_parent_failed(tmp_path):
    """Once the refusal came before the code that ends the parent: the repro failed, its parent FINISHED."""
    db = tmp_path / "mlflow.db"
    refused = f"{sys.executable} -m offroad_path.split split.block_m=-4 mlflow.tracking_uri=sqlite:///{db}"
    repo = dvc_pipeline(tmp_path, {"first": {"cmd": f'{sys.executable} -c "{STAGE.format(db=db)}" first.json', "outs": ["first.json"]},
                                   "second": {"cmd": refused, "deps": ["first.json"], "outs": ["second"]}})  # fmt: skip
    repro = subprocess.run([sys.executable, "-m", "dvc", "repro", "-q"], cwd=repo, capture_output=True, text=True)
    assert repro.returncode != 0 and "split.block_m=-4" in repro.stdout + repro.stderr
    parent = json.loads((repo / "first.json").read_text())["parent"]
    with sqlite3.connect(db) as store:
        (status,) = store.execute("select status from runs where run_uuid = ?", (parent,)).fetchone()
    assert status == "FAILED"


def test_outside_dvc_there_is_no_parent(tmp_path):
    from omegaconf import OmegaConf

    from offroad_path.utils.tracking import dvc_repro_process, pipeline_parent

    cfg = OmegaConf.create({"mlflow": {"enabled": True, "experiment": "x", "tracking_uri": f"sqlite:///{tmp_path / 'm.db'}"}})
    assert dvc_repro_process() is None and pipeline_parent(cfg) is None
    assert not (tmp_path / "m.db").exists()


def test_training_runs_are_named_by_seed_in_a_model_training_experiment(trained):
    _, run_id, db = trained
    with sqlite3.connect(db) as store:
        (name,) = store.execute("select name from runs where run_uuid = ?", (run_id,)).fetchone()
        seed = store.execute("select value from tags where run_uuid = ? and key = 'seed'", (run_id,)).fetchone()
        kind = store.execute("select value from experiment_tags where key = 'mlflow.experimentKind'").fetchall()
    assert name == "train unet-none seed0" and seed == ("0",)
    assert kind == [("custom_model_development",)]  # MLflow 3 opens it on runs and models, not on GenAI traces


def test_an_existing_experiment_without_a_kind_gets_one(tmp_path):
    from mlflow.tracking import MlflowClient
    from omegaconf import OmegaConf

    from offroad_path.utils.tracking import experiment_id

    uri = f"sqlite:///{tmp_path / 'm.db'}"
    made = MlflowClient(uri).create_experiment("old", artifact_location=str(Path(tmp_path / "a")))  # as an earlier version made it
    assert experiment_id(OmegaConf.create({"experiment": "old", "tracking_uri": uri})) == made
    assert MlflowClient(uri).get_experiment(made).tags["mlflow.experimentKind"] == "custom_model_development"


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@contextlib.contextmanager
def mlflow_server(db: Path) -> Iterator[Callable[..., dict]]:
    """A real `mlflow server` on the store `db`; yields get(endpoint, **query) -> its JSON."""
    port = free_port()
    command = [sys.executable, "-m", "mlflow", "server", "--backend-store-uri", f"sqlite:///{db}",
               "--host", "127.0.0.1", "--port", str(port), "--workers", "1"]  # fmt: skip
    server = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)

    def get(endpoint: str, **query: str) -> dict:
        url = f"{get.url}/api/2.0/mlflow/{endpoint}?{urllib.parse.urlencode(query)}"
        with urllib.request.urlopen(url, timeout=30) as response:
            return json.load(response)

    get.url = f"http://127.0.0.1:{port}"  # type: ignore[attr-defined]

    try:
        deadline = time.monotonic() + 90
        while True:
            try:
                urllib.request.urlopen(f"http://127.0.0.1:{port}/health", timeout=2).close()
                break
            except OSError:
                assert server.poll() is None and time.monotonic() < deadline, "mlflow server did not start"
                time.sleep(0.5)
        yield get
    finally:
        os.killpg(server.pid, signal.SIGTERM)
        server.wait(30)


@pytest.mark.slow(seconds=30)
def test_the_dashboard_over_rest_shows_the_model_its_datasets_and_the_best_version(trained, tmp_path):
    _, run_id, db = trained
    store = tmp_path / "mlflow.db"
    shutil.copy(db, store)  # the server may migrate the store it opens: a copy (artifacts stay where they are)
    with mlflow_server(store) as get:
        experiment = get("experiments/get-by-name", experiment_name="offroad-path")["experiment"]
        assert {"key": "mlflow.experimentKind", "value": "custom_model_development"} in experiment["tags"]
        run = get("runs/get", run_id=run_id)["run"]
        assert run["info"]["run_name"] == "train unet-none seed0"
        datasets = {i["dataset"]["name"]: {t["value"] for t in i["tags"]} for i in run["inputs"]["dataset_inputs"]}
        assert datasets == {"train": {"training"}, "val": {"validation"}, "test": {"testing"}}
        model = get("registered-models/get", name="offroad-path-unet")["registered_model"]
        (best,) = [a for a in model["aliases"] if a["alias"] == "best"]
        version = get("model-versions/get", name="offroad-path-unet", version=best["version"])["model_version"]
        assert version["run_id"] == run_id
        mlflow.set_tracking_uri(get.url)
        signature = mlflow.models.get_model_info("models:/offroad-path-unet@best").signature
        (tensor,) = signature.inputs.inputs
        assert tuple(tensor.shape[1:]) == (3, 48, 64)  # (N, 3, H, W): the tiny preset's input
        assert tuple(signature.outputs.inputs[0].shape[1:]) == (2, 48, 64)  # path and not, per pixel


@pytest.mark.slow(seconds=6)
def test_synthesize_and_split_each_log_a_run(compose_config, labelled_drive, tmp_path):
    """Every stage shows in the dashboard: the two that logged nothing before, each with its settings and counts."""
    from offroad_path.split import split
    from offroad_path.synthesize import synthesize

    db = tmp_path / "mlflow.db"
    store = f"mlflow.tracking_uri=sqlite:///{db}"
    synthesize(compose_config("synthesize.sequences=1", "world.frames=3", "world.width=160", "world.height=96", "synthesize.workers=1",
                              "synthesize.test_worlds.min_blocks=0", f"synthesize.out_dir={tmp_path / 'synthetic'}", store))  # fmt: skip
    summary = split(compose_config(f"split.labels_dir={labelled_drive}", f"split.out_dir={tmp_path / 'split'}", store))
    with sqlite3.connect(db) as found:
        runs = dict(found.execute("select name, run_uuid from runs where status = 'FINISHED'").fetchall())
        metric = dict(found.execute("select key || ':' || r.name, value from metrics m join runs r on m.run_uuid = r.run_uuid").fetchall())
        params = {k for (k,) in found.execute("select key from params where run_uuid = ?", (runs["synthesize"],))}
    assert {"synthesize", "split"} <= set(runs)
    assert metric["sequences:synthesize"] == 1 and metric["frames:synthesize"] == 3
    assert metric["frames:split"] == summary["frames"] and metric["train:split"] == summary["samples"]["train"]
    assert {"sequences", "world.frames", "world.width"} <= params
