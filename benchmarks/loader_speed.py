"""Training loader throughput: images per second, with and without the decoded-sample cache, on
0, 1 and 2 worker processes, at the laptop input size and at the paper's.

    python benchmarks/loader_speed.py [--split-dir data/split] [--epochs 3]

Needs the laptop pipeline's split (`dvc repro split`). Runs the real data module (decode, mirror,
random resized crop, colour jitter, normalise, collate) over the training manifest for `--epochs`
epochs with persistent workers and reports the images/s of the first epoch (every PNG decoded)
and of the later ones (from the cache, where it is on). The model is not run: this is the rate
at which the data path could feed an accelerator.
"""

from __future__ import annotations

import argparse
import time

import torch
from hydra.utils import instantiate

from offroad_path.config import load_config
from offroad_path.report.tables import grid_head, grid_row

SIZES = {"laptop 128 x 72": (128, 72), "paper 512 x 288": (512, 288)}


def rates(split_dir: str, size: tuple[int, int], workers: int, cache_mb: float, epochs: int) -> tuple[float, float]:
    width, height = size
    cfg = load_config(f"data.split_dir={split_dir}", f"data.width={width}", f"data.height={height}", f"data.num_workers={workers}",
                      f"data.cache_mb={cache_mb}", "mlflow.enabled=false")  # fmt: skip
    data = instantiate(cfg.data, target="path", seed=0)
    data.setup()
    loader = data.train_dataloader()
    seconds = []
    for epoch in range(epochs):
        loader.sampler.set_epoch(epoch)
        start = time.perf_counter()
        count = sum(len(batch["image"]) for batch in loader)
        seconds.append(time.perf_counter() - start)
    return count / seconds[0], count / min(seconds[1:])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--split-dir", default="data/split")
    parser.add_argument("--epochs", type=int, default=3)
    args = parser.parse_args()
    torch.set_num_threads(1)  # collation only; the workers' own threads are set by the loader
    print(grid_head(["input", "workers", "cache", "first epoch, images/s", "later epochs, images/s"]))
    for name, size in SIZES.items():
        for workers in (0, 1, 2):
            for cache_mb in (0, 2048):
                first, later = rates(args.split_dir, size, workers, cache_mb, args.epochs)
                print(grid_row([name, workers, f"{'on' if cache_mb else 'off'}", f"{first:.0f}", f"{later:.0f}"]), flush=True)


if __name__ == "__main__":
    main()
