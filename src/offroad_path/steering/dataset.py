"""Steering frames as tensors: the image resized to PilotNet's input, mirrored with its angle."""

from __future__ import annotations

import albumentations as A
import cv2
import lightning as L
import numpy as np
import torch
from albumentations.pytorch import ToTensorV2
from omegaconf import DictConfig
from torch.utils.data import DataLoader, Dataset

from offroad_path.data.dataset import EpochSampler, read
from offroad_path.geometry.path import mirror
from offroad_path.steering.balance import balance_weights
from offroad_path.steering.frames import SteeringFrame


def steering_transforms(width: int, height: int, jitter: float, seed: int) -> A.Compose:
    """Resize and normalise; photometric jitter only, since a crop or a shift would change the angle."""
    ops: list = [A.Resize(height, width)]
    if jitter > 0:
        ops.append(A.ColorJitter(brightness=jitter, contrast=jitter, saturation=jitter, hue=0.02))
    return A.Compose([*ops, A.Normalize(), ToTensorV2()], seed=seed)


class SteeringDataset(Dataset):
    """Images and angles; with `loss_weights`, each item also carries its frame's weight in the loss."""

    def __init__(self, frames: list[SteeringFrame], transform: A.Compose, loss_weights: np.ndarray | None = None):
        self.frames = frames
        self.transform = transform
        self.loss_weights = loss_weights

    def __len__(self) -> int:
        return len(self.frames)

    def __getitem__(self, key: int | tuple[int, int]) -> dict:
        """key: an index, or (index, augmentation seed) from EpochSampler (see offroad_path.data.dataset)."""
        i, seed = key if isinstance(key, tuple) else (key, None)
        if seed is not None:
            self.transform.set_random_seed(seed)
        frame = self.frames[i]
        image = cv2.cvtColor(read(frame.image, cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
        if frame.mirrored:
            image = mirror(image)
        item = {"image": self.transform(image=image)["image"], "steering": torch.tensor(frame.steering, dtype=torch.float32)}
        if self.loss_weights is not None:
            item["weight"] = torch.tensor(self.loss_weights[i], dtype=torch.float32)
        return item


class SteeringDataModule(L.LightningDataModule):
    """train / val / test loaders of the steering frames, by the `steering` settings (width, height,
    batch_size, jitter, seed, balance: see offroad_path.steering.balance)."""

    def __init__(self, parts: dict[str, list[SteeringFrame]], s: DictConfig):
        super().__init__()
        self.parts, self.s = parts, s

    def _loader(self, part: str, train: bool) -> DataLoader:
        s = self.s
        transform = steering_transforms(s.width, s.height, s.jitter if train else 0.0, s.seed)
        sampling, loss = balance_weights(np.array([f.steering for f in self.parts[part]]), s.balance) if train else (None, None)
        dataset = SteeringDataset(self.parts[part], transform, loss)
        return DataLoader(dataset, s.batch_size, sampler=EpochSampler(len(dataset), s.seed, weights=sampling) if train else None)

    def train_dataloader(self) -> DataLoader:
        return self._loader("train", train=True)

    def val_dataloader(self) -> DataLoader:
        return self._loader("val", train=False)

    def test_dataloader(self) -> DataLoader:
        return self._loader("test", train=False)
