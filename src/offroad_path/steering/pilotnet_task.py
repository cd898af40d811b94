"""The Lightning task of the steering baseline: MSE on the normalised angle, SGD with momentum and
step decay as the thesis trained PilotNet; mean absolute error per split (torchmetrics).

With target "curvature" the network learns tan(angle) / tan(lock) in place of angle / lock: the
path's curvature over the recording vehicle's tightest, which another vehicle turns into its own
angle as pure pursuit does, atan(its wheelbase x curvature) (drive.policies.PilotNetPolicy).
`angle` gives the normalised angle of the recording vehicle either way, for predictions and metrics.
"""

from __future__ import annotations

import inspect
import math

import torch
import torch.nn.functional as F
from torchmetrics import MeanAbsoluteError

from offroad_path.steering.pilotnet import PilotNet
from offroad_path.training.task import OPTIMIZERS, BaseTask, optimizer_with_schedule


def weighted_mse(predicted: torch.Tensor, true: torch.Tensor, weight: torch.Tensor | None = None) -> torch.Tensor:
    """Mean squared error, each frame's term times its weight (steering.balance=weighted; training only)."""
    return F.mse_loss(predicted, true) if weight is None else (weight * (predicted - true) ** 2).mean()


class SteeringTask(BaseTask):
    monitor, mode = "val/mae", "min"
    loss_settings = "steering.lr, steering.momentum, steering.weight_decay"

    # Each argument is a hyper-parameter saved flat in the checkpoint, which the drive rebuilds the
    # task from; conf/steering/default.yaml builds one through steering_task (its `_target_`).
    def __init__(  # noqa: PLR0913
        self,
        *,
        width: int,
        height: int,
        lr: float,
        lr_step_epochs: int,
        lr_gamma: float,
        momentum: float,
        weight_decay: float,
        target: str = "angle",
        lock_deg: float | None = None,  # the recording vehicle's, for target curvature
        wheelbase_m: float | None = None,
        optimizer: str = "sgd",
    ):
        if target == "curvature" and not (lock_deg and wheelbase_m):
            raise ValueError("a curvature PilotNet needs the recording vehicle's lock_deg and wheelbase_m")
        if optimizer not in OPTIMIZERS:
            raise ValueError(f"optimizer {optimizer!r}: valid {OPTIMIZERS}")
        super().__init__()

    def configure_optimizers(self):
        """sgd: the thesis's (momentum, the rate times lr_gamma every lr_step_epochs epochs, 0: fixed);
        adamw: AdamW with a 5 % warm-up and a cosine to 0 over the run (the laptop's, as the path
        networks'). One builder for both tasks, training.task.optimizer_with_schedule."""
        hp = self.hparams
        if hp.optimizer == "sgd":
            epochs, every = self.trainer.max_epochs, hp.lr_step_epochs
            milestones = [k / epochs for k in range(every, epochs, every)] if every > 0 else []  # fractions of the run
            return optimizer_with_schedule(self, "sgd", "step", warmup=0.0, milestones=milestones)
        return optimizer_with_schedule(self, "adamw", "cosine", warmup=0.05)

    @property
    def max_curvature(self) -> float | None:
        """1/m of normalised output 1 (target curvature): tan(lock) / wheelbase; None for target angle."""
        hp = self.hparams
        return math.tan(math.radians(hp.lock_deg)) / hp.wheelbase_m if hp.target == "curvature" else None

    def learnt(self, steering: torch.Tensor) -> torch.Tensor:
        """The normalised angles (N,) as the network learns them: unchanged, or tan(angle) / tan(lock)."""
        if self.max_curvature is None:
            return steering
        lock = math.radians(self.hparams.lock_deg)
        return torch.tan(steering * lock) / math.tan(lock)

    def angle(self, image: torch.Tensor) -> torch.Tensor:  # (N, 3, H, W) -> (N,) normalised angle of the recording vehicle
        out = self(image)
        if self.max_curvature is None:
            return out
        lock = math.radians(self.hparams.lock_deg)
        return torch.atan(out * math.tan(lock)) / lock

    def configure_models(self) -> None:
        self.model = PilotNet(self.hparams.width, self.hparams.height)

    def configure_losses(self) -> None:
        self.loss = weighted_mse

    def configure_metrics(self) -> None:
        self.mae = torch.nn.ModuleDict({f"{split}_mae": MeanAbsoluteError() for split in ("train", "val", "test")})

    def forward(self, image: torch.Tensor) -> torch.Tensor:  # (N, 3, H, W) -> (N,)
        return self.model(image)

    def _step(self, batch: dict, split: str) -> torch.Tensor:
        predicted, true = self(batch["image"]), self.learnt(batch["steering"])
        loss = self.loss(predicted, true, batch.get("weight"))
        mae = self.mae[f"{split}_mae"]
        mae.update(predicted, true)
        self.log(f"{split}/loss", loss, on_step=split == "train", on_epoch=True, batch_size=len(predicted), sync_dist=True)
        self.log(f"{split}/mae", mae, on_step=False, on_epoch=True, sync_dist=True)
        return loss


def steering_task(**node: object) -> SteeringTask:
    """The task of conf/steering/default.yaml, its `_target_`: hydra.utils.instantiate(cfg.steering,
    _convert_="all"). SteeringTask's arguments are taken from the node by name (its signature is the
    one list of them); the node's other keys are the stage's (folders, batches, epochs, balance). The
    recording vehicle's lock and wheelbase are hyper-parameters of a curvature PilotNet alone."""
    names = set(inspect.signature(SteeringTask).parameters)
    if node.get("target") != "curvature":
        names -= {"lock_deg", "wheelbase_m"}
    return SteeringTask(**{key: value for key, value in node.items() if key in names})


def required_hyperparameters() -> list[str]:
    """The arguments every SteeringTask is built with (a checkpoint of train_steering has them all)."""
    return [name for name, p in inspect.signature(SteeringTask).parameters.items() if p.default is inspect.Parameter.empty]
