"""`dvc repro` stage by stage: seconds from each stage's start to the next one's (DVC's hashing and
caching of a stage's outputs count in that stage), idle or beside another CPU-heavy process.

    python benchmarks/pipeline_time.py [--beside-load] [--log OUT] [--json metrics/pipeline_time.json] [-- <dvc repro arguments>]
    python benchmarks/pipeline_time.py --parse LOG [LOG ...] [--mlflow-db mlflow.db] [--json metrics/pipeline_time.json]

Run in a checkout (a fresh clone for "from nothing": no data/, no .dvc/cache). Every line of
`dvc repro`'s output is stamped with the epoch second it came (written to --log), and the table
groups a matrix stage's runs (train_scratch@unet-0 ...) under its name. `--beside-load` runs a
second process that multiplies matrices on torch's default threads all along, as another training
job would. `--parse` prints the table of a log written before (of several, a repro stopped and
resumed: stitched end to start, the time between them not counted). With the run's MLflow store
(`--mlflow-db`, the default mlflow.db when it exists), each stage that logs a run is split into its
start-up (the process's imports, Hydra, data set-up and MLflow's store, until its run starts), the
run itself, and its end (the run's end to the next stage's start: process exit, DVC hashing and
caching its outputs). `--json` writes the machine, `total_s` and each stage's seconds, which the
generated results (offroad_path.report.readme) state as the committed run's time. Each
stage's peak resident memory is the largest high-water mark (VmHWM) of any
process under `dvc repro` while the stage runs, read from /proc every 0.2 s (a rise in a process's
last 0.2 s can be missed); it is written into the log as `#peak` lines.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import re
import shutil
import sqlite3
import subprocess
import sys
import threading
import time
from pathlib import Path

from common import BUSY, descendants, high_water_kb

STAGE = re.compile(r"^Running stage '([^']+)'")
PEAK = re.compile(r"^#peak (\S+) (\d+)$")


class PeakMemory(threading.Thread):
    """Polls the peak resident memory of every process under `root`, per stage (`stage` set from outside)."""

    def __init__(self, root: int):
        super().__init__(daemon=True)
        self.root, self.stage, self.peaks, self.done = root, "", {}, threading.Event()

    def run(self) -> None:
        while not self.done.wait(0.2):
            if self.stage:
                top = max(high_water_kb(pid) for pid in [self.root, *descendants(self.root)])
                self.peaks[self.stage] = max(self.peaks.get(self.stage, 0), top)


def stage_seconds(lines: list[tuple[float, str]]) -> list[tuple[str, float]]:
    """(stage, seconds) in the order run: from its 'Running stage' line to the next one or the end."""
    lines = [(when, text) for when, text in lines if not text.startswith("#peak")]
    starts = [(when, m.group(1)) for when, text in lines if (m := STAGE.match(text))]
    ends = [when for when, _ in starts[1:]] + [lines[-1][0]]
    return [(name, end - start) for (start, name), end in zip(starts, ends, strict=True)]


def table(lines: list[tuple[float, str]]) -> str:
    grouped: dict[str, list[float]] = {}
    peaks: dict[str, int] = {}
    for _, text in lines:
        if m := PEAK.match(text):
            peaks[m.group(1).split("@")[0]] = max(peaks.get(m.group(1).split("@")[0], 0), int(m.group(2)))
    for name, seconds in stage_seconds(lines):
        grouped.setdefault(name.split("@")[0], []).append(seconds)
    rows = ["| stage | runs | seconds | each | peak resident memory (largest process) |", "| --- | --- | --- | --- | --- |"]
    for name, each in grouped.items():
        peak = f"{peaks[name] / 1024**2:.2f} GB" if name in peaks else ""
        rows.append(f"| {name} | {len(each)} | {sum(each):.0f} | {' + '.join(f'{s:.0f}' for s in each)} | {peak} |")
    total = lines[-1][0] - lines[0][0]
    rows.append(f"| **total** | | **{total:.0f} ({int(total // 60)} min {total % 60:.0f} s)** | |")
    return "\n".join(rows)


def overheads(lines: list[tuple[float, str]], db: Path) -> str:
    """Per stage with an MLflow run inside its window: seconds before the run, of the run, after it."""
    with sqlite3.connect(db) as connection:
        runs = connection.execute("select start_time / 1000.0, end_time / 1000.0 from runs where end_time is not null").fetchall()
    rows = ["| stage | start-up | run | end |", "| --- | --- | --- | --- |"]
    totals = [0.0, 0.0, 0.0]
    clock = lines[0][0]
    for name, seconds in stage_seconds(lines):
        start = next(when for when, text in lines if when >= clock and text.startswith(f"Running stage '{name}'"))
        clock, end = start, start + seconds
        inside = [(a, b) for a, b in runs if start <= a <= end]
        if len(inside) != 1:
            continue
        parts = (inside[0][0] - start, inside[0][1] - inside[0][0], end - inside[0][1])
        totals = [t + p for t, p in zip(totals, parts, strict=True)]
        rows.append(f"| {name} | {parts[0]:.1f} | {parts[1]:.1f} | {parts[2]:.1f} |")
    rows.append(f"| **sum** | **{totals[0]:.0f}** | **{totals[1]:.0f}** | **{totals[2]:.0f}** |")
    return "\n".join(rows)


def machine() -> str:
    """The CPU's model and core count, and the GPUs' names where nvidia-smi lists any."""
    model = platform.processor() or platform.machine()
    if Path("/proc/cpuinfo").is_file():
        names = [line.split(":", 1)[1].strip() for line in Path("/proc/cpuinfo").read_text().splitlines() if line.startswith("model name")]
        model = names[0] if names else model
    found = f"{os.cpu_count()}-core {model}"
    if shutil.which("nvidia-smi"):
        gpus = subprocess.run(["nvidia-smi", "--query-gpu=name", "--format=csv,noheader"], capture_output=True, text=True, check=False)
        if gpus.returncode == 0 and gpus.stdout.strip():
            found += ", " + " + ".join(gpus.stdout.split("\n")[:-1])
    return found


def write_json(path: Path, lines: list[tuple[float, str]], sittings: int = 1) -> None:
    """`{"machine", "total_s", "stages": {stage: seconds}}` of one repro, for the generated results;
    `sittings` when its logs were stitched (a repro stopped and resumed)."""
    timed = {"machine": machine(), "total_s": round(lines[-1][0] - lines[0][0], 1)} | ({"sittings": sittings} if sittings > 1 else {})
    timed["stages"] = {name: round(seconds, 1) for name, seconds in stage_seconds(lines)}
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(timed, indent=2) + "\n")


def read_log(*paths: Path) -> list[tuple[float, str]]:
    """A --log's stamped lines; several logs (one repro stopped and resumed) stitched end to start:
    each later log's clock shifted to begin where the one before ended, the time between not counted."""
    lines: list[tuple[float, str]] = []
    for path in paths:
        found = []
        for line in path.read_text().splitlines():
            stamp, _, text = line.partition(" ")
            found.append((float(stamp), text))
        shift = lines[-1][0] - found[0][0] if lines and found else 0.0
        lines += [(when + shift, text) for when, text in found]
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--beside-load", action="store_true", help="run a torch matrix-multiplying process beside it")
    parser.add_argument("--log", type=Path, default=Path("pipeline_time.log"))
    parser.add_argument("--parse", type=Path, nargs="+", help="only print the table of earlier --log files (several: stitched)")
    parser.add_argument("--mlflow-db", type=Path, default=Path("mlflow.db"), help="the run's MLflow store, for start-up and end times")
    parser.add_argument("--json", type=Path, help="also write the machine, total_s and each stage's seconds here")
    parser.add_argument("dvc_args", nargs="*", help="arguments of dvc repro, after --")
    args = parser.parse_args()
    if args.parse:
        lines = read_log(*args.parse)
        if args.json:
            write_json(args.json, lines, len(args.parse))
        print(table(lines))
        if args.mlflow_db.is_file():
            print("\n" + overheads(lines, args.mlflow_db))
        return
    busy = subprocess.Popen([sys.executable, "-c", BUSY]) if args.beside_load else None
    lines = [(time.time(), "start")]
    try:
        with subprocess.Popen(["dvc", "repro", *args.dvc_args], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True) as dvc, \
             args.log.open("w") as log:  # fmt: skip
            log.write(f"{lines[0][0]:.1f} start\n")
            memory = PeakMemory(dvc.pid)
            memory.start()
            for text in dvc.stdout:
                lines.append((time.time(), text.rstrip("\n")))
                log.write(f"{lines[-1][0]:.1f} {lines[-1][1]}\n")
                log.flush()
                if m := STAGE.match(lines[-1][1]):
                    memory.stage = m.group(1)
            memory.done.set()
            memory.join()
        ended = time.time()
        lines += [(ended, f"#peak {stage} {kb}") for stage, kb in memory.peaks.items()] + [(ended, "end")]
        with args.log.open("a") as log:
            log.writelines(f"{ended:.1f} {text}\n" for _, text in lines[-len(memory.peaks) - 1 :])
    finally:
        if busy:
            busy.kill()
    if dvc.returncode:
        sys.exit(f"dvc repro failed ({dvc.returncode}); its output: {args.log}")
    if args.json:
        write_json(args.json, lines)
    print(table(lines))
    if args.mlflow_db.is_file():
        print("\n" + overheads(lines, args.mlflow_db))


if __name__ == "__main__":
    main()
