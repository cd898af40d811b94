"""One training loop for every stage that trains (pretrain, train, train_steering): Lightning trainer
with early stopping, resumable and exactly reproducible checkpoints, MLflow, test, published
weights; and for the path networks, their data, task, initialisation and the test-set confidence
maps that post-processing reads."""

from __future__ import annotations

import hashlib
import json
import logging
import shutil
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import lightning as L
import numpy as np
import torch
import torch.nn.functional as F
from hydra.utils import instantiate
from lightning.pytorch.callbacks import ModelCheckpoint
from lightning.pytorch.loggers import Logger, MLFlowLogger
from omegaconf import DictConfig, OmegaConf

from offroad_path.data.datamodule import OffroadDataModule
from offroad_path.data.dataset import transforms
from offroad_path.data.loading import load_sample
from offroad_path.data.manifest import prediction_name, write_predictions_manifest
from offroad_path.training.callbacks import LogSamples, SeedEachEpoch, StampConfig, StayStopped, configured_callbacks
from offroad_path.training.checkpoints import (
    CONFIG_HASH,
    AtomicCheckpointIO,
    CheckpointError,
    file_digest,
    load_checkpoint,
    load_weights,
    save_weights,
)
from offroad_path.training.pretrained import initialise
from offroad_path.training.published import publish
from offroad_path.training.task import BaseTask, SegmentationTask
from offroad_path.utils.atomic import MARKER, atomic_directory, owned
from offroad_path.utils.ranks import is_global_zero
from offroad_path.utils.tracking import OPEN_RUNS, experiment_id, flatten, multirun_parent, pipeline_parent, tracking_uri
from offroad_path.world.classes import CLASS_NAMES

log = logging.getLogger(__name__)


def training_logger(cfg: DictConfig, run_name: str, tags: dict, params: dict) -> Logger | None:
    """The run's Lightning logger from conf/logger (mlflow, csv or wandb), named `run_name`, tagged
    with `tags` and the experiment's name, with `params` logged. MLflow's run is a child of its
    sweep in a multirun, and there is none when mlflow.enabled is false; logger=null logs nothing."""
    if cfg.logger is None or not is_global_zero():  # Lightning logs from rank 0 only
        return None
    run_name = f"{run_name} seed{cfg.seed}"  # unique per training seed in the dashboard's run list
    tags = {**tags, "experiment_name": cfg.experiment_name, "seed": str(cfg.seed)}
    target = cfg.logger["_target_"]
    if target.endswith(".MLFlowLogger"):
        if not cfg.mlflow.enabled:
            return None
        if parent := multirun_parent(cfg) or pipeline_parent(cfg):
            tags["mlflow.parentRunId"] = parent
        # The tracking URI is always explicit: Lightning's logger would otherwise fall back to ./mlruns.
        experiment_id(cfg.mlflow)  # created with its artifact location, which the logger would not set
        logger = instantiate(cfg.logger, run_name=run_name, tracking_uri=tracking_uri(cfg.mlflow), tags=tags)
    elif target.endswith(".WandbLogger"):
        logger = instantiate(cfg.logger, name=run_name, tags=[f"{k}={v}" for k, v in tags.items()])
    else:  # a logger that writes folders (CSVLogger, TensorBoardLogger): one per stage and run
        logger = instantiate(cfg.logger, name=run_name.replace(" ", "/"))
    logger.log_hyperparams(flatten(params))
    if isinstance(logger, MLFlowLogger):
        OPEN_RUNS[logger.run_id] = tracking_uri(cfg.mlflow)  # ended KILLED on a stop; Lightning ends it otherwise
    return logger


# Settings that change how long a run goes on, not what it computes: a longer run resumes a shorter one.
LENGTH_SETTINGS = {"max_epochs", "fast_dev_run", "log_every_n_steps"}  # of conf/trainer (max_steps lives in train and pretrain)
# Settings of the data loader that change its speed, not the samples it gives.
LOADER_SETTINGS = {"num_workers", "pin_memory", "cache_mb"}


@dataclass(frozen=True, kw_only=True)
class RunSpec:
    """Where a training run writes and how long it goes on. What every training stage shares
    (conf/trainer, conf/callbacks, seed, resume) comes from the stage's config."""

    stage: str
    out_dir: Path
    out_key: str  # the config key of out_dir, for messages
    key: str  # run_identity(): a resume must match it
    max_epochs: int
    max_steps: int = -1  # -1: no cap
    validate: bool = True  # False (no validation set, the paper's protocol): no early stopping, the last weights are kept
    patience: int | None = None  # early stopping's patience instead of the one in conf/callbacks
    extra_callbacks: tuple[L.Callback, ...] = ()
    # What the run writes besides its weights and metrics: write_more(task, data, tmp) puts files in
    # the output's temporary folder and returns more metrics.
    write_more: Callable[[BaseTask, L.LightningDataModule, Path], dict] | None = None
    # For MLflow (training/published.py): the network's input (height, width), the manifests it
    # learnt from by context, and the architecture whose registered model gets a version (None: none).
    input_size: tuple[int, int] = (0, 0)
    manifests: dict[str, Path] = field(default_factory=dict)
    register_as: str | None = None


MANIFEST_CONTEXTS = (("training", "train"), ("validation", "val"), ("testing", "test"))  # MLflow's dataset contexts
NUM_CLASSES = {"path": 2, "semantic": len(CLASS_NAMES)}  # a segmentation target's classes: path and not, or the world's
PACKAGE = Path(__file__).resolve().parents[1]


def run_identity(cfg: DictConfig, stage: str, settings: dict, files: list[Path]) -> str:
    """The identity of a training run, as a key: the stage, the seed, `settings` (the stage's own
    that change what it computes), conf/trainer less its length settings, conf/callbacks, the bytes
    of `files` and of this package's code (so new data, a new pretraining or a code change never
    resumes an old run, even one that finished). Paths are taken as configured, never resolved."""
    trainer = {k: v for k, v in OmegaConf.to_container(cfg.trainer, resolve=True).items() if k not in LENGTH_SETTINGS}
    identity = {
        "stage": stage,
        "seed": cfg.seed,
        **settings,
        "trainer": trainer,
        "callbacks": OmegaConf.to_container(cfg.callbacks, resolve=True),
    }
    digest = hashlib.sha256(json.dumps(identity, sort_keys=True).encode())
    return file_digest(files + sorted(PACKAGE.rglob("*.py")), digest).hexdigest()[:16]


def resume_checkpoint(work: Path, key: str, resume: bool) -> str | None:
    """The work folder's last.ckpt to resume from, checked; None to start fresh (resume=false
    clears the folder first). A corrupt or foreign last.ckpt is a CheckpointError naming it."""
    last = work / "last.ckpt"
    if not resume:
        if owned(work) and is_global_zero():  # the other ranks of a DDP run start after rank 0 cleared it
            shutil.rmtree(work)
        return None
    if not last.is_file():
        return None
    try:
        saved = load_checkpoint(last)
    except CheckpointError as e:
        raise CheckpointError(f"{e}; delete it, or set resume=false to start this run afresh") from e
    if saved.get(CONFIG_HASH) != key:
        raise CheckpointError(
            f"{last}: belongs to another configuration (hash {saved.get(CONFIG_HASH)} is not {key}); "
            "set resume=false to start this run afresh"
        )
    return str(last)


def fit(
    cfg: DictConfig,
    task: BaseTask,
    data: L.LightningDataModule,
    spec: RunSpec,
    logger: Logger | None,
) -> dict:
    """Train `task` (early stopping on task.monitor), test its best weights, and write spec.out_dir
    atomically: checkpoints/best.ckpt (weights and hyper-parameters only), metrics.json, and
    whatever `spec.write_more` adds; then log them to MLflow. One job per function below.

    Lightning's full checkpoints live in a work folder beside out_dir (`.resume/<name>-<hash>`), keyed
    by the run's identity: outside the stage's DVC output, so an interrupted run (even under
    `dvc repro`, which deletes outputs before a stage runs) resumes there when spec.resume, and
    the resumed run ends exactly as an uninterrupted one (per-epoch seeding and sampling).
    """
    work, resume = resume_folder(cfg, spec)
    trainer, best = build_trainer(cfg, task, spec, logger, work)
    trainer.fit(task, data, ckpt_path=resume, weights_only=True)
    metrics = test_best(trainer, task, data, best)
    write_outputs(spec, task, data, metrics)
    if isinstance(logger, MLFlowLogger):
        log_outputs(cfg, logger, spec, task, metrics)
    return metrics


def resume_folder(cfg: DictConfig, spec: RunSpec) -> tuple[Path, str | None]:
    """The run's work folder (`.resume/<name>-<key>`, made on rank 0) and the checkpoint it resumes
    from (None: it starts afresh)."""
    work = spec.out_dir.parent / ".resume" / f"{spec.out_dir.name}-{spec.key}"
    resume = resume_checkpoint(work, spec.key, cfg.resume)
    if not cfg.trainer.fast_dev_run and is_global_zero():
        work.mkdir(parents=True, exist_ok=True)
        (work / MARKER).write_text(f"{spec.stage} resume\n")
        warnings.filterwarnings("ignore", message="Checkpoint directory .* exists and is not empty")  # the marker, or a resume
    if resume:
        log.info("resuming from %s", resume)
    return work, resume


def build_trainer(
    cfg: DictConfig, task: BaseTask, spec: RunSpec, logger: Logger | None, work: Path
) -> tuple[L.Trainer, ModelCheckpoint | None]:
    """The configured Trainer with the run's checkpoints in `work`, its callbacks and atomic
    checkpoint writes; the callback that keeps the best weights (None without a validation set)."""
    # Lightning's save_last writes only when the best changes; a resume wants every epoch's end.
    checkpoints = [ModelCheckpoint(dirpath=work, filename="last", enable_version_counter=False)]
    best = None
    without_validation = {}
    if spec.validate:
        best = ModelCheckpoint(dirpath=work, filename="best", monitor=task.monitor, mode=task.mode)
        checkpoints.insert(0, best)
    else:
        log.info(
            "no validation set: training runs to its end (max_steps %d, max_epochs %d) and keeps the last weights",
            spec.max_steps,
            spec.max_epochs,
        )
        without_validation = {"limit_val_batches": 0, "num_sanity_val_steps": 0}
    trainer: L.Trainer = instantiate(
        cfg.trainer,
        max_epochs=spec.max_epochs,
        max_steps=spec.max_steps,
        logger=logger if logger is not None else False,
        default_root_dir=work,
        **without_validation,
        callbacks=[
            *checkpoints,
            *configured_callbacks(cfg.callbacks, task, spec.validate, spec.patience),
            SeedEachEpoch(cfg.seed),
            StayStopped(),
            StampConfig(spec.key),
            *spec.extra_callbacks,
        ],
        plugins=[AtomicCheckpointIO()],
        enable_progress_bar=False,
    )
    return trainer, best


def test_best(trainer: L.Trainer, task: BaseTask, data: L.LightningDataModule, best: ModelCheckpoint | None) -> dict:
    """The best weights (the last without validation) tested: the run's metrics, its best validation
    score among them. Another rank of a DDP run exits here: rank 0 writes the outputs."""
    best_score = None
    if best is not None and best.best_model_path:
        load_weights(task, best.best_model_path)
        best_score = float(best.best_model_score) if best.best_model_score is not None else None
    tested = trainer.test(task, data, verbose=False)[0]  # under DDP, each rank tests its share; the metrics are synced
    if not trainer.is_global_zero:
        raise SystemExit(0)
    metrics = {
        best_key(task): best_score,
        "epochs": trainer.current_epoch,
        "global_step": trainer.global_step,
        **{k: float(v) for k, v in tested.items()},
    }
    return metrics


def best_key(task: BaseTask) -> str:
    """The metrics key of the best validation score: best_val_iou for task.monitor val/iou."""
    return f"best_{task.monitor.replace('/', '_')}"


def write_outputs(spec: RunSpec, task: BaseTask, data: L.LightningDataModule, metrics: dict) -> None:
    """spec.out_dir written whole or not at all: the best weights, metrics.json and spec.write_more's
    files (whose metrics join `metrics`)."""
    with atomic_directory(spec.out_dir, spec.stage, key=spec.out_key) as tmp:
        extra = {"datamodule_hyper_parameters": dict(data.hparams)} if data.hparams else {}
        save_weights(tmp / "checkpoints" / "best.ckpt", task, **extra, **{CONFIG_HASH: spec.key})
        if spec.write_more is not None:
            metrics.update(spec.write_more(task, data, tmp))
        (tmp / "metrics.json").write_text(json.dumps(metrics, indent=2) + "\n")


def log_outputs(cfg: DictConfig, logger: MLFlowLogger, spec: RunSpec, task: BaseTask, metrics: dict) -> None:
    """The run's metrics and checkpoint into its MLflow run, and the model published (mlflow.log_models)."""
    logger.experiment.log_dict(logger.run_id, metrics, "metrics.json")
    logger.experiment.log_artifact(logger.run_id, str(spec.out_dir / "checkpoints" / "best.ckpt"), "checkpoints")
    if cfg.mlflow.log_models and spec.input_size[0]:
        publish(logger.run_id, tracking_uri(cfg.mlflow), task, input_size=spec.input_size, manifests=spec.manifests,
                register_as=spec.register_as, score=metrics[best_key(task)])  # fmt: skip
    OPEN_RUNS.pop(logger.run_id, None)  # whole: a stop from here on is no longer this run's


def fit_segmentation(
    cfg: DictConfig,
    stage: str,
    *,
    target: str,
    pretraining: DictConfig | None = None,
    write_more: Callable[[SegmentationTask, OffroadDataModule, Path], dict] | None = None,
) -> dict:
    """The pretrain and train stages' run: a segmentation network on the split's manifests, into
    `<stage>.out_dir` (its max_epochs, max_steps, channels_last and sample_images too), initialised
    from `pretraining` (conf/pretraining) when given (see fit)."""
    own, m = cfg[stage], cfg.model
    out_dir = Path(own.out_dir)
    pretraining_name = pretraining.name if pretraining is not None else "none"
    L.seed_everything(cfg.seed, workers=True)
    data: OffroadDataModule = instantiate(cfg.data, target=target, seed=cfg.seed)
    data.setup()  # every listed file exists, before any training
    task: SegmentationTask = instantiate(m, num_classes=NUM_CLASSES[target], channels_last=own.channels_last, _convert_="all")
    loaded = initialise(task, pretraining_name, pretraining)
    if loaded:
        log.info("initialised %d parameter tensors from %s pretraining", len(loaded), pretraining_name)
    files = [data.split_dir / f"{name}.csv" for name in ("train", "val", "test")]
    files += sorted({Path(s.label) for name in ("train", "val") for s in data.samples[name]})
    if pretraining_name != "none":
        files.append(Path(pretraining.checkpoint or pretraining.weights_path or ""))
    settings = {
        "target": target,
        "channels_last": own.channels_last,
        "model": OmegaConf.to_container(m, resolve=True),
        "data": {k: v for k, v in OmegaConf.to_container(cfg.data, resolve=True).items() if k not in LOADER_SETTINGS},
        "pretraining": OmegaConf.to_container(pretraining, resolve=True) if pretraining is not None else None,
    }
    spec = RunSpec(
        stage=stage,
        out_dir=out_dir,
        out_key=f"{stage}.out_dir",
        key=run_identity(cfg, stage, settings, files),
        max_epochs=own.get("max_epochs") or cfg.trainer.max_epochs,
        max_steps=own.max_steps,
        validate=bool(data.samples["val"]),
        extra_callbacks=(LogSamples(own.sample_images),),
        write_more=write_more,
        input_size=(cfg.data.height, cfg.data.width),
        manifests={context: data.split_dir / f"{name}.csv" for context, name in MANIFEST_CONTEXTS},
        register_as=m.name if stage == "train" else None,  # path networks; pretraining's are steps towards them
    )
    tags = {"stage": stage, "model": m.name, "pretraining": pretraining_name}
    logger = training_logger(cfg, f"{stage} {m.name}-{pretraining_name}", tags, OmegaConf.to_container(cfg, resolve=True))
    return fit(cfg, task, data, spec, logger)


def write_confidence_maps(task: SegmentationTask, data: OffroadDataModule, tmp: Path, final: Path) -> int:
    """Path confidence (softmax of the path class) for every test sample, at the label's size, as
    float16 .npy under tmp/<sequence>/NNNNNN[_mirrored].npy, listed in tmp/manifest.csv by the path
    each will have once tmp is renamed to `final`."""
    samples = data.samples["test"]
    transform = transforms(data.hparams.width, data.hparams.height)
    task.eval()
    rows = []
    tmp.mkdir()
    with torch.no_grad():
        for sample in samples:
            image, label = load_sample(sample, "path")
            scores = task(transform(image=image)["image"][None].to(task.device))
            confidence = F.interpolate(scores.softmax(1)[:, 1:2], size=label.shape, mode="bilinear", align_corners=False)[0, 0]
            name = prediction_name(sample)
            (tmp / sample.sequence).mkdir(exist_ok=True)
            np.save(tmp / name, confidence.cpu().numpy().astype(np.float16))
            rows.append((sample, str(final / name)))
        write_predictions_manifest(tmp / "manifest.csv", rows)
    return len(rows)
