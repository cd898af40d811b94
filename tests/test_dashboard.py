"""The MLflow dashboard as a user opens it (issue 42): the experiment is a model-training one, each
training run is named with its seed, and the stages of one `dvc repro` are children of one parent
run. Real SQLite stores and a real DVC repo."""

from __future__ import annotations

import json
import sqlite3
import subprocess
import sys
from pathlib import Path

from helpers import git

# What a DVC stage runs here: the parent run its MLflow runs would get, into the stage's output.
STAGE = (
    "from omegaconf import OmegaConf; from offroad_path.utils.tracking import pipeline_parent, dvc_repro_process; import json, sys;"
    "cfg = OmegaConf.create({{'mlflow': {{'enabled': True, 'experiment': 'offroad-path', 'tracking_uri': 'sqlite:///{db}'}}}});"
    "json.dump({{'parent': pipeline_parent(cfg), 'repro': dvc_repro_process()}}, open(sys.argv[1], 'w'))"
)


def test_the_stages_of_one_dvc_repro_share_one_parent_run(tmp_path):
    repo, db = tmp_path / "repo", tmp_path / "mlflow.db"
    repo.mkdir()
    git(repo, "init", "-q")
    subprocess.run([sys.executable, "-m", "dvc", "init", "-q"], cwd=repo, check=True)
    command = f'{sys.executable} -c "{STAGE.format(db=db)}"'
    stages = {name: {"cmd": f"{command} {name}.json", "outs": [f"{name}.json"]} for name in ("first", "second")}
    (repo / "dvc.yaml").write_text(json.dumps({"stages": stages}))
    subprocess.run([sys.executable, "-m", "dvc", "repro", "-q"], cwd=repo, check=True, capture_output=True)
    first, second = (json.loads((repo / f"{name}.json").read_text()) for name in ("first", "second"))
    assert first["parent"] and first == second  # one repro: one parent, found by the second stage
    with sqlite3.connect(db) as store:
        (name,) = store.execute("select name from runs where run_uuid = ?", (first["parent"],)).fetchone()
        (repro,) = store.execute("select value from tags where run_uuid = ? and key = 'dvc_repro'", (first["parent"],)).fetchone()
    assert name.startswith("dvc repro ") and repro == first["repro"]
    subprocess.run([sys.executable, "-m", "dvc", "repro", "-q", "-f"], cwd=repo, check=True, capture_output=True)
    assert json.loads((repo / "first.json").read_text())["parent"] != first["parent"]  # the next repro: a parent of its own


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
