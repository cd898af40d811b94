"""The predict command end to end (read, run, write PNGs and the MP4), idle and beside another
CPU-heavy process, for each thread setting.

    python benchmarks/predict_under_load.py [--run unet-none] [--sequence data/synthetic/seq_001]

Needs `dvc repro` (the run's checkpoint and the rendered sequence). Exports the run to ONNX with
the export command, then runs `python -m offroad_path.predict` on the sequence with onnxruntime
and with PyTorch, once per setting of predict.threads, first on an idle machine, then while a second process
multiplies matrices on torch's default threads (as another training stage would). Prints the
frames/s the command reports, end to end and in the model (the fastest of --repeats runs).
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from common import BUSY

from offroad_path.report.tables import grid_head, grid_row

SETTINGS = ("free", "all", "1")


def predict(checkpoint: Path, sequence: str, threads: str, out: Path) -> tuple[float, float, int]:
    """(end-to-end frames/s, model frames/s, threads used) of one predict run."""
    run = subprocess.run([sys.executable, "-m", "offroad_path.predict", f"predict.checkpoint={checkpoint}", f"predict.input={sequence}",
                          f"predict.out_dir={out}", f"predict.threads={threads}", "mlflow.enabled=false"],
                         capture_output=True, text=True, check=True)  # fmt: skip
    found = re.search(r"([\d.]+) frames/s end to end, ([\d.]+) frames/s in the model \(.*, (\d+) threads\)", run.stdout)
    if found is None:
        raise RuntimeError(f"predict printed no summary:\n{run.stdout}\n{run.stderr}")
    return float(found[1]), float(found[2]), int(found[3])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--run", default="unet-none")
    parser.add_argument("--sequence", default="data/synthetic/seq_001")
    parser.add_argument("--repeats", type=int, default=3, help="runs per setting; the fastest is shown")
    args = parser.parse_args()
    model = args.run.split("-")[0]
    with tempfile.TemporaryDirectory() as tmp:
        onnx = Path(tmp) / f"{args.run}.onnx"
        subprocess.run([sys.executable, "-m", "offroad_path.export", f"model={model}", f"pretraining={args.run.split('-', 1)[1]}",
                        f"export.out={onnx}", "mlflow.enabled=false"], check=True, capture_output=True)  # fmt: skip
        checkpoints = {"onnxruntime": onnx, "PyTorch": Path("data") / "runs" / args.run / "seed0" / "checkpoints" / "best.ckpt"}
        print(grid_head(["machine", "runtime", "predict.threads", "threads used", "end to end, frames/s", "in the model, frames/s"]))
        for load in ("idle", "beside a busy torch process"):
            busy = subprocess.Popen([sys.executable, "-c", BUSY]) if load != "idle" else None
            try:
                if busy is not None:
                    time.sleep(3)  # let it reach full speed
                for runtime, checkpoint in checkpoints.items():
                    for threads in SETTINGS:
                        outs = [Path(tempfile.mkdtemp(dir=tmp)) / "out" for _ in range(args.repeats)]
                        runs = [predict(checkpoint, args.sequence, threads, out) for out in outs]
                        fps, model_fps, used = max(runs)
                        print(grid_row([load, runtime, threads, used, f"{fps:.1f}", f"{model_fps:.1f}"]), flush=True)
            finally:
                if busy is not None:
                    busy.kill()
                    busy.wait()


if __name__ == "__main__":
    main()
