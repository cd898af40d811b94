"""The LightningDataModule over the split stage's manifests."""

from __future__ import annotations

from pathlib import Path

import lightning as L
from torch.utils.data import DataLoader

from offroad_path.data.dataset import Augmentation, EpochSampler, ManifestDataset, transforms
from offroad_path.data.manifest import Sample, read_manifest
from offroad_path.errors import InputError


class OffroadDataModule(L.LightningDataModule):
    """train / val / test loaders for target 'path' (2 classes) or 'semantic' (8 classes)."""

    # Each argument is a hyper-parameter saved flat in the checkpoint (predict reads the input size
    # from it); conf/data holds them: hydra.utils.instantiate(cfg.data, target=..., seed=...).
    def __init__(  # noqa: PLR0913
        self,
        *,
        split_dir: str,
        target: str,
        width: int,
        height: int,
        batch_size: int,
        num_workers: int,
        pin_memory: bool,
        augment: bool,
        jitter: float,
        min_scale: float,
        seed: int,
        cache_mb: float = 0,
    ):
        super().__init__()
        self.save_hyperparameters(logger=False)  # the run logs the whole resolved config instead
        self.split_dir = Path(split_dir)
        self.samples: dict[str, list[Sample]] = {}

    def setup(self, stage: str | None = None) -> None:
        """Read the manifests and check that every file they list exists, before any training."""
        for name in ("train", "val", "test"):
            if name not in self.samples:
                self.samples[name] = read_manifest(self.split_dir / f"{name}.csv", check_files=True)
        if not self.samples["train"]:  # a split of too little driving: nothing to learn from, a run that would report nothing
            raise InputError(
                self.split_dir / "train.csv", "lists no training sample (too little driving for the split's blocks: see split.block_m)"
            )

    def _loader(self, name: str, train: bool) -> DataLoader:
        hp = self.hparams
        augmentation = Augmentation(hp.jitter, hp.min_scale) if train and hp.augment else None
        transform = transforms(hp.width, hp.height, augmentation, seed=hp.seed)
        dataset = ManifestDataset(self.samples[name], hp.target, transform, hp.cache_mb)
        sampler = EpochSampler(len(dataset), hp.seed) if train else None
        return DataLoader(
            dataset,
            batch_size=hp.batch_size,
            sampler=sampler,
            drop_last=train and len(dataset) > hp.batch_size,
            num_workers=hp.num_workers,
            pin_memory=hp.pin_memory,
            persistent_workers=hp.num_workers > 0,
        )

    def train_dataloader(self) -> DataLoader:
        return self._loader("train", train=True)

    def val_dataloader(self) -> DataLoader:
        return self._loader("val", train=False)

    def test_dataloader(self) -> DataLoader:
        return self._loader("test", train=False)
