"""Where one laptop training epoch's time goes, part by part, with the real pipeline's code and data.

    python benchmarks/training_profile.py [--model unet] [--split-dir data/split]

Needs the laptop pipeline's split (`dvc repro` or the split stage). Prints seconds per epoch for:
process start-up and imports of a training stage; PNG decoding of the training images and labels
alone; the training loader's first epoch (decoding into the cache) and a later one (from the
cache: augmentation, resizing, collation); forward and backward
passes on batches already in memory; the validation pass; one MLflow sample image; and the
number of epochs the laptop preset ran (from data/runs/<model>-none/seed0/metrics.json when present).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np
import torch
from hydra.utils import instantiate

from offroad_path.config import load_config


def timed(fn) -> tuple[float, object]:
    start = time.perf_counter()
    out = fn()
    return time.perf_counter() - start, out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--model", default="unet")
    parser.add_argument("--split-dir", default="data/split")
    args = parser.parse_args()

    startup = min(timed(lambda: subprocess.run([sys.executable, "-c", "import offroad_path.train"], check=True))[0] for _ in range(2))
    cfg = load_config(f"model={args.model}", f"data.split_dir={args.split_dir}", "mlflow.enabled=false")
    data = instantiate(cfg.data, target="path", seed=cfg.seed)
    data.setup()
    train = data.samples["train"]
    decode, _ = timed(lambda: [(cv2.imread(s.image), cv2.imread(s.label, cv2.IMREAD_GRAYSCALE)) for s in train])
    loader = data.train_dataloader()
    loader.sampler.set_epoch(0)
    first_load, batches = timed(lambda: list(loader))  # decodes every PNG once, into the cache (data.cache_mb)
    loader.sampler.set_epoch(1)
    load, _ = timed(lambda: list(loader))  # every later epoch: from the cache

    task = instantiate(cfg.model, num_classes=2, channels_last=cfg.train.channels_last, _convert_="all")
    optimiser = torch.optim.SGD(task.parameters(), lr=cfg.model.lr, momentum=cfg.model.momentum)
    task.train()

    def compute() -> None:
        for batch in batches:
            optimiser.zero_grad()
            loss = task.loss(task(batch["image"]), batch["target"])  # training_step without its logging
            loss.backward()
            optimiser.step()

    compute()  # warm-up: oneDNN picks its kernels on the first pass
    step, _ = timed(compute)
    task.eval()
    val_loader = data.val_dataloader()
    with torch.no_grad():
        validate, _ = timed(lambda: [task(b["image"]) for b in val_loader])

    import mlflow

    with tempfile.TemporaryDirectory() as tmp:
        mlflow.set_tracking_uri(f"sqlite:///{tmp}/mlflow.db")
        with mlflow.start_run():
            image = np.zeros((4 * 288, 2 * 512, 3), np.uint8)
            log_image, _ = timed(lambda: mlflow.log_image(image, "samples/epoch_000.png"))

    epochs = None
    metrics = Path("data/runs") / f"{args.model}-none" / "seed0" / "metrics.json"
    if metrics.is_file():
        epochs = json.loads(metrics.read_text()).get("epochs")
    total = load + step + validate + log_image
    print(f"{args.model}, laptop preset: {len(train)} training and {len(data.samples['val'])} validation samples, "
          f"{cfg.data.width} x {cfg.data.height} inputs, batch {cfg.data.batch_size}, torch threads {torch.get_num_threads()}")  # fmt: skip
    print(f"process start-up and imports of a training stage: {startup:.2f} s (once per stage)")
    print(f"PNG decoding of images and labels alone: {decode:.2f} s per epoch")
    print(f"training loader, first epoch (decoding every PNG into the cache): {first_load:.2f} s")
    for name, seconds in (("training loader, later epochs (cache, augment, resize, collate)", load), ("forward and backward", step),
                          ("validation pass", validate), ("MLflow sample image", log_image)):  # fmt: skip
        print(f"{name}: {seconds:.2f} s per epoch ({seconds / total:.0%})")
    if epochs is not None:
        print(f"the laptop run trained {epochs} epochs: about {epochs * total + startup:.0f} s of the stage")


if __name__ == "__main__":
    main()
