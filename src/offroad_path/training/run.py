"""One training loop for every stage that trains (pretrain, train, train_steering): Lightning trainer
with early stopping, resumable and exactly reproducible checkpoints, MLflow, test, published
weights; and for the path networks, their data, task, initialisation and the test-set confidence
maps that post-processing reads."""

from __future__ import annotations

import hashlib
import json
import logging
import random
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
from lightning.pytorch.callbacks import EarlyStopping, ModelCheckpoint
from lightning.pytorch.loggers import MLFlowLogger
from omegaconf import DictConfig, OmegaConf

from offroad_path.data.datamodule import OffroadDataModule
from offroad_path.data.dataset import transforms
from offroad_path.data.loading import load_sample
from offroad_path.data.manifest import prediction_name, write_predictions_manifest
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
from offroad_path.training.task import BaseTask, SegmentationTask
from offroad_path.utils.atomic import MARKER, atomic_directory, check_output_dir, owned
from offroad_path.utils.tracking import experiment_id, flatten, multirun_parent, tracking_uri
from offroad_path.viz import colour_semantic, overlay

log = logging.getLogger(__name__)


class LogSamples(L.Callback):
    """After each validation epoch, validation predictions beside their targets, as one MLflow image."""

    def __init__(self, count: int):
        self.count = count

    def on_validation_epoch_end(self, trainer: L.Trainer, task: SegmentationTask) -> None:
        if trainer.sanity_checking or not isinstance(trainer.logger, MLFlowLogger) or self.count <= 0:
            return
        dataset = trainer.val_dataloaders.dataset
        rows = []
        for i in range(min(self.count, len(dataset))):
            image, target = load_sample(dataset.samples[i], dataset.target)
            with torch.no_grad():
                scores = task(dataset[i]["image"][None].to(task.device))
            scores = F.interpolate(scores, size=target.shape, mode="bilinear", align_corners=False)[0]
            predicted = scores.argmax(0).cpu().numpy()
            if task.hparams.num_classes == 2:
                rows.append(np.hstack([overlay(image, target), overlay(image, predicted)]))
            else:
                rows.append(np.hstack([image, colour_semantic(target.astype(np.uint8)), colour_semantic(predicted.astype(np.uint8))]))
        trainer.logger.experiment.log_image(
            trainer.logger.run_id, np.vstack(rows), artifact_file=f"samples/epoch_{trainer.current_epoch:03d}.png"
        )


def training_logger(cfg: DictConfig, run_name: str, tags: dict, params: dict) -> MLFlowLogger | None:
    """The run's Lightning logger from conf/logger, with the experiment's name in its tags, a child
    of its sweep in a multirun, with `params` logged; None when mlflow.enabled is false."""
    if not cfg.mlflow.enabled:
        return None
    tags = {**tags, "experiment_name": cfg.experiment_name}
    if parent := multirun_parent(cfg):
        tags["mlflow.parentRunId"] = parent
    # The tracking URI is always explicit: Lightning's logger would otherwise fall back to ./mlruns.
    experiment_id(cfg.mlflow)  # created with its artifact location, which the logger would not set
    logger = instantiate(cfg.logger, run_name=run_name, tracking_uri=tracking_uri(cfg.mlflow), tags=tags)
    logger.log_hyperparams(flatten(params))
    return logger


class SeedEachEpoch(L.Callback):
    """Seeds torch, NumPy and random from (seed, epoch) before each training epoch: dropout and
    anything else drawn from the global generators replays the same after a resume."""

    def __init__(self, seed: int):
        self.seed = seed

    def on_train_epoch_start(self, trainer: L.Trainer, task: L.LightningModule) -> None:
        seed_everything_quietly(self.seed * 1_000_003 + trainer.current_epoch)


def seed_everything_quietly(seed: int) -> None:
    random.seed(seed)
    np.random.seed(seed % 2**32)
    torch.manual_seed(seed)


class StayStopped(L.Callback):
    """A run that early stopping ended stays ended when it is run again: resuming from its last.ckpt
    would otherwise train one more epoch (Lightning restores the callback's counters, not its
    decision) and change epochs, steps and possibly the best weights."""

    def on_train_start(self, trainer: L.Trainer, task: L.LightningModule) -> None:
        if any(isinstance(c, EarlyStopping) and c.stopped_epoch > 0 for c in trainer.callbacks):
            trainer.should_stop = True


class StampConfig(L.Callback):
    """Writes the run's config hash into every checkpoint, so a resume can check it belongs to this run."""

    def __init__(self, key: str):
        self.key = key

    def on_save_checkpoint(self, trainer: L.Trainer, task: L.LightningModule, checkpoint: dict) -> None:
        checkpoint[CONFIG_HASH] = self.key


# Settings that change how long a run goes on, not what it computes: a longer run resumes a shorter one.
LENGTH_SETTINGS = {"max_epochs", "fast_dev_run", "log_every_n_steps"}  # of conf/trainer (max_steps lives in train and pretrain)
# Settings of the data loader that change its speed, not the samples it gives.
LOADER_SETTINGS = {"num_workers", "pin_memory", "cache_mb"}


@dataclass
class RunSpec:
    """What a training run needs besides its task and data (one spec for pretrain, train and
    train_steering)."""

    stage: str
    out_dir: Path
    inputs: list[str]  # folders and files out_dir must not overlap
    seed: int
    resume: bool
    trainer: DictConfig  # conf/trainer: instantiated with the run's callbacks, logger and max_epochs
    callbacks: DictConfig  # conf/callbacks: each instantiated; early stopping gets the task's monitor and mode
    max_epochs: int
    identity: dict  # every setting that changes what the run computes
    files: list[Path] = field(default_factory=list)  # inputs whose bytes are part of its identity
    extra_callbacks: list[L.Callback] = field(default_factory=list)
    patience: int | None = None  # early stopping's patience instead of the one in conf/callbacks
    out_key: str = ""  # the config key of out_dir, for messages (default: <stage>.out_dir)
    max_steps: int = -1  # -1: no cap
    validate: bool = True  # False (no validation set, the paper's protocol): no early stopping, the last weights are kept


PACKAGE = Path(__file__).resolve().parents[1]


def run_key(identity: dict, files: list[Path]) -> str:
    """The identity of a training run: its settings, the bytes of its input files and of this
    package's code (so new data, a new pretraining or a code change never resumes an old run, even
    one that finished). Paths are taken as configured, never resolved."""
    digest = hashlib.sha256(json.dumps(identity, sort_keys=True).encode())
    return file_digest(files + sorted(PACKAGE.rglob("*.py")), digest).hexdigest()[:16]


def resume_checkpoint(work: Path, key: str, resume: bool) -> str | None:
    """The work folder's last.ckpt to resume from, checked; None to start fresh (resume=false
    clears the folder first). A corrupt or foreign last.ckpt is a CheckpointError naming it."""
    last = work / "last.ckpt"
    if not resume:
        if owned(work):
            shutil.rmtree(work)
        return None
    if not last.is_file():
        return None
    try:
        saved = load_checkpoint(last)
    except CheckpointError as e:
        raise CheckpointError(f"{e}; delete it, or set train.resume=false to start this run afresh") from e
    if saved.get(CONFIG_HASH) != key:
        raise CheckpointError(
            f"{last}: belongs to another configuration (hash {saved.get(CONFIG_HASH)} is not {key}); "
            "set train.resume=false to start this run afresh"
        )
    return str(last)


def callbacks_from(spec: RunSpec, task: BaseTask) -> list[L.Callback]:
    """conf/callbacks instantiated, early stopping following the task's validation metric (left
    out when the run has no validation set)."""
    made = []
    for name, node in spec.callbacks.items():
        extra: dict = {}
        if OmegaConf.select(node, "_target_", default="").endswith("EarlyStopping"):
            if not spec.validate:
                continue
            extra = {"monitor": task.monitor, "mode": task.mode} | ({"patience": spec.patience} if spec.patience else {})
        try:
            made.append(instantiate(node, **extra))
        except Exception as e:  # Hydra wraps the callback's own error
            raise ValueError(f"callbacks.{name}: cannot be built ({e})") from e
    return made


def fit(
    task: BaseTask,
    data: L.LightningDataModule,
    spec: RunSpec,
    logger: MLFlowLogger | None,
    write_more: Callable[[BaseTask, L.LightningDataModule, Path], dict] | None = None,
) -> dict:
    """Train `task` (early stopping on task.monitor), test its best weights, and write spec.out_dir
    atomically: checkpoints/best.ckpt (weights and hyper-parameters only), metrics.json, and
    whatever `write_more(task, data, tmp)` adds (it returns extra metrics).

    Lightning's full checkpoints live in a work folder beside out_dir (`.resume/<name>-<hash>`), keyed
    by the run's identity: outside the stage's DVC output, so an interrupted run (even under
    `dvc repro`, which deletes outputs before a stage runs) resumes there when spec.resume, and
    the resumed run ends exactly as an uninterrupted one (per-epoch seeding and sampling).
    """
    key = run_key(spec.identity, spec.files)
    work = spec.out_dir.parent / ".resume" / f"{spec.out_dir.name}-{key}"
    resume = resume_checkpoint(work, key, spec.resume)
    if not spec.trainer.fast_dev_run:
        work.mkdir(parents=True, exist_ok=True)
        (work / MARKER).write_text(f"{spec.stage} resume\n")
        warnings.filterwarnings("ignore", message="Checkpoint directory .* exists and is not empty")  # the marker, or a resume
    if resume:
        log.info("resuming from %s", resume)
    # Lightning's save_last writes only when the best changes; a resume wants every epoch's end.
    latest = ModelCheckpoint(dirpath=work, filename="last", enable_version_counter=False)
    checkpoints = [latest]
    without_validation = {}
    if spec.validate:
        best = ModelCheckpoint(dirpath=work, filename="best", monitor=task.monitor, mode=task.mode)
        checkpoints.insert(0, best)
    else:
        log.info("no validation set: training runs to its end (max_steps %d, max_epochs %d) and keeps the last weights",
                 spec.max_steps, spec.max_epochs)  # fmt: skip
        without_validation = {"limit_val_batches": 0, "num_sanity_val_steps": 0}
    trainer: L.Trainer = instantiate(
        spec.trainer, max_epochs=spec.max_epochs, max_steps=spec.max_steps, logger=logger if logger is not None else False,
        default_root_dir=work, **without_validation,
        callbacks=[*checkpoints, *callbacks_from(spec, task), SeedEachEpoch(spec.seed), StayStopped(), StampConfig(key),
                   *spec.extra_callbacks],
        plugins=[AtomicCheckpointIO()], enable_progress_bar=False,
    )  # fmt: skip
    trainer.fit(task, data, ckpt_path=resume, weights_only=True)
    best_score = None
    if spec.validate and best.best_model_path:
        load_weights(task, best.best_model_path)
        best_score = float(best.best_model_score) if best.best_model_score is not None else None
    tested = trainer.test(task, data, verbose=False)[0]
    metrics = {f"best_{task.monitor.replace('/', '_')}": best_score,
               "epochs": trainer.current_epoch, "global_step": trainer.global_step, **{k: float(v) for k, v in tested.items()}}  # fmt: skip
    with atomic_directory(spec.out_dir, spec.stage, spec.inputs, key=spec.out_key or f"{spec.stage}.out_dir") as tmp:
        extra = {"datamodule_hyper_parameters": dict(data.hparams)} if data.hparams else {}
        save_weights(tmp / "checkpoints" / "best.ckpt", task, **extra, **{CONFIG_HASH: key})
        if write_more is not None:
            metrics.update(write_more(task, data, tmp))
        (tmp / "metrics.json").write_text(json.dumps(metrics, indent=2) + "\n")
    if logger is not None:
        logger.experiment.log_dict(logger.run_id, metrics, "metrics.json")
        logger.experiment.log_artifact(logger.run_id, str(spec.out_dir / "checkpoints" / "best.ckpt"), "checkpoints")
    return metrics


def fit_segmentation(
    cfg: DictConfig,
    stage: str,
    target: str,
    num_classes: int,
    write_more: Callable[[SegmentationTask, OffroadDataModule, Path], dict] | None = None,
) -> dict:
    """The pretrain and train stages' run: a segmentation network on the split's manifests, into
    `<stage>.out_dir`, from `pretraining` when the stage is train (see fit)."""
    out_dir = Path(cfg[stage].out_dir)
    pretraining = cfg.pretraining.name if stage == "train" else "none"
    inputs = [cfg.data.split_dir] + ([cfg.pretraining.checkpoint] if stage == "train" and cfg.pretraining.checkpoint else [])
    check_output_dir(out_dir, f"{stage}.out_dir", inputs)
    L.seed_everything(cfg.train.seed, workers=True)
    d, m = cfg.data, cfg.model
    data = OffroadDataModule.from_config(d, target, cfg.train.seed)
    data.setup()  # every listed file exists, before any training
    task = SegmentationTask.from_config(m, num_classes, cfg.train.channels_last)
    loaded = initialise(task.model, pretraining, cfg.pretraining, m.name, m.width)
    if loaded:
        log.info("initialised %d parameter tensors from %s pretraining", len(loaded), pretraining)
    identity = {
        "stage": stage, "target": target, "seed": cfg.train.seed,
        "data": {k: v for k, v in OmegaConf.to_container(cfg.data, resolve=True).items() if k not in LOADER_SETTINGS},
        "model": OmegaConf.to_container(cfg.model, resolve=True),
        "pretraining": OmegaConf.to_container(cfg.pretraining, resolve=True) if stage == "train" else None,
        "trainer": {k: v for k, v in OmegaConf.to_container(cfg.trainer, resolve=True).items() if k not in LENGTH_SETTINGS},
        "callbacks": OmegaConf.to_container(cfg.callbacks, resolve=True), "channels_last": cfg.train.channels_last,
    }  # fmt: skip
    files = [data.split_dir / f"{name}.csv" for name in ("train", "val", "test")]
    files += sorted({Path(s.label) for name in ("train", "val") for s in data.samples[name]})
    if stage == "train" and cfg.pretraining.name != "none":
        files.append(Path(cfg.pretraining.checkpoint or cfg.pretraining.weights_path or ""))
    spec = RunSpec(stage, out_dir, inputs, cfg.train.seed, cfg.train.resume, cfg.trainer, cfg.callbacks, cfg.trainer.max_epochs, identity,
                   files, [LogSamples(cfg.train.sample_images)], max_steps=cfg.train.max_steps,
                   validate=bool(data.samples["val"]))  # fmt: skip
    tags = {"stage": stage, "model": m.name, "pretraining": cfg.pretraining.name}
    logger = training_logger(cfg, f"{stage} {m.name}-{cfg.pretraining.name}", tags, OmegaConf.to_container(cfg, resolve=True))
    return fit(task, data, spec, logger, write_more)


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
