"""How long each stage's command takes to answer --help, --cfg job, a misspelt key and a bad value
(issue 40: before any torch or Lightning import). Wall time of the whole process, median of
--repeats runs, one stage after another.

    python benchmarks/refusal_time.py [--repeats 3] [--src PATH]

--src runs another checkout's code (PYTHONPATH=<its src>), e.g. a `git worktree` of an older commit,
so that both are measured back to back on the same machine.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time

STAGES = ["synthesize", "label", "split", "pretrain", "train", "postprocess", "evaluate", "train_steering", "drive", "predict", "export"]
CASES = {"--help": ["--help"], "--cfg job": ["--cfg", "job"], "bad key": ["bogus_key=1"], "bad value": ["threads=zero"]}


def seconds(stage: str, args: list[str], env: dict) -> tuple[float, int]:
    started = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", f"offroad_path.{stage}", *args], env=env, capture_output=True, check=False)
    return time.perf_counter() - started, done.returncode


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--src", help="the src/ folder of another checkout")
    a = parser.parse_args()
    env = dict(os.environ)
    if a.src:
        env["PYTHONPATH"] = a.src
    print("| stage | " + " | ".join(CASES) + " |")
    print("| --- |" + " --- |" * len(CASES))
    for stage in STAGES:
        cells = []
        for args in CASES.values():
            runs = [seconds(stage, args, env) for _ in range(a.repeats)]
            cells.append(f"{statistics.median(s for s, _ in runs):.1f} (rc {runs[0][1]})")
        print(f"| {stage} | " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
