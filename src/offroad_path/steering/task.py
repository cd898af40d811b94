"""The Lightning task of the steering baseline: MSE on the normalised angle, SGD with momentum and
step decay as the thesis trained PilotNet; mean absolute error per split (torchmetrics)."""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torchmetrics import MeanAbsoluteError

from offroad_path.steering.pilotnet import PilotNet
from offroad_path.training.task import BaseTask


class SteeringTask(BaseTask):
    monitor, mode = "val/mae", "min"

    def __init__(self, width: int = 256, height: int = 136, lr: float = 2e-4, lr_step_epochs: int = 0, lr_gamma: float = 0.1,
                 momentum: float = 0.9, weight_decay: float = 0.0):  # fmt: skip
        super().__init__()
        self.save_hyperparameters()
        self.configure()

    def configure_models(self) -> None:
        self.model = PilotNet(self.hparams.width, self.hparams.height)

    def configure_losses(self) -> None:
        self.loss = F.mse_loss

    def configure_metrics(self) -> None:
        self.mae = torch.nn.ModuleDict({f"{split}_mae": MeanAbsoluteError() for split in ("train", "val", "test")})

    def forward(self, image: torch.Tensor) -> torch.Tensor:  # (N, 3, H, W) -> (N,)
        return self.model(image)

    def _step(self, batch: dict, split: str) -> torch.Tensor:
        predicted = self(batch["image"])
        loss = self.loss(predicted, batch["steering"])
        mae = self.mae[f"{split}_mae"]
        mae.update(predicted, batch["steering"])
        self.log(f"{split}/loss", loss, on_step=split == "train", on_epoch=True, batch_size=len(predicted))
        self.log(f"{split}/mae", mae, on_step=False, on_epoch=True)
        return loss
