"""How long a killed label stage's worker processes outlive it.

    python benchmarks/orphan_workers.py [--recordings data/synthetic] [--delays 0.3 1 2] [--busy 0 6]

Starts `python -m offroad_path.label` with 2 workers on the recordings into a temporary folder,
SIGKILLs it DELAY seconds after its temporary output folder appears (its workers are then starting
or at work), and times how long any process it started (tagged by an environment variable, which
workers inherit) stays alive. Each case also runs beside BUSY processes that spin a core each.

Workers die with their parent by the kernel's parent-death signal; one still starting when the
parent died used to take its first job from its pipe and do it (utils/parallel.py).
"""

from __future__ import annotations

import argparse
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import uuid
from pathlib import Path

from common import tagged_processes


def orphan_lifetime(recordings: Path, delay_s: float, busy: int) -> float:
    spinners = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(busy)]
    out = Path(tempfile.mkdtemp(prefix="orphans-"))
    try:
        tag = uuid.uuid4().hex
        command = [sys.executable, "-m", "offroad_path.label", f"label.in_dir={recordings}", f"label.out_dir={out / 'labels'}",
                   f"label.metrics_path={out / 'm.json'}", "label.workers=2", "mlflow.enabled=false"]  # fmt: skip
        stage = subprocess.Popen(command, env={**os.environ, "OFFROAD_TEST_TAG": tag}, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        while not list(out.glob(".labels.tmp-*")):
            if stage.poll() is not None:
                raise SystemExit(f"error: the label stage ended before its temporary folder appeared (exit {stage.returncode})")
            time.sleep(0.01)
        time.sleep(delay_s)
        stage.send_signal(signal.SIGKILL)
        stage.wait()
        killed = time.monotonic()
        while tagged_processes(tag):
            time.sleep(0.05)
        return time.monotonic() - killed
    finally:
        for spinner in spinners:
            spinner.kill()
        shutil.rmtree(out, ignore_errors=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--recordings", type=Path, default=Path("data/synthetic"))
    parser.add_argument("--delays", type=float, nargs="+", default=[0.3, 1.0, 2.0])
    parser.add_argument("--busy", type=int, nargs="+", default=[0, 6])
    args = parser.parse_args()
    print("busy processes | kill after the temporary folder, s | workers outlived the stage, s")
    for busy in args.busy:
        for delay in args.delays:
            print(f"{busy} | {delay:.1f} | {orphan_lifetime(args.recordings.resolve(), delay, busy):.1f}", flush=True)


if __name__ == "__main__":
    main()
