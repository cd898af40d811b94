"""Samples from a manifest as tensors for training: resized, augmented and normalised (files are read by
offroad_path.data.loading)."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import albumentations as A
import numpy as np
import torch
from albumentations.pytorch import ToTensorV2
from torch.utils.data import Dataset, Sampler

from offroad_path.data.loading import TARGETS, load_sample
from offroad_path.data.manifest import Sample


@dataclass(frozen=True)
class Augmentation:
    jitter: float  # brightness, contrast and saturation jitter
    min_scale: float  # the random resized crop keeps at least this fraction of the image


def transforms(width: int, height: int, augmentation: Augmentation | None = None, seed: int = 0) -> A.Compose:
    """Resize to the network's input (nearest for the target), with photometric jitter and a small
    random scale and crop when augmenting; flips are already in the data as mirrored copies."""
    ops: list = []
    if augmentation is not None:
        aspect = width / height
        jitter = augmentation.jitter
        ops += [
            A.RandomResizedCrop(size=(height, width), scale=(augmentation.min_scale, 1.0), ratio=(aspect * 0.9, aspect * 1.1)),
            A.ColorJitter(brightness=jitter, contrast=jitter, saturation=jitter, hue=0.02),
        ]
    else:
        ops.append(A.Resize(height, width))
    # Albumentations draws from its own generator, seeded here: unseeded, it reads OS entropy.
    return A.Compose([*ops, A.Normalize(), ToTensorV2()], seed=seed)


class EpochSampler(Sampler):
    """Shuffles with a generator seeded by (seed, epoch) and gives each sample its own augmentation
    seed: an epoch is the same whether a run went straight through or was resumed before it.
    Lightning calls set_epoch before each training epoch, as it does for a DistributedSampler.
    With `weights`, an epoch is `size` draws with replacement, each sample drawn in proportion to
    its weight (oversampling)."""

    def __init__(self, size: int, seed: int, shuffle: bool = True, weights: np.ndarray | None = None):
        self.size, self.seed, self.shuffle, self.epoch = size, seed, shuffle, 0
        self.weights = None if weights is None else torch.as_tensor(weights, dtype=torch.float64)

    def set_epoch(self, epoch: int) -> None:
        self.epoch = epoch

    def __len__(self) -> int:
        return self.size

    def __iter__(self) -> Iterator[tuple[int, int]]:
        generator = torch.Generator().manual_seed(self.seed * 1_000_003 + self.epoch)
        if self.weights is not None:
            order = torch.multinomial(self.weights, self.size, replacement=True, generator=generator)
        else:
            order = torch.randperm(self.size, generator=generator) if self.shuffle else torch.arange(self.size)
        seeds = torch.randint(0, 2**31 - 1, (self.size,), generator=generator)
        return iter(zip(order.tolist(), seeds.tolist(), strict=True))


class ManifestDataset(Dataset):
    """Samples of a manifest as tensors. Decoded samples (after mirroring) are kept in memory up to
    `cache_mb`, so that each PNG is decoded once per process, not once per epoch: decoding was 70 %
    of the laptop loader's time. The cached arrays are read-only; the transforms make new ones."""

    def __init__(self, samples: list[Sample], target: str, transform: A.Compose, cache_mb: float = 0):
        if target not in TARGETS:
            raise ValueError(f"unknown target {target!r}; valid: {', '.join(TARGETS)}")
        self.samples = samples
        self.target = target
        self.transform = transform
        self.cache_bytes = int(cache_mb * 2**20)
        self.cached_bytes = 0
        self.cache: dict[int, tuple[np.ndarray, np.ndarray]] = {}  # index -> decoded (image, mask), read-only arrays

    def __len__(self) -> int:
        return len(self.samples)

    def load(self, i: int) -> tuple[np.ndarray, np.ndarray]:
        """load_sample of sample i, from the cache when it is there."""
        if (hit := self.cache.get(i)) is not None:
            return hit
        image, mask = load_sample(self.samples[i], self.target)
        mask = mask.astype(np.uint8)  # class ids < 256: an eighth of int64's bytes in the cache
        size = image.nbytes + mask.nbytes
        if self.cached_bytes + size <= self.cache_bytes:
            image.flags.writeable = mask.flags.writeable = False
            self.cache[i] = (image, mask)
            self.cached_bytes += size
        return image, mask

    def __getitem__(self, key: int | tuple[int, int]) -> dict:
        """key: an index, or (index, seed) from EpochSampler: then the augmentation of this sample is
        drawn from `seed` alone, whatever the worker or the point a run was resumed from."""
        i, seed = key if isinstance(key, tuple) else (key, None)
        if seed is not None:
            self.transform.set_random_seed(seed)
        image, mask = self.load(i)
        out = self.transform(image=image, mask=mask)
        return {"image": out["image"], "target": out["mask"].long(), "index": torch.tensor(i)}
