"""How OpenMP's wait policy changes a training step alone, beside a twin and beside a busy process.

    python benchmarks/wait_policy.py [--model segnet] [--steps 40] [--threads 2]

Each case starts a fresh process (OpenMP reads its settings when torch loads) that times SGD steps
of one network at the laptop size on --threads threads (benchmarks/training_step.py): with
OpenMP's default (threads spin a while before they sleep), a shorter spin, and PASSIVE (they
sleep at once; the test suite's setting, and the README's advice beside other work):

- alone, on an idle machine;
- two such processes at once (two stages, or a stage beside the test suite);
- beside a process multiplying matrices on torch's default threads and policy (someone else's job).

The last column is a hash of the weights after the warm-up and timed steps: the same in every
case of a row, and the same across rows, since waiting does not change the arithmetic.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

from common import BUSY

from offroad_path.report.tables import grid_head, grid_row

HERE = Path(__file__).resolve().parent
STEPS = """
import hashlib, sys, torch
sys.path.insert(0, {here!r})
from common import step_ms
from offroad_path.config import load_config
from offroad_path.models import build_model
torch.set_num_threads({threads})
torch.manual_seed(0)
x, y = torch.randn(6, 3, 72, 128), torch.randint(0, 2, (6, 72, 128))
net = build_model({model!r}, 2, 0.25)
if load_config("model={model}").model.channels_last:  # the layout its train stage uses
    net, x = net.to(memory_format=torch.channels_last), x.contiguous(memory_format=torch.channels_last)
print(step_ms(net, x, y, {steps}))
print(hashlib.sha256(b"".join(p.detach().numpy().tobytes() for p in net.parameters())).hexdigest()[:12])
"""


OPENMP = ("OMP_WAIT_POLICY", "GOMP_SPINCOUNT")
POLICIES = {
    "default (spin)": {},
    "GOMP_SPINCOUNT=10000": {"GOMP_SPINCOUNT": "10000"},
    "OMP_WAIT_POLICY=PASSIVE": {"OMP_WAIT_POLICY": "PASSIVE"},
}


def clean_env() -> dict[str, str]:
    return {k: v for k, v in os.environ.items() if k not in OPENMP}


def start(policy: dict[str, str], args: argparse.Namespace) -> subprocess.Popen:
    env = clean_env() | policy
    code = STEPS.format(here=str(HERE), threads=args.threads, model=args.model, steps=args.steps)
    return subprocess.Popen([sys.executable, "-c", code], env=env, stdout=subprocess.PIPE, text=True)


def ms(process: subprocess.Popen) -> tuple[float, str]:
    """(ms per step, SHA-256 of the weights after every step) of a process from start()."""
    out, _ = process.communicate()
    step, weights = out.strip().splitlines()[-2:]
    return float(step), weights


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--model", default="segnet")
    parser.add_argument("--steps", type=int, default=40)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--policies", default=",".join(POLICIES), help="comma-separated names of POLICIES")
    args = parser.parse_args()
    print(f"{args.model}, 128 x 72, batch 6, {args.threads} threads: ms per SGD step ({os.cpu_count()} cores)")
    print(grid_head(["OpenMP setting", "alone", "two at once (each)", "beside a busy torch process", "weights after the steps (SHA-256)"]))
    for name in args.policies.split(","):
        policy = POLICIES[name]
        alone, weights = ms(start(policy, args))
        twins = [start(policy, args) for _ in range(2)]
        pair = [ms(p) for p in twins]
        busy = subprocess.Popen([sys.executable, "-c", BUSY], env=clean_env())
        try:
            time.sleep(3)  # let it reach full speed
            beside = ms(start(policy, args))
        finally:
            busy.kill()
            busy.wait()
        runs = {weights, beside[1], *(w for _, w in pair)}
        same = weights if len(runs) == 1 else "differ: " + ", ".join(sorted(runs))
        print(grid_row([name, f"{alone:.1f}", f"{max(t for t, _ in pair):.1f}", f"{beside[0]:.1f}", same]), flush=True)


if __name__ == "__main__":
    main()
