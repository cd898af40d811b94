"""How long each stage's command takes to answer --help, --cfg job, a misspelt key and a bad value
(before any torch or Lightning import). Wall time of the whole process, median of
--repeats runs; with several --src, the checkouts are timed in turn for each cell, so that load
on the machine falls on all of them alike.

    python benchmarks/refusal_time.py [--repeats 3] [--src PATH ...]

--src is the src/ folder of a checkout to run (PYTHONPATH), e.g. a `git worktree` of an older
commit; default: this one.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

from offroad_path.report.tables import grid_head, grid_row

STAGES = ["synthesize", "label", "split", "pretrain", "train", "postprocess", "evaluate", "train_steering", "drive", "predict", "export"]
CASES = {"--help": ["--help"], "--cfg job": ["--cfg", "job"], "bad key": ["bogus_key=1"], "bad value": ["threads=zero"]}


def seconds(stage: str, args: list[str], src: str) -> tuple[float, int]:
    env = {**os.environ, "PYTHONPATH": src}
    started = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", f"offroad_path.{stage}", *args], env=env, capture_output=True, check=False)
    return time.perf_counter() - started, done.returncode


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--src", nargs="+", default=[str(Path(__file__).resolve().parents[1] / "src")])
    a = parser.parse_args()
    header = [f"{case} ({i})" if len(a.src) > 1 else case for case in CASES for i in range(1, len(a.src) + 1)]
    print(grid_head(["stage", *header]))
    for stage in STAGES:
        cells = []
        for args in CASES.values():
            for src in a.src:
                runs = [seconds(stage, args, src) for _ in range(a.repeats)]
                cells.append(f"{statistics.median(s for s, _ in runs):.1f}")
        print(grid_row([stage, *cells]), flush=True)
    for i, src in enumerate(a.src, start=1):
        print(f"({i}) {src}")


if __name__ == "__main__":
    main()
