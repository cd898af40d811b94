"""The Lightning task: per-pixel softmax cross-entropy over the path (2 classes) or the world's
8 semantic classes, SGD as Holder & Breckon trained, torchmetrics per split."""

from __future__ import annotations

import bisect

import lightning as L
import torch
import torch.nn.functional as F
from torchmetrics import Metric, MetricCollection
from torchmetrics.classification import MulticlassAccuracy, MulticlassJaccardIndex
from torchmetrics.functional.classification import binary_stat_scores

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
    the best checkpoint follow, and write one `_step`; all train with the paper's SGD."""

    monitor: str
    mode: str  # "max" or "min"

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
        return self._step(batch, "train")

    def validation_step(self, batch: dict, batch_idx: int) -> None:
        self._step(batch, "val")

    def test_step(self, batch: dict, batch_idx: int) -> None:
        self._step(batch, "test")

    def configure_optimizers(self):
        return sgd_with_step_decay(self)  # PilotNet (the thesis's schedule, in epochs)


class SegmentationTask(BaseTask):
    monitor, mode = "val/iou", "max"

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
    ):
        super().__init__()

    @classmethod
    def for_inference(cls, hp: dict) -> SegmentationTask:
        """From a checkpoint's hyper-parameters, of this version or an earlier one: the optimiser's
        settings, which inference does not use, are filled in or left out."""
        own = {"lr_milestones": [], "lr_gamma": 0.1, "lr_warmup": 0.0} | {k: v for k, v in hp.items() if k != "lr_step_epochs"}
        return cls(**own)

    def configure_optimizers(self):
        return sgd_with_milestones(self)

    def configure_models(self) -> None:
        self.model = build_model(self.hparams.model, self.hparams.num_classes, self.hparams.width)
        if self.hparams.channels_last:
            self.model = self.model.to(memory_format=torch.channels_last)

    def configure_losses(self) -> None:
        self.loss = F.cross_entropy  # per-pixel softmax cross-entropy, the paper's (a function: no module in the state dict)

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


def sgd_with_milestones(task: L.LightningModule):
    """SGD with momentum and weight decay (the paper's), the rate ramped linearly from 0 over the
    first lr_warmup of the run's iterations and multiplied by lr_gamma at each of lr_milestones
    (fractions of the run's iterations: max_steps when set, else max_epochs x batches per epoch;
    Lightning's estimated_stepping_batches). The paper says only "a step function" for SegNet: its
    milestones, like FCN-8s's warm-up, are this project's choice (conf/model/)."""
    hp = task.hparams
    optimizer = torch.optim.SGD(task.parameters(), lr=hp.lr, momentum=hp.momentum, weight_decay=hp.weight_decay)
    if not hp.lr_milestones and not hp.lr_warmup:
        return optimizer
    total = task.trainer.estimated_stepping_batches
    warmup, milestones = hp.lr_warmup * total, sorted(round(f * total) for f in hp.lr_milestones)

    def factor(step: int) -> float:
        return min(1.0, (step + 1) / warmup if warmup else 1.0) * hp.lr_gamma ** bisect.bisect_right(milestones, step)

    scheduler = torch.optim.lr_scheduler.LambdaLR(optimizer, factor)
    return {"optimizer": optimizer, "lr_scheduler": {"scheduler": scheduler, "interval": "step"}}


def sgd_with_step_decay(task: L.LightningModule):
    """SGD with momentum and weight decay, the lr multiplied by lr_gamma every lr_step_epochs (0: fixed)."""
    hp = task.hparams
    optimizer = torch.optim.SGD(task.parameters(), lr=hp.lr, momentum=hp.momentum, weight_decay=hp.weight_decay)
    if hp.lr_step_epochs <= 0:
        return optimizer
    scheduler = torch.optim.lr_scheduler.StepLR(optimizer, step_size=hp.lr_step_epochs, gamma=hp.lr_gamma)
    return {"optimizer": optimizer, "lr_scheduler": {"scheduler": scheduler, "interval": "epoch"}}
