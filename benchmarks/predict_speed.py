"""predict's speed per architecture on this CPU: PyTorch against onnxruntime.

    python benchmarks/predict_speed.py [--width 0.25 --size 128x72] [--frames 50]

Builds each network at the laptop preset's width and input size (weights do not change the
speed), exports it with the same code as `python -m offroad_path.export`, and times one frame at
a time (batch 1, as predict runs) after a warm-up: the network alone, and the whole per-frame
work of predict (resize and normalise a 512 x 288 RGB image, run, resize the confidence back).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
import onnxruntime as ort
import torch

from offroad_path.export.onnx_export import PathConfidence, export_onnx
from offroad_path.inference.runners import PathModel
from offroad_path.models import MODELS, build_model
from offroad_path.report.tables import grid_head, grid_row


class Torch(PathModel):
    def __init__(self, net: torch.nn.Module, width: int, height: int):
        self.net, self.width, self.height = PathConfidence(net).eval(), width, height

    def run(self, batch: torch.Tensor) -> np.ndarray:
        with torch.no_grad():
            return self.net(batch).numpy()


class Onnx(PathModel):
    def __init__(self, path: Path, width: int, height: int):
        self.session, self.width, self.height = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"]), width, height

    def run(self, batch: torch.Tensor) -> np.ndarray:
        return self.session.run(None, {"image": batch.numpy()})[0]


def per_frame(fn, frames: int) -> float:
    for _ in range(3):
        fn()
    start = time.perf_counter()
    for _ in range(frames):
        fn()
    return (time.perf_counter() - start) / frames * 1000


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--width", type=float, default=0.25, help="channel multiplier (laptop preset: 0.25)")
    parser.add_argument("--size", default="128x72", help="network input WxH (laptop preset: 128x72)")
    parser.add_argument("--frames", type=int, default=50)
    args = parser.parse_args()
    w, h = (int(v) for v in args.size.split("x"))
    image = np.random.default_rng(0).integers(0, 256, (288, 512, 3), dtype=np.uint8)
    x = torch.randn(1, 3, h, w)
    print(f"torch threads {torch.get_num_threads()}, width {args.width}, input {w} x {h}, batch 1, ms per frame")
    print(grid_head(["network", "PyTorch network", "onnxruntime network", "ratio", "PyTorch predict frame", "onnxruntime predict frame"]))
    for name in sorted(MODELS):
        torch.manual_seed(0)
        net = build_model(name, 2, args.width).eval()
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / f"{name}.onnx"
            export_onnx(net, w, h, path)
            pt, ox = Torch(net, w, h), Onnx(path, w, h)
            net_pt = per_frame(lambda pt=pt: pt.run(x), args.frames)
            net_ox = per_frame(lambda ox=ox: ox.run(x), args.frames)
            frame_pt = per_frame(lambda pt=pt: pt([image]), args.frames)
            frame_ox = per_frame(lambda ox=ox: ox([image]), args.frames)
        print(grid_row([name, f"{net_pt:.2f}", f"{net_ox:.2f}", f"{net_pt / net_ox:.2f}x", f"{frame_pt:.2f}", f"{frame_ox:.2f}"]))


if __name__ == "__main__":
    main()
