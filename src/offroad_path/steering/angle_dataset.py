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

from offroad_path.data.dataset import EpochSampler
from offroad_path.data.loading import read
from offroad_path.geometry.path import mirror
from offroad_path.steering.balance import balance_weights
from offroad_path.steering.frames import SteeringFrame


def steering_transforms(jitter: float, seed: int) -> A.Compose:
    """Photometric jitter only, since a crop or a shift would change the angle; then normalise.
    (The resize to PilotNet's input comes before, once per frame: SteeringDataset.)"""
    ops: list = []
    if jitter > 0:
        ops.append(A.ColorJitter(brightness=jitter, contrast=jitter, saturation=jitter, hue=0.02))
    return A.Compose([*ops, A.Normalize(), ToTensorV2()], seed=seed)


class SteeringDataset(Dataset):
    """Images and angles; with `loss_weights`, each item also carries its frame's weight in the loss.
    Each frame is decoded and resized to (width, height) once and kept, read-only, up to cache_mb
    (steering.cache_mb): at PilotNet's 256 x 136 a frame is 104 KB, and decoding its 512 x 288 PNG
    every epoch took a quarter of the epoch."""

    def __init__(
        self,
        frames: list[SteeringFrame],
        size: tuple[int, int],
        transform: A.Compose,
        loss_weights: np.ndarray | None = None,
        cache_mb: float = 0,
    ):
        self.frames = frames
        self.size = size  # (width, height)
        self.transform = transform
        self.loss_weights = loss_weights
        self.cache_bytes = int(cache_mb * 2**20)
        self.cache: dict[int, np.ndarray] = {}  # index -> resized frame, read-only

    def __len__(self) -> int:
        return len(self.frames)

    def resized(self, i: int) -> np.ndarray:
        """Frame i's RGB image at (width, height), mirrored where the frame says so."""
        if (image := self.cache.get(i)) is None:
            frame = self.frames[i]
            image = cv2.cvtColor(read(frame.image, cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
            if frame.mirrored:
                image = mirror(image)
            image = cv2.resize(image, self.size, interpolation=cv2.INTER_LINEAR)  # albumentations' Resize, exactly
            if (len(self.cache) + 1) * image.nbytes <= self.cache_bytes:
                image.flags.writeable = False
                self.cache[i] = image
        return image

    def __getitem__(self, key: int | tuple[int, int]) -> dict:
        """key: an index, or (index, augmentation seed) from EpochSampler (see offroad_path.data.dataset)."""
        i, seed = key if isinstance(key, tuple) else (key, None)
        if seed is not None:
            self.transform.set_random_seed(seed)
        frame = self.frames[i]
        item = {"image": self.transform(image=self.resized(i))["image"], "steering": torch.tensor(frame.steering, dtype=torch.float32)}
        if self.loss_weights is not None:
            item["weight"] = torch.tensor(self.loss_weights[i], dtype=torch.float32)
        return item


class SteeringDataModule(L.LightningDataModule):
    """train / val / test loaders of the steering frames, by the `steering` settings (width, height,
    batch_size, jitter, seed, balance: see offroad_path.steering.balance), each keeping up to
    cache_mb of resized frames."""

    def __init__(self, parts: dict[str, list[SteeringFrame]], s: DictConfig, seed: int):
        super().__init__()
        self.parts, self.s, self.seed = parts, s, seed

    def _loader(self, part: str, train: bool) -> DataLoader:
        s = self.s
        transform = steering_transforms(s.jitter if train else 0.0, self.seed)
        sampling, loss = balance_weights(np.array([f.steering for f in self.parts[part]]), s.balance) if train else (None, None)
        dataset = SteeringDataset(self.parts[part], (s.width, s.height), transform, loss, s.cache_mb)
        return DataLoader(dataset, s.batch_size, sampler=EpochSampler(len(dataset), self.seed, weights=sampling) if train else None)

    def train_dataloader(self) -> DataLoader:
        return self._loader("train", train=True)

    def val_dataloader(self) -> DataLoader:
        return self._loader("val", train=False)

    def test_dataloader(self) -> DataLoader:
        return self._loader("test", train=False)
