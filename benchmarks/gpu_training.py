"""How the GPU preset's trainings can fill one GPU: images/s of a training step by batch size in one
process, and of several processes side by side (the design tools/parallel_repro.py runs).

    python benchmarks/gpu_training.py [--models segnet fcn unet] [--batches 32 128] [--processes 1 2 4]
                                      [--seconds 8] [--json FILE] [--device auto]

Compute only, as `experiment=gpu` trains: each network at full width on 256 x 144 inputs (--width,
--size), channels-last, bf16 autocast on a GPU (float32 on a CPU), AdamW and cross-entropy, on one
batch of random inputs (the values do not change the speed), for --seconds after three warm-up
steps. "Side by side": --processes copies of the first network's step at the first batch size, each
its own process (its own CUDA context, as parallel_repro's stages are), timed over the same window;
their images/s summed. Prints a Markdown table; --json writes the figures. On a CPU it runs, slowly,
as a rehearsal (use --width 0.125 --size 64x36 there).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import torch
import torch.nn.functional as F

from offroad_path.models import MODELS, build_model
from offroad_path.report.tables import grid_head, grid_row
from offroad_path.world.render_torch import torch_device


def images_per_s(model: str, batch: int, args: argparse.Namespace) -> float:
    """Training images per second of `model` at `batch` on args.device, over args.seconds after a warm-up."""
    torch.manual_seed(0)
    device, seconds = torch_device(args.device), args.seconds
    w, h = (int(v) for v in args.size.split("x"))
    net = build_model(model, 2, args.width).to(device, memory_format=torch.channels_last)
    x = torch.randn(batch, 3, h, w, device=device).contiguous(memory_format=torch.channels_last)
    y = torch.randint(0, 2, (batch, h, w), device=device)
    optimiser = torch.optim.AdamW(net.parameters(), lr=1e-3)
    cuda = device.type == "cuda"

    def step() -> None:
        optimiser.zero_grad(set_to_none=True)
        with torch.autocast(device.type, dtype=torch.bfloat16, enabled=cuda):
            loss = F.cross_entropy(net(x), y)
        loss.backward()
        optimiser.step()

    for _ in range(3):
        step()
    if cuda:
        torch.cuda.synchronize(device)
    steps, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        step()
        steps += 1
        if cuda and steps % 5 == 0:
            torch.cuda.synchronize(device)  # the queue kept short, so the clock measures the GPU's work
    if cuda:
        torch.cuda.synchronize(device)
    return steps * batch / (time.perf_counter() - start)


def side_by_side(args: argparse.Namespace, count: int) -> list[float]:
    """images/s of each of `count` processes running the first model's step at the first batch at once."""
    child = [sys.executable, __file__, "--child", "--models", args.models[0], "--batches", str(args.batches[0]),
             "--width", str(args.width), "--size", args.size, "--seconds", str(args.seconds), "--device", args.device]  # fmt: skip
    runs = [subprocess.Popen(child, stdout=subprocess.PIPE, text=True) for _ in range(count)]
    outputs = [run.communicate()[0] for run in runs]
    if any(run.returncode for run in runs):
        sys.exit(f"error: a side-by-side process failed (exits {[run.returncode for run in runs]})")
    return [float(out.split()[-1]) for out in outputs]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--models", nargs="+", default=sorted(MODELS))
    parser.add_argument("--batches", nargs="+", type=int, default=[32, 128])
    parser.add_argument("--processes", nargs="+", type=int, default=[1, 2, 4])
    parser.add_argument("--width", type=float, default=1.0)
    parser.add_argument("--size", default="256x144")
    parser.add_argument("--seconds", type=float, default=8.0)
    parser.add_argument("--device", default="auto", help="auto (the GPU where there is one), cpu, cuda, ...")
    parser.add_argument("--json", type=Path, help="write the figures here")
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    problems = [f"--models: unknown {m!r}; valid: {', '.join(sorted(MODELS))}" for m in args.models if m not in MODELS]
    counts = {"--batches": args.batches, "--processes": args.processes}
    problems += [f"{name}: {v} is not a positive count" for name, values in counts.items() for v in values if v < 1]
    if problems:
        parser.exit(2, f"error: {problems[0]}\n")
    device = torch_device(args.device)
    if args.child:
        print(images_per_s(args.models[0], args.batches[0], args))
        return
    name = torch.cuda.get_device_name(device) if device.type == "cuda" else f"CPU, {torch.get_num_threads()} threads"
    print(f"{name}; width {args.width}, input {args.size}: training images/s ({args.seconds:g} s each)")
    figures: dict = {"device": name, "width": args.width, "size": args.size, "one_process": {}, "side_by_side": {}}
    print(grid_head(["network", *(f"batch {b}" for b in args.batches)]))
    for model in args.models:
        rates = {b: images_per_s(model, b, args) for b in args.batches}
        figures["one_process"][model] = {str(b): round(r, 1) for b, r in rates.items()}
        print(grid_row([model, *(f"{r:.0f}" for r in rates.values())]), flush=True)
    print(f"\n{args.models[0]}, batch {args.batches[0]}, processes side by side: images/s each and summed")
    for count in args.processes:
        each = side_by_side(args, count)
        figures["side_by_side"][str(count)] = {"each": [round(r, 1) for r in each], "sum": round(sum(each), 1)}
        print(grid_row([count, f"{' '.join(f'{r:.0f}' for r in each)}", f"{sum(each):.0f}"]), flush=True)
    if args.json:
        args.json.write_text(json.dumps(figures, indent=2) + "\n")


if __name__ == "__main__":
    main()
