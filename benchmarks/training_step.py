"""One SGD step of each network at the laptop size on this CPU: memory format, threads, torch.compile.

    python benchmarks/training_step.py [--width 0.25 --size 128x72 --batch 6] [--steps 20] [--compile]

Builds each network (random weights: they do not change the speed), and times forward, loss,
backward and an SGD step on a batch of random inputs after three warm-up steps: with torch's
default threads and with one; in NCHW and channels-last layout. With --compile, also the
channels-last model under torch.compile (inductor), with the first step's compile time.
"""

from __future__ import annotations

import argparse
import time

import torch
from common import step_ms

from offroad_path.models import MODELS, build_model
from offroad_path.report.tables import grid_head, grid_row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--width", type=float, default=0.25)
    parser.add_argument("--size", default="128x72")
    parser.add_argument("--batch", type=int, default=6)
    parser.add_argument("--steps", type=int, default=20)
    parser.add_argument("--compile", action="store_true")
    args = parser.parse_args()
    w, h = (int(v) for v in args.size.split("x"))
    default_threads = torch.get_num_threads()
    print(f"width {args.width}, input {w} x {h}, batch {args.batch}: ms per SGD step")
    print(grid_head(["network", "threads", "NCHW", "channels-last", "ratio", *(["compiled", "compile s"] if args.compile else [])]))
    for name in sorted(MODELS):
        for threads in (default_threads, 1):
            torch.set_num_threads(threads)
            torch.manual_seed(0)
            x, y = torch.randn(args.batch, 3, h, w), torch.randint(0, 2, (args.batch, h, w))
            nchw = step_ms(build_model(name, 2, args.width), x, y, args.steps)
            last = build_model(name, 2, args.width).to(memory_format=torch.channels_last)
            x_last = x.contiguous(memory_format=torch.channels_last)
            channels_last = step_ms(last, x_last, y, args.steps)
            row = [name, threads, f"{nchw:.1f}", f"{channels_last:.1f}", f"{nchw / channels_last:.2f}x"]
            if args.compile and threads == default_threads:
                compiled = torch.compile(last)
                start = time.perf_counter()
                compiled(x_last).sum().backward()
                compile_s = time.perf_counter() - start
                row += [f"{step_ms(compiled, x_last, y, args.steps):.1f}", f"{compile_s:.0f}"]
            print(grid_row(row), flush=True)
    torch.set_num_threads(default_threads)


if __name__ == "__main__":
    main()
