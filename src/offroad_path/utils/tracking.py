"""MLflow for every stage: the embedded SQLite store unless told otherwise."""

from __future__ import annotations

import contextlib
import os
import signal
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, OmegaConf

from offroad_path.utils.lifetime import dvc_ancestor, process_started

# The experiment's kind: model training (runs, models, metrics), not GenAI development (traces).
# MLflow 3.17's UI opens experiments by its sidebar switch instead (?workflowType=machine_learning,
# README "The dashboard"); the tag is what MLflow's APIs and UIs without that switch read.
EXPERIMENT_KIND, MODEL_TRAINING = "mlflow.experimentKind", "custom_model_development"
# The runs this process has open (run id -> tracking URI): what a stop (SIGTERM) ends KILLED.
OPEN_RUNS: dict[str, str] = {}


def tracking_uri(cfg: DictConfig) -> str:
    """config's tracking_uri, else $MLFLOW_TRACKING_URI, else sqlite:///mlflow.db in the working directory."""
    return cfg.tracking_uri or os.environ.get("MLFLOW_TRACKING_URI") or f"sqlite:///{Path.cwd() / 'mlflow.db'}"


def artifact_location(cfg: DictConfig) -> str | None:
    """Artifacts of a SQLite store live beside the database file, in mlartifacts/ (not ./mlruns)."""
    uri = tracking_uri(cfg)
    if uri.startswith("sqlite:///"):
        return str(Path(uri.removeprefix("sqlite:///")).resolve().parent / "mlartifacts")
    return None


def experiment_id(cfg: DictConfig) -> str:
    """The configured experiment's id, creating it (with its artifact location) if needed."""
    from mlflow.tracking import MlflowClient

    client = MlflowClient(tracking_uri(cfg))
    experiment = client.get_experiment_by_name(cfg.experiment)
    if experiment is None:
        created = client.create_experiment(cfg.experiment, artifact_location=artifact_location(cfg))
        experiment = client.get_experiment(created)
    if experiment.tags.get(EXPERIMENT_KIND) is None:  # MLflow 3 opens an experiment without it on its GenAI traces page
        client.set_experiment_tag(experiment.experiment_id, EXPERIMENT_KIND, MODEL_TRAINING)
    return experiment.experiment_id


def flatten(tree: Any, prefix: str = "") -> dict[str, Any]:
    if isinstance(tree, dict):
        out: dict[str, Any] = {}
        for key, value in tree.items():
            out.update(flatten(value, f"{prefix}{key}."))
        return out
    return {prefix[:-1]: tree}


@contextlib.contextmanager
def stop_deferred() -> Iterator[None]:
    """A SIGTERM that arrives inside the block is handled when it ends (by the handler installed
    before it), not in the middle: MLflow's run is in the store before start_run returns, and a stop
    caught in between left it RUNNING for good. Outside the main thread (where no handler can be
    set), the block runs as it is."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    handler = signal.getsignal(signal.SIGTERM)
    caught: list[int] = []
    signal.signal(signal.SIGTERM, lambda signum, frame: caught.append(signum))
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, handler)
        if caught and callable(handler):
            handler(caught[0], None)
        elif caught and handler == signal.SIG_DFL:
            os.kill(os.getpid(), signal.SIGTERM)


@contextlib.contextmanager
def stage_run(cfg: DictConfig, stage: str) -> Iterator[Any]:
    """An MLflow run for one stage with its resolved config as parameters; None when disabled."""
    if not cfg.mlflow.enabled:
        yield None
        return
    import mlflow

    mlflow.set_tracking_uri(tracking_uri(cfg.mlflow))
    experiment = experiment_id(cfg.mlflow)
    end_abandoned_runs(tracking_uri(cfg.mlflow), experiment)
    parent = pipeline_parent(cfg)
    with stop_deferred():  # a stop that lands while MLflow makes the run must find it among the open runs
        tags = {PROCESS_TAG: process_key(os.getpid())} | ({"mlflow.parentRunId": parent} if parent else {})  # a kill right after finds it
        started = mlflow.start_run(experiment_id=experiment, run_name=stage, tags=tags)
        OPEN_RUNS[started.info.run_id] = tracking_uri(cfg.mlflow)
    with started as run:
        try:
            mlflow.set_tags({"stage": stage, "experiment_name": cfg.experiment_name})
            mlflow.log_params(flatten(OmegaConf.to_container(cfg[stage], resolve=True)))
            yield run
        finally:
            OPEN_RUNS.pop(run.info.run_id, None)


def end_open_runs_killed(timeout_s: float = 5.0) -> None:
    """On a stop: every run this process has open ends KILLED, and so does the `dvc repro` parent
    of each (the repro stopped with it). In a thread given timeout_s, from the signal handler: a store
    the stop caught in the middle of a write must not keep the stopped process alive."""
    if not OPEN_RUNS:
        return

    def end() -> None:
        from mlflow.tracking import MlflowClient

        for run_id, uri in list(OPEN_RUNS.items()):
            end_killed(MlflowClient(uri), run_id)

    stopping = threading.Thread(target=end, daemon=True)
    stopping.start()
    stopping.join(timeout_s)


def end_killed(client: Any, run_id: str) -> None:
    """A stage's run ends KILLED, and so does the `dvc repro` parent it belongs to (the repro stopped with it)."""
    now = int(time.time() * 1000)
    client.set_terminated(run_id, "KILLED", end_time=now)
    parent = client.get_run(run_id).data.tags.get("mlflow.parentRunId")
    if parent and client.get_run(parent).data.tags.get("stage") == "dvc repro":
        client.set_terminated(parent, "KILLED", end_time=now)


def multirun_parent(cfg: DictConfig) -> str | None:
    """In a Hydra multirun, the id of the sweep's parent run (made by the sweep's first job), so
    that every job shows as its child in the MLflow UI; None outside a multirun."""
    from hydra.core.hydra_config import HydraConfig
    from hydra.types import RunMode

    if not HydraConfig.initialized() or HydraConfig.get().mode != RunMode.MULTIRUN:
        return None
    from mlflow.tracking import MlflowClient

    sweep = str(HydraConfig.get().sweep.dir)
    client = MlflowClient(tracking_uri(cfg.mlflow))
    experiment = experiment_id(cfg.mlflow)
    found = client.search_runs([experiment], filter_string=f"tags.sweep_dir = '{sweep}'", max_results=1)
    if found:
        return found[0].info.run_id
    parent = client.create_run(experiment, run_name=f"sweep {Path(sweep).name}", tags={"sweep_dir": sweep, "stage": "sweep"})
    client.set_terminated(parent.info.run_id)
    return parent.info.run_id


PROCESS_TAG = "process"  # a stage run's `<host>-<pid>-<start>`: a run left RUNNING by a process now gone was killed


def process_key(pid: int) -> str | None:
    """`<host>-<pid>-<start>` of a live process (the start time tells it from a later one of the same pid)."""
    found = process_started(pid)
    return None if found is None else _key(pid, found[1])


def _key(pid: int, start: int) -> str:
    return f"{os.uname().nodename}-{pid}-{start}"


def _gone(key: str | None) -> bool:
    """Whether the process a key names ran on this host and no longer runs."""
    parts = (key or "").rsplit("-", 2)
    if len(parts) != 3 or parts[0] != os.uname().nodename or not parts[1].isdigit():
        return False
    return process_key(int(parts[1])) != key


def end_abandoned_runs(uri: str, experiment: str) -> None:
    """A process killed outright (SIGKILL, the machine's OOM killer) cannot end its run: its stage's run
    stays RUNNING, and the `dvc repro` parent its last finished stage ended FINISHED. The next stage
    that logs ends each such run of this host KILLED, and its repro parent too."""
    from mlflow.tracking import MlflowClient

    client = MlflowClient(uri)
    for run in client.search_runs([experiment], filter_string="attributes.status = 'RUNNING'", max_results=1000):
        if _gone(run.data.tags.get(PROCESS_TAG)):
            end_killed(client, run.info.run_id)


def dvc_repro_process() -> str | None:
    """`<host>-<pid>-<start>` of the `dvc repro` (or `dvc exp run`) this process runs under
    (utils.lifetime finds it); None outside DVC. Every stage of one repro gets the same."""
    found = dvc_ancestor()
    return None if found is None else _key(*found)


def pipeline_parent(cfg: DictConfig) -> str | None:
    """Under `dvc repro`: the id of one parent run for the whole repro (made by its first stage that
    logs, starting then), so that the dashboard shows each repro's stages together; None outside DVC.
    Every stage that logs ends it again as it ends (end_pipeline_parent): it ends with the repro."""
    return _pipeline_parent(cfg, create=True)


def _pipeline_parent(cfg: DictConfig, create: bool) -> str | None:
    repro = dvc_repro_process()
    if repro is None or not cfg.mlflow.enabled:
        return None
    from mlflow.tracking import MlflowClient

    client = MlflowClient(tracking_uri(cfg.mlflow))
    experiment = experiment_id(cfg.mlflow)
    found = client.search_runs([experiment], filter_string=f"tags.dvc_repro = '{repro}'", max_results=1)
    if found:
        return found[0].info.run_id
    if not create:
        return None
    parent = client.create_run(
        experiment, run_name=f"dvc repro {time.strftime('%Y-%m-%d %H:%M')}", tags={"dvc_repro": repro, "stage": "dvc repro"}
    )
    return parent.info.run_id


def end_pipeline_parent(cfg: DictConfig, failed: bool) -> None:
    """The repro's parent run (when a stage of it has logged) ends now: the last stage's end is the
    repro's. FAILED when this stage failed, which stops the repro."""
    parent = _pipeline_parent(cfg, create=False)
    if parent is None:
        return
    from mlflow.tracking import MlflowClient

    MlflowClient(tracking_uri(cfg.mlflow)).set_terminated(parent, "FAILED" if failed else "FINISHED", end_time=int(time.time() * 1000))
