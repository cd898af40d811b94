"""A training run's network in MLflow, as the dashboard shows it: the model logged with its signature
(MLflow's "Logged models"), the split manifests it learnt from as datasets, and a version under a
registered name per architecture whose alias `best` follows the best validation score.

    mlflow.pytorch.load_model("models:/offroad-path-unet@best")  # the best U-Net trained so far
"""

from __future__ import annotations

import logging
from pathlib import Path

import lightning as L
import numpy as np
import torch

log = logging.getLogger("offroad_path.training")
BEST = "best"  # the registered model's alias for its version with the best validation score


def registered_name(architecture: str) -> str:
    return f"offroad-path-{architecture}"


def _datasets(manifests: dict[str, Path]) -> list:
    """Each manifest as an MLflow dataset (its rows, and the file as the source)."""
    import mlflow.data
    import pandas as pd

    return [(context, mlflow.data.from_pandas(pd.read_csv(path), source=str(path.resolve()), name=path.stem))
            for context, path in manifests.items() if path.is_file()]  # fmt: skip


def _mark_best(client, name: str, monitor: str, mode: str) -> None:
    """Point alias BEST at the version whose run scored best on `monitor` (its `score` tag)."""
    scored = [(float(v.tags["score"]), int(v.version)) for v in client.search_model_versions(f"name = '{name}'") if "score" in v.tags]
    if not scored:
        return
    best = (max if mode == "max" else min)(scored)
    client.set_registered_model_alias(name, BEST, str(best[1]))
    client.set_registered_model_tag(name, "selected_by", f"{mode} {monitor}")


def publish(  # noqa: PLR0913
    run_id: str,
    tracking_uri: str,
    task: L.LightningModule,
    *,
    input_size: tuple[int, int],
    manifests: dict[str, Path],
    register_as: str | None,
    score: float | None,
) -> None:
    """Log task.model into the run `run_id` with its signature (input_size: the network's (height,
    width)) and `manifests` (by MLflow context) as its inputs; with register_as, an architecture,
    register it (a new version of registered_name(register_as)) and move BEST."""
    import mlflow
    import mlflow.pytorch
    from mlflow.models import infer_signature
    from mlflow.tracking import MlflowClient

    network = task.model.eval()
    architecture = register_as
    example = torch.zeros(1, 3, *input_size)  # (1, 3, H, W), an image as the network takes it
    with torch.no_grad():
        output = network(example)
    signature = infer_signature(example.numpy(), output.numpy())
    mlflow.set_tracking_uri(tracking_uri)
    with mlflow.start_run(run_id=run_id):
        for context, dataset in _datasets(manifests):
            mlflow.log_input(dataset, context=context)
        logged = mlflow.pytorch.log_model(
            network,
            name="model",
            signature=signature,
            input_example=np.zeros((1, 3, *input_size), np.float32),
            pip_requirements=[f"torch=={torch.__version__.split('+')[0]}"],  # given: inferring them imports the model in a subprocess
        )
    if architecture is None:
        return
    client = MlflowClient(tracking_uri)
    name = registered_name(architecture)
    if not client.search_registered_models(f"name = '{name}'"):
        client.create_registered_model(
            name, description=f"{architecture} networks trained by offroad-path; alias '{BEST}' is the best validation score"
        )
    version = client.create_model_version(name, logged.model_uri, run_id=run_id, tags={} if score is None else {"score": str(score)})
    _mark_best(client, name, task.monitor, task.mode)
    log.info("registered %s version %s", name, version.version)
