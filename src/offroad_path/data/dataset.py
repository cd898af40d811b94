"""Samples from a manifest as tensors: image, path label or semantic map, and stereo depth."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import albumentations as A
import cv2
import numpy as np
import torch
from albumentations.pytorch import ToTensorV2
from torch.utils.data import Dataset, Sampler

from offroad_path.data.manifest import Sample
from offroad_path.geometry.path import mirror
from offroad_path.geometry.stereo import decode_disparity, depth_from_disparity

TARGETS = ("path", "semantic")


def read(path: str, flags: int) -> np.ndarray:
    image = cv2.imread(path, flags)
    if image is None:
        raise FileNotFoundError(f"{path}: missing or not an image")
    return image


def load_sample(sample: Sample, target: str) -> tuple[np.ndarray, np.ndarray]:
    """(RGB image (H, W, 3) uint8, target (H, W) int64), mirrored when the sample says so.

    target 'path': 1 where the label says path; 'semantic': the world's class ids 0..7.
    """
    image = cv2.cvtColor(read(sample.image, cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
    if target == "path":
        mask = (read(sample.label, cv2.IMREAD_GRAYSCALE) > 0).astype(np.int64)
    elif target == "semantic":
        if not sample.semantic:
            raise ValueError(f"{sample.image}: no semantic map to pretrain on (real recordings have none)")
        mask = read(sample.semantic, cv2.IMREAD_UNCHANGED).astype(np.int64)
    else:
        raise ValueError(f"unknown target {target!r}; valid: {', '.join(TARGETS)}")
    if sample.mirrored:
        image, mask = mirror(image), mirror(mask)
    return np.ascontiguousarray(image), np.ascontiguousarray(mask)


def load_depth(sample: Sample) -> np.ndarray:
    """Stereo depth of the sample's frame (H, W) float32 metres, 0 unknown, mirrored with it."""
    depth = depth_from_disparity(decode_disparity(read(sample.disparity, cv2.IMREAD_UNCHANGED)), sample.fx, sample.baseline_m)
    return mirror(depth) if sample.mirrored else depth


def load_labels(samples: list[Sample]) -> np.ndarray:
    """Path labels (N, H, W) bool, mirrored where a sample says so."""
    labels = [read(s.label, cv2.IMREAD_GRAYSCALE) > 0 for s in samples]
    return np.stack([mirror(m) if s.mirrored else m for s, m in zip(samples, labels, strict=True)])


def load_maps(paths: list[str]) -> np.ndarray:
    """Confidence maps (N, H, W) float32 from .npy files (the train and postprocess stages' predictions)."""
    maps = []
    for path in paths:
        try:
            maps.append(np.load(path).astype(np.float32))
        except (OSError, ValueError) as e:
            raise ValueError(f"{path}: not a readable confidence map ({e})") from e
    return np.stack(maps)


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
        self._cache: dict[int, tuple[np.ndarray, np.ndarray]] = {}

    def __len__(self) -> int:
        return len(self.samples)

    def load(self, i: int) -> tuple[np.ndarray, np.ndarray]:
        """load_sample of sample i, from the cache when it is there."""
        if (hit := self._cache.get(i)) is not None:
            return hit
        image, mask = load_sample(self.samples[i], self.target)
        mask = mask.astype(np.uint8)  # class ids < 256: an eighth of int64's bytes in the cache
        size = image.nbytes + mask.nbytes
        if self.cached_bytes + size <= self.cache_bytes:
            image.flags.writeable = mask.flags.writeable = False
            self._cache[i] = (image, mask)
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
