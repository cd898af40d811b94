"""What the speed work must not change: the decoded-sample cache gives the loader's exact tensors,
and the thread settings mean what they say."""

from __future__ import annotations

import os
import subprocess
import sys
import time

import cv2
import pytest
import torch
from hydra.utils import instantiate
from torch.utils.data import DataLoader

from offroad_path.utils.threads import busy_cores, is_thread_setting, set_threads, thread_count, usable_cores


def epochs_of(split_dir, compose_config, cache_mb: float, epochs: int = 2) -> tuple[list[dict], DataLoader]:
    cfg = compose_config(f"data.split_dir={split_dir}", "data.width=64", "data.height=48", f"data.cache_mb={cache_mb}")
    data = instantiate(cfg.data, target="path", seed=3)
    data.setup()
    loader = data.train_dataloader()
    batches = []
    for epoch in range(epochs):
        loader.sampler.set_epoch(epoch)
        batches += list(loader)
    return batches, loader


def test_cached_samples_give_the_same_tensors_epoch_after_epoch(split_dir, compose_config):
    plain, _ = epochs_of(split_dir, compose_config, cache_mb=0)
    cached, loader = epochs_of(split_dir, compose_config, cache_mb=1024)
    assert len(plain) == len(cached) > 0
    for a, b in zip(plain, cached, strict=True):
        assert torch.equal(a["image"], b["image"]) and torch.equal(a["target"], b["target"]) and torch.equal(a["index"], b["index"])
        assert b["target"].dtype == torch.int64
    dataset = loader.dataset
    assert len(dataset.cache) == len(dataset)  # the first epoch decoded each sample once
    image, mask = dataset.cache[0]
    assert not image.flags.writeable and not mask.flags.writeable  # a transform that wrote into them would raise


def test_the_cache_stops_at_its_budget(split_dir, compose_config):
    _, loader = epochs_of(split_dir, compose_config, cache_mb=0, epochs=1)
    assert loader.dataset.cache == {}
    one_sample = sum(a.nbytes for a in loader.dataset.load(0))
    _, loader = epochs_of(split_dir, compose_config, cache_mb=1.5 * one_sample / 2**20, epochs=1)
    assert len(loader.dataset.cache) == 1 and loader.dataset.cached_bytes == one_sample


@pytest.mark.parametrize(("value", "valid"), [("all", True), ("free", True), (1, True), ("3", True), (0, False), ("-1", False),
                                              ("half", False), (1.5, False)])  # fmt: skip
def test_thread_settings(value, valid):
    assert is_thread_setting(value) is valid


def test_thread_counts():
    cores = usable_cores()
    assert thread_count("all") == cores == len(os.sched_getaffinity(0))
    assert thread_count(3) == 3
    assert 1 <= thread_count("free") <= cores
    with pytest.raises(ValueError, match="threads='half'"):
        thread_count("half")


def test_busy_cores_sees_a_busy_process():
    spinner = subprocess.Popen([sys.executable, "-c", "import time\nend = time.time() + 3\nwhile time.time() < end: pass"])
    try:
        time.sleep(0.5)  # started and spinning
        assert busy_cores(0.5) >= 0.7  # at least the spinner's core (other tests may add theirs)
    finally:
        spinner.kill()
        spinner.wait()


def test_set_threads_sets_torch_and_opencv():  # conftest's restore_threads puts them back
    assert set_threads(1) == 1
    assert torch.get_num_threads() == 1 and cv2.getNumThreads() == 1 and os.environ["OMP_NUM_THREADS"] == "1"


def test_steering_frames_resized_once_give_the_same_tensors(compose_config, labelled_drive, split_dir):
    from offroad_path.steering.angle_dataset import SteeringDataModule
    from offroad_path.steering.frames import steering_split

    parts = steering_split(labelled_drive, split_dir, block_m=4, guard_m=3, mirror=True)
    plain, cached = (SteeringDataModule(parts, compose_config(f"steering.cache_mb={mb}").steering, seed=0).train_dataloader().dataset
                     for mb in (0, 64))  # fmt: skip
    keys = [(i, 1000 + i) for i in range(len(plain))] * 2  # every frame twice: decoded, then from the cache
    for key in keys:
        a, b = plain[key], cached[key]
        assert torch.equal(a["image"], b["image"]) and a["steering"] == b["steering"]
    assert len(cached.cache) == len(cached) and plain.cache == {}
    # The same tensors as the transform that resized inside albumentations (before this cache).
    import albumentations as A
    from albumentations.pytorch import ToTensorV2

    s = compose_config().steering
    whole = A.Compose([A.Resize(s.height, s.width), A.ColorJitter(s.jitter, s.jitter, s.jitter, hue=0.02), A.Normalize(), ToTensorV2()],
                      seed=0)  # fmt: skip
    frame = parts["train"][3]
    image = cv2.cvtColor(cv2.imread(frame.image), cv2.COLOR_BGR2RGB)
    whole.set_random_seed(77)
    assert torch.equal(whole(image=image[:, ::-1] if frame.mirrored else image)["image"], cached[(3, 77)]["image"])
