"""Peak memory of each stage at a preset's sizes, on fewer drives than the preset renders.

    python benchmarks/stage_memory.py WORK_DIR [--stages ...] -- experiment=laptop_reference synthesize.sequences=4 ...

Runs the pipeline's stages one after another as `python -m offroad_path.<stage> paths.root=WORK_DIR
mlflow.enabled=false <overrides>` (one seed, one network of each kind; see STAGES) and prints, per
stage: its seconds, the peak resident memory of its largest process (VmHWM), the peak of the
proportional set size summed over all its processes (each shared page counted once: a loader
worker's forked copy of its parent is not counted twice) (the figure that matters for the stages with one
worker per core: synthesize, label, the loaders, drive), and where `nvidia-smi` answers, the
peak GPU memory in use minus what was in use before the stage. Both are polled every 0.2 s from /proc
(a rise shorter than that can be missed). What scales with the count of drives (the label stage's
workers each hold one drive; the training cache holds at most `data.cache_mb` per loader) is
described beside the table it gives in benchmarks/README.md ("Memory per stage at the presets' sizes").
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import threading
import time
from pathlib import Path

from common import descendants, high_water_kb

# (name, module, its own arguments): the stages of dvc.yaml, one run of each kind.
STAGES = {
    "synthesize": ("synthesize", []),
    "label": ("label", []),
    "split": ("split", []),
    "pretrain": ("pretrain", ["model=unet"]),
    "train segnet": ("train", ["model=segnet", "pretraining=none", "seed=0"]),
    "train fcn": ("train", ["model=fcn", "pretraining=none", "seed=0"]),
    "train unet": ("train", ["model=unet", "pretraining=segmentation", "seed=0"]),
    "postprocess": ("postprocess", ["model=unet", "pretraining=segmentation", "seed=0"]),
    "train_steering": ("train_steering", ["seed=0"]),
    "evaluate": ("evaluate", ["evaluate.seeds=[0]", "evaluate.runs=[unet-segmentation]", "evaluate.temporal.enabled=false"]),
    "evaluate_all": ("evaluate", []),  # every run and seed evaluate.runs and evaluate.seeds list (a whole pipeline's)
}


def proportional_kb(pid: int) -> int:
    """The process's proportional set size: its resident pages, each shared page divided among its sharers."""
    try:
        return next(int(line.split()[1]) for line in Path(f"/proc/{pid}/smaps_rollup").read_text().splitlines() if line.startswith("Pss:"))
    except (OSError, StopIteration):
        return 0


def gpu_used_mb() -> int | None:
    """GPU memory in use on the first device (every process's), or None without nvidia-smi."""
    if not shutil.which("nvidia-smi"):
        return None
    out = subprocess.run(["nvidia-smi", "--query-gpu=memory.used", "--format=csv,noheader,nounits"], capture_output=True, text=True)
    return int(out.stdout.split()[0]) if out.returncode == 0 and out.stdout.strip() else None


class Peaks(threading.Thread):
    """Largest process's VmHWM, the tree's summed PSS and the GPU's memory in use, polled until `done`."""

    def __init__(self, root: int):
        super().__init__(daemon=True)
        self.root, self.largest_kb, self.summed_kb, self.gpu_mb, self.done = root, 0, 0, None, threading.Event()

    def run(self) -> None:
        while not self.done.wait(0.2):
            pids = [self.root, *descendants(self.root)]
            self.largest_kb = max(self.largest_kb, *(high_water_kb(pid) for pid in pids))
            self.summed_kb = max(self.summed_kb, sum(proportional_kb(pid) for pid in pids))
            if (used := gpu_used_mb()) is not None:
                self.gpu_mb = max(self.gpu_mb or 0, used)


def run_stage(module: str, arguments: list[str], log: Path) -> tuple[float, Peaks, int | None]:
    before = gpu_used_mb()
    start = time.time()
    with log.open("a") as out:
        out.write(f"\n$ python -m offroad_path.{module} {' '.join(arguments)}\n")
        out.flush()
        process = subprocess.Popen([sys.executable, "-m", f"offroad_path.{module}", *arguments], stdout=out, stderr=subprocess.STDOUT)
        peaks = Peaks(process.pid)
        peaks.start()
        process.wait()
    peaks.done.set()
    peaks.join()
    if process.returncode:
        sys.exit(f"offroad_path.{module} failed ({process.returncode}); its output: {log}")
    return time.time() - start, peaks, before


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("work_dir", type=Path, help="paths.root of the run (made; every output goes under it)")
    parser.add_argument("--stages", nargs="+", choices=list(STAGES), default=list(STAGES)[:-1])
    parser.add_argument("overrides", nargs="*", help="Hydra overrides of every stage, after --")
    args = parser.parse_args()
    args.work_dir.mkdir(parents=True, exist_ok=True)
    log = args.work_dir / "stage_memory.log"
    common = [f"paths.root={args.work_dir.resolve()}", "mlflow.enabled=false", *args.overrides]
    rows = ["| stage | seconds | largest process | all its processes | GPU memory in use |", "| --- | --- | --- | --- | --- |"]
    for name in args.stages:
        module, own = STAGES[name]
        seconds, peaks, gpu_before = run_stage(module, [*common, *own], log)
        gpu = f"{(peaks.gpu_mb - gpu_before) / 1024:.2f} GB" if peaks.gpu_mb is not None and gpu_before is not None else "n/a"
        rows.append(f"| {name} | {seconds:.0f} | {peaks.largest_kb / 1024**2:.2f} GB | {peaks.summed_kb / 1024**2:.2f} GB | {gpu} |")
        print(rows[-1], flush=True)
    print("\n".join(rows))


if __name__ == "__main__":
    main()
