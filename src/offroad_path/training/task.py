"""The Lightning task: per-pixel softmax cross-entropy over the path (2 classes) or the world's
8 semantic classes, with an optional soft Dice term; SGD as Holder & Breckon trained, or AdamW
with a cosine schedule (the laptop recipe, benchmarks/recipe_search.py); torchmetrics per split."""

from __future__ import annotations

import bisect
import math

import lightning as L
import torch
import torch.nn.functional as F
from torchmetrics import Metric, MetricCollection
from torchmetrics.classification import MulticlassAccuracy, MulticlassJaccardIndex
from torchmetrics.functional.classification import binary_stat_scores

from offroad_path.errors import InputError
from offroad_path.models import build_model
from offroad_path.statistics.scores import SCORES


class PathScore(Metric):
    """One of the paper's scores (statistics.scores) of the path class, from tp, fp, tn, fn summed
    over an epoch and synced across DDP ranks: training logs what the evaluation reports."""

    full_state_update = False

    def __init__(self, score: str):
        super().__init__()
        self.score = SCORES[score]
        self.add_state("counts", default=torch.zeros(4, dtype=torch.long), dist_reduce_fx="sum")

    def update(self, predicted: torch.Tensor, target: torch.Tensor) -> None:  # (N, H, W) 0/1 each
        self.counts += binary_stat_scores(predicted, target, validate_args=False)[:4]

    def compute(self) -> torch.Tensor:
        # An epoch that predicts no path has no precision (nan in the evaluation's tables); logged as
        # 0, as torchmetrics does, so that early stopping and metrics.json see a number.
        return torch.nan_to_num(self.score(self.counts), nan=0.0)


class BaseTask(L.LightningModule):
    """What every task of this project shares (torchgeo's pattern): subclasses build their network,
    loss and metrics in the configure_* hooks, name the validation metric that early stopping and
    the best checkpoint follow, write one `_step` and own their optimiser (configure_optimizers)."""

    monitor: str
    mode: str  # "max" or "min"
    loss_settings: str  # the settings a non-finite training loss points to, named in its error

    def __init__(self) -> None:
        """Saves the subclass's __init__ arguments as the checkpoint's hyper-parameters (Lightning reads
        them from the calling __init__ frames, as torchgeo's BaseTask does; the run logs the whole
        resolved config instead), then builds the network, loss and metrics from them: a subclass's
        __init__ checks its arguments and calls super().__init__(), nothing more."""
        super().__init__()
        self.save_hyperparameters(logger=False)
        self.configure_models()
        self.configure_losses()
        self.configure_metrics()

    def configure_models(self) -> None:
        raise NotImplementedError

    def configure_losses(self) -> None:
        raise NotImplementedError

    def configure_metrics(self) -> None:
        raise NotImplementedError

    def _step(self, batch: dict, split: str) -> torch.Tensor:
        raise NotImplementedError

    def training_step(self, batch: dict, batch_idx: int) -> torch.Tensor:
        """One step's loss; stops the run at the first non-finite one (a diverged run trains nothing
        worth keeping), naming the settings of its loss terms and rate."""
        loss = self._step(batch, "train")
        if not torch.isfinite(loss):
            raise InputError(
                self.loss_settings, f"the training loss is {loss.item()} at step {self.global_step}: the run diverged; lower or check them"
            )
        return loss

    def validation_step(self, batch: dict, batch_idx: int) -> None:
        self._step(batch, "val")

    def test_step(self, batch: dict, batch_idx: int) -> None:
        self._step(batch, "test")

    def configure_optimizers(self):
        raise NotImplementedError  # each task owns its optimiser and schedule


class SegmentationTask(BaseTask):
    monitor, mode = "val/iou", "max"
    loss_settings = "model.dice_weight, model.lr, model.weight_decay"

    # Each argument is a hyper-parameter saved flat in the checkpoint, which TorchModel rebuilds
    # the task from; conf/model/<name>.yaml builds one through segmentation_task (its `_target_`).
    def __init__(  # noqa: PLR0913
        self,
        *,
        model: str,
        num_classes: int,
        width: float,
        lr: float,
        lr_milestones: list[float],
        lr_gamma: float,
        lr_warmup: float,
        momentum: float,
        weight_decay: float,
        channels_last: bool,
        optimizer: str = "sgd",
        lr_schedule: str = "step",
        dice_weight: float = 0.0,
        batch_norm: bool | None = None,
    ):
        if optimizer not in OPTIMIZERS or lr_schedule not in SCHEDULES:
            raise ValueError(f"optimizer {optimizer!r}, lr_schedule {lr_schedule!r}: valid {OPTIMIZERS} and {SCHEDULES}")
        super().__init__()

    def configure_optimizers(self):
        return optimizer_with_schedule(self)

    def configure_models(self) -> None:
        self.model = build_model(self.hparams.model, self.hparams.num_classes, self.hparams.width, self.hparams.batch_norm)
        if self.hparams.channels_last:
            self.model = self.model.to(memory_format=torch.channels_last)

    def configure_losses(self) -> None:
        self.loss = self.cross_entropy_and_dice  # a method: no module in the state dict

    def cross_entropy_and_dice(self, scores: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        """Per-pixel softmax cross-entropy (the paper's) plus dice_weight x soft Dice loss, which
        scores the overlap the IoU measures rather than each pixel alone (Milletari et al. 2016)."""
        loss = F.cross_entropy(scores, target)
        if self.hparams.dice_weight:
            loss = loss + self.hparams.dice_weight * soft_dice_loss(scores, target)
        return loss

    def configure_metrics(self) -> None:
        n = self.hparams.num_classes
        if n == 2:  # path or not: the paper's scores of the path class (MetricCollection shares their counts)
            metrics = MetricCollection({name: PathScore(name) for name in SCORES})
        else:
            metrics = MetricCollection(
                {"accuracy": MulticlassAccuracy(n, average="micro"), "iou": MulticlassJaccardIndex(n, average="macro")}
            )
        self.train_metrics = metrics.clone(prefix="train/")
        self.val_metrics = metrics.clone(prefix="val/")
        self.test_metrics = metrics.clone(prefix="test/")

    def forward(self, image: torch.Tensor) -> torch.Tensor:  # (N, 3, H, W) -> scores (N, C, H, W)
        if self.hparams.channels_last:
            image = image.contiguous(memory_format=torch.channels_last)
        return self.model(image)

    def _step(self, batch: dict, split: str) -> torch.Tensor:
        scores = self(batch["image"])
        loss = self.loss(scores, batch["target"])
        metrics = {"train": self.train_metrics, "val": self.val_metrics, "test": self.test_metrics}[split]
        metrics.update(scores.argmax(dim=1), batch["target"])
        self.log(f"{split}/loss", loss, on_step=split == "train", on_epoch=True, batch_size=len(scores), sync_dist=True)
        self.log_dict(metrics, on_step=False, on_epoch=True)
        return loss


def segmentation_task(
    *, name: str, num_classes: int, channels_last: bool, imagenet_weights: str | None = None, paper: dict | None = None, **hyperparameters
) -> SegmentationTask:
    """The task of conf/model/<name>.yaml, its `_target_`: hydra.utils.instantiate(cfg.model,
    num_classes=..., channels_last=..., _convert_="all"). Every key of the file is an argument of
    SegmentationTask but the two that other settings read: imagenet_weights (pretraining=imagenet)
    and paper (experiment=paper)."""
    return SegmentationTask(model=name, num_classes=num_classes, channels_last=channels_last, **hyperparameters)


OPTIMIZERS = ("sgd", "adamw")
SCHEDULES = ("step", "cosine")


def soft_dice_loss(scores: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """1 - soft Dice of the batch: (N, C, H, W) scores against (N, H, W) classes; the path class
    alone when C is 2, the mean over classes otherwise."""
    probability = scores.float().softmax(dim=1)
    truth = F.one_hot(target, scores.shape[1]).permute(0, 3, 1, 2).to(probability.dtype)  # (N, C, H, W)
    if scores.shape[1] == 2:
        probability, truth = probability[:, 1:], truth[:, 1:]
    overlap = (probability * truth).sum(dim=(0, 2, 3))
    total = probability.sum(dim=(0, 2, 3)) + truth.sum(dim=(0, 2, 3))
    return 1 - ((2 * overlap + 1) / (total + 1)).mean()


def optimizer_with_schedule(
    task: L.LightningModule,
    optimizer: str | None = None,
    schedule: str | None = None,
    warmup: float | None = None,
    milestones: list[float] | None = None,
):
    """SGD with momentum and weight decay (the paper's) or AdamW (decoupled weight decay), the rate
    ramped linearly from 0 over the first lr_warmup of the run's iterations, then either multiplied
    by lr_gamma at each of lr_milestones (lr_schedule step) or annealed to 0 along a half cosine
    (lr_schedule cosine; Loshchilov & Hutter 2017), in fractions of the run's iterations: max_steps
    when set, else max_epochs x batches per epoch (Lightning's estimated_stepping_batches). The paper
    says only "a step function" for SegNet: its milestones, like the laptop's recipe, are this
    project's choice (conf/model/). `optimizer`, `schedule`, `warmup` and `milestones` stand in for
    hyper-parameters a task does not have (PilotNet's). The one optimiser builder of both tasks."""
    hp = task.hparams
    optimizer, schedule = optimizer or hp.optimizer, schedule or hp.lr_schedule
    warmup = hp.get("lr_warmup", 0.0) if warmup is None else warmup
    milestones = hp.get("lr_milestones", []) if milestones is None else milestones
    if optimizer == "adamw":
        optimizer = torch.optim.AdamW(task.parameters(), lr=hp.lr, weight_decay=hp.weight_decay)
    else:
        optimizer = torch.optim.SGD(task.parameters(), lr=hp.lr, momentum=hp.momentum, weight_decay=hp.weight_decay)
    if schedule == "step" and not milestones and not warmup:
        return optimizer
    total = task.trainer.estimated_stepping_batches
    warmup, milestones = warmup * total, sorted(round(f * total) for f in milestones)

    def factor(step: int) -> float:
        ramp = min(1.0, (step + 1) / warmup if warmup else 1.0)
        if schedule == "cosine":
            return ramp * 0.5 * (1 + math.cos(math.pi * min(step, total) / total))
        return ramp * hp.lr_gamma ** bisect.bisect_right(milestones, step)

    scheduler = torch.optim.lr_scheduler.LambdaLR(optimizer, factor)
    return {"optimizer": optimizer, "lr_scheduler": {"scheduler": scheduler, "interval": "step"}}
