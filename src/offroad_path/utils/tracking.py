"""MLflow for every stage: the embedded SQLite store unless told otherwise."""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, OmegaConf


def tracking_uri(cfg: DictConfig) -> str:
    """config's tracking_uri, else $MLFLOW_TRACKING_URI, else sqlite:///mlflow.db in the working directory."""
    return cfg.tracking_uri or os.environ.get("MLFLOW_TRACKING_URI") or f"sqlite:///{Path.cwd() / 'mlflow.db'}"


def flatten(tree: Any, prefix: str = "") -> dict[str, Any]:
    if isinstance(tree, dict):
        out: dict[str, Any] = {}
        for key, value in tree.items():
            out.update(flatten(value, f"{prefix}{key}."))
        return out
    return {prefix[:-1]: tree}


@contextlib.contextmanager
def stage_run(cfg: DictConfig, stage: str) -> Iterator[Any]:
    """An MLflow run for one stage with its resolved config as parameters; None when disabled."""
    if not cfg.mlflow.enabled:
        yield None
        return
    import mlflow

    mlflow.set_tracking_uri(tracking_uri(cfg.mlflow))
    mlflow.set_experiment(cfg.mlflow.experiment)
    with mlflow.start_run(run_name=stage) as run:
        mlflow.set_tags({"stage": stage, "experiment_name": cfg.experiment_name})
        mlflow.log_params(flatten(OmegaConf.to_container(cfg[stage], resolve=True)))
        yield run
