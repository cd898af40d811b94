"""Can three seeds train for the price of one on this CPU? A training step's achieved GFLOP/s against a
large convolution's, and three ways of training three seeds at once, each against three steps of one.

    python benchmarks/seeds_together.py [--models segnet fcn unet] [--steps 15]

For each network at the laptop size (width 0.25, 128 x 72, batch 6, 2 threads, the pipeline's):
- its forward and backward FLOPs (torch.utils.flop_counter), milliseconds per SGD step, GFLOP/s;
- the three seeds as one batch of 18 through one network (what batching the seeds would cost at
  best: the same FLOPs as three steps, in larger tensors);
- the three seeds stacked (torch.func.stack_module_state + vmap over functional_call, the
  ensembling recipe), which runs each convolution as one grouped convolution;
- one thread instead of two, and two one-thread processes side by side (two seeds at once);
- where a step's time goes: the profiler's self time by operator kind.
The reference for the CPU's reach: a 3x3 convolution of 128 to 128 channels at 128 x 128, batch 8,
forward and backward, on the same threads.
"""

from __future__ import annotations

import argparse
import copy
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import torch
import torch.nn.functional as F
from torch.func import functional_call, stack_module_state, vmap
from torch.profiler import ProfilerActivity, profile
from torch.utils.flop_counter import FlopCounterMode

from offroad_path.models import build_model
from offroad_path.report.tables import grid_head, grid_row

SEEDS = 3


def timed(step: Callable[[], None], steps: int) -> float:
    """Seconds per call after three warm-up calls."""
    for _ in range(3):
        step()
    start = time.perf_counter()
    for _ in range(steps):
        step()
    return (time.perf_counter() - start) / steps


def flops(step: Callable[[], None]) -> int:
    with FlopCounterMode(display=False) as counter:
        step()
    return counter.get_total_flops()


def sgd_step(net: torch.nn.Module, x: torch.Tensor, y: torch.Tensor) -> Callable[[], None]:
    optimiser = torch.optim.SGD(net.parameters(), lr=0.01, momentum=0.9)

    def step() -> None:
        optimiser.zero_grad()
        F.cross_entropy(net(x), y).backward()
        optimiser.step()

    return step


def stacked_step(name: str, x: torch.Tensor, y: torch.Tensor) -> Callable[[], None]:
    """Three seeds' networks as one: parameters stacked on a leading axis, vmap over them and over each seed's batch."""
    nets = [build_model(name, 2, 0.25) for _ in range(SEEDS)]
    params, buffers = stack_module_state(nets)
    skeleton = copy.deepcopy(nets[0]).to("meta")
    optimiser = torch.optim.SGD(list(params.values()), lr=0.01, momentum=0.9)
    xs, ys = x.expand(SEEDS, *x.shape).contiguous(), y.expand(SEEDS, *y.shape).contiguous()  # (S, N, 3, H, W), (S, N, H, W)

    def forward(p: dict, b: dict, images: torch.Tensor) -> torch.Tensor:
        return functional_call(skeleton, (p, b), (images,))

    def step() -> None:
        optimiser.zero_grad()
        scores = vmap(forward, randomness="different")(params, buffers, xs)  # (S, N, 2, H, W)
        F.cross_entropy(scores.flatten(0, 1), ys.flatten(0, 1)).backward()
        optimiser.step()

    return step


def time_split(step: Callable[[], None], steps: int) -> str:
    """Where a step's CPU time goes (torch.profiler, self time by operator kind)."""
    for _ in range(3):
        step()
    with profile(activities=[ProfilerActivity.CPU]) as prof:
        for _ in range(steps):
            step()
    kinds: dict[str, float] = {}
    for event in prof.key_averages():
        key = event.key
        kinds_of = (("conv", "convolution"), ("mkldnn", "convolution"), ("batch_norm", "batch norm"), ("pool", "pooling"))
        kind = next((kind for part, kind in kinds_of if part in key), "other")
        kinds[kind] = kinds.get(kind, 0.0) + event.self_cpu_time_total
    total = sum(kinds.values())
    return ", ".join(f"{kind} {seconds / total:.0%}" for kind, seconds in sorted(kinds.items(), key=lambda kv: -kv[1]))


def conv_reach(steps: int) -> float:
    """GFLOP/s of a large 3x3 convolution's forward and backward."""
    conv = torch.nn.Conv2d(128, 128, 3, padding=1)
    x = torch.randn(8, 128, 128, 128, requires_grad=True)

    def step() -> None:
        conv(x).sum().backward()

    return flops(step) / timed(step, steps) / 1e9


def one_thread_ms(name: str, steps: int, side_by_side: bool) -> float:
    """Milliseconds per step of one single-thread process, alone or beside another running the same."""
    code = (
        "import sys, torch, time, torch.nn.functional as F\ntorch.set_num_threads(1)\n"
        "sys.path.insert(0, sys.argv[1])\nfrom seeds_together import sgd_step, timed\nfrom offroad_path.models import build_model\n"
        f"torch.manual_seed(0)\nx, y = torch.randn(6, 3, 72, 128), torch.randint(0, 2, (6, 72, 128))\n"
        f"print(timed(sgd_step(build_model('{name}', 2, 0.25), x, y), {steps}) * 1000)\n"
    )
    here = str(Path(__file__).parent)
    runs = [subprocess.Popen([sys.executable, "-c", code, here], stdout=subprocess.PIPE, text=True) for _ in range(1 + side_by_side)]
    return max(float(run.communicate()[0]) for run in runs)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--models", nargs="+", default=["segnet", "fcn", "unet"])
    parser.add_argument("--steps", type=int, default=15)
    args = parser.parse_args()
    torch.set_num_threads(2)
    torch.manual_seed(0)
    reach = conv_reach(args.steps)
    print(f"a 3x3 convolution 128 -> 128 at 128 x 128, batch 8, forward and backward: {reach:.1f} GFLOP/s on 2 threads\n")
    print(grid_head(["network", "GFLOP per step", "ms per step", "GFLOP/s", "share of the convolution's", "3 seeds as a batch of 18",
                     "3 seeds stacked (vmap)", "1 thread", "2 one-thread processes side by side"]))  # fmt: skip
    for name in args.models:
        x, y = torch.randn(6, 3, 72, 128), torch.randint(0, 2, (6, 72, 128))
        step = sgd_step(build_model(name, 2, 0.25), x, y)
        work = flops(step) / 1e9
        one = timed(step, args.steps)
        batch = timed(sgd_step(build_model(name, 2, 0.25), x.repeat(SEEDS, 1, 1, 1), y.repeat(SEEDS, 1, 1)), args.steps)
        stacked = timed(stacked_step(name, x, y), args.steps)
        alone, beside = one_thread_ms(name, args.steps, False), one_thread_ms(name, args.steps, True)
        print(grid_row([name, f"{work:.2f}", f"{one * 1000:.0f}", f"{work / one:.1f}", f"{work / one / reach:.0%}",
                        f"{batch / one / SEEDS:.2f}x three steps", f"{stacked / one / SEEDS:.2f}x three steps", f"{alone:.0f} ms",
                        f"{beside:.0f} ms for two steps at once: {beside / 2 / (one * 1000):.2f}x a 2-thread step each"]))  # fmt: skip
    print("\nWhere a step's time goes (profiler self time):")
    for name in args.models:
        x, y = torch.randn(6, 3, 72, 128), torch.randint(0, 2, (6, 72, 128))
        print(f"- {name}: {time_split(sgd_step(build_model(name, 2, 0.25), x, y), 5)}")


if __name__ == "__main__":
    main()
