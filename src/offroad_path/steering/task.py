"""The Lightning task of the steering baseline: MSE on the normalised angle, SGD with momentum and
step decay as the thesis trained PilotNet; mean absolute error per split (torchmetrics)."""

from __future__ import annotations

import torch
import torch.nn.functional as F
from omegaconf import DictConfig
from torchmetrics import MeanAbsoluteError

from offroad_path.steering.pilotnet import PilotNet
from offroad_path.training.task import BaseTask


def weighted_mse(predicted: torch.Tensor, true: torch.Tensor, weight: torch.Tensor | None = None) -> torch.Tensor:
    """Mean squared error, each frame's term times its weight (steering.balance=weighted; training only)."""
    return F.mse_loss(predicted, true) if weight is None else (weight * (predicted - true) ** 2).mean()


class SteeringTask(BaseTask):
    monitor, mode = "val/mae", "min"

    # Hyper-parameters saved flat in the checkpoint; build one from config with from_config.
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
    ):
        super().__init__()
        self.save_hyperparameters()
        self.configure()

    @classmethod
    def from_config(cls, s: DictConfig) -> SteeringTask:
        """From the `steering` config node (conf/steering/default.yaml)."""
        return cls(**{k: s[k] for k in ("width", "height", "lr", "lr_step_epochs", "lr_gamma", "momentum", "weight_decay")})

    def configure_models(self) -> None:
        self.model = PilotNet(self.hparams.width, self.hparams.height)

    def configure_losses(self) -> None:
        self.loss = weighted_mse

    def configure_metrics(self) -> None:
        self.mae = torch.nn.ModuleDict({f"{split}_mae": MeanAbsoluteError() for split in ("train", "val", "test")})

    def forward(self, image: torch.Tensor) -> torch.Tensor:  # (N, 3, H, W) -> (N,)
        return self.model(image)

    def _step(self, batch: dict, split: str) -> torch.Tensor:
        predicted = self(batch["image"])
        loss = self.loss(predicted, batch["steering"], batch.get("weight"))
        mae = self.mae[f"{split}_mae"]
        mae.update(predicted, batch["steering"])
        self.log(f"{split}/loss", loss, on_step=split == "train", on_epoch=True, batch_size=len(predicted), sync_dist=True)
        self.log(f"{split}/mae", mae, on_step=False, on_epoch=True, sync_dist=True)
        return loss
