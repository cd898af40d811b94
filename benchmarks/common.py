"""What the benchmarks share (and the tests check): run from this folder, `python benchmarks/<name>.py`,
a benchmark imports it as `common`; pytest finds it through its pythonpath (pyproject.toml).

- the rule for changes that alter results: non-inferiority over training seeds (seed_spread.py
  --compare). Per path network, a candidate preset is admissible when the one-sided 95 % lower bound
  (Student's t over the seeds) of the paired (by seed) difference in pooled test IoU, candidate minus
  reference, is above -margin, and no seed collapses (every seed's IoU above the mean-path prior's);
  for PilotNet, when the upper bound of the paired difference in mean absolute error is below
  +mae_margin and every seed is below always-straight-ahead's error. Both on the test frames both
  files scored. A file: {"overrides", "labels", "prior": per-image counts, "models": {model: PER_SEED lists}};
- a run's per-image test counts (`test_counts`, by frame `key`);
- processes: the ones a test or benchmark started (`tagged_processes`), those below one (`descendants`),
  their peak memory (`high_water_kb`), a core kept busy (`BUSY`);
- the CPU kernel sets a process's numerical libraries can be held to (`without_vector_kernels`,
  `openblas_cores`), for the checks that bytes are the same on every CPU;
- a training step's time (`step_ms`) and a KITTI recording labelled from its poses (`label_recording`).
"""

from __future__ import annotations

import argparse
import math
import statistics
import time
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from scipy import stats

from offroad_path.report.tables import grid_head, grid_row
from offroad_path.statistics.scores import Scores

if TYPE_CHECKING:
    import torch

    from offroad_path.data.manifest import Sample

BUSY = "import torch\nx = torch.randn(1024, 1024)\nwhile True:\n    x = (x @ x).clamp(-1, 1)\n"  # a process that keeps one core busy


# -- The rule for changes that alter results ------------------------------------------------------

PER_SEED = ("seeds", "score", "epochs", "seconds", "counts")  # a network's lists in a file, one entry per seed


def iou(per_image: dict[str, list[int]], keys: list[str]) -> float:
    """Pooled IoU of the images `keys` (per-image counts tp, fp, tn, fn by frame key)."""
    return Scores.of(np.array([per_image[k] for k in keys]).sum(axis=0)).iou


def mae(errors: dict[str, float], keys: list[str]) -> float:
    """Mean absolute error over the frames `keys`."""
    return float(np.mean([errors[k] for k in keys]))


def merge(files: list[dict]) -> dict:
    """One file of the same preset and yardstick from several that hold other seeds, seeds in order."""
    first = files[0]
    if any((f["overrides"], f["labels"]) != (first["overrides"], first["labels"]) for f in files):
        raise ValueError("the files were made with other overrides or labels")
    models: dict[str, dict] = {}
    for f in files:
        for model, row in f["models"].items():
            into = models.setdefault(model, {key: [] for key in PER_SEED})
            for key in PER_SEED:
                into[key] += row[key]
            if "straight" in row:
                into["straight"] = row["straight"]
    for model, row in models.items():
        if len(set(row["seeds"])) != len(row["seeds"]):
            raise ValueError(f"{model} has seed {row['seeds']} twice")
        order = np.argsort(row["seeds"])
        for key in PER_SEED:
            row[key] = [row[key][i] for i in order]
    return {**first, "models": models}


def one_sided(diffs: list[float], sign: int) -> tuple[float, float, float, float]:
    """Mean, sample sd, standard error and the one-sided 95 % bound (lower for sign +1, upper for -1) of paired differences."""
    n, mean_d = len(diffs), statistics.mean(diffs)
    sd = statistics.stdev(diffs) if n > 1 else math.nan
    se = sd / math.sqrt(n)
    return mean_d, sd, se, mean_d - sign * float(stats.t.ppf(0.95, n - 1)) * se


def compare(reference: dict, candidate: dict, margin: float = 0.02, mae_margin: float = 0.01) -> bool:
    """Print the rule's table per network, on the test frames both files scored; True when every network is admissible."""
    for model, ref in reference["models"].items():
        new = candidate["models"].get(model)
        if new is None or new["seeds"] != ref["seeds"]:
            raise ValueError(f"{model} was not run with the same seeds in both files")
    paths = [m for m in reference["models"] if m != "pilotnet"]
    runs = [c for file in (reference, candidate) for model in paths for c in file["models"][model]["counts"]]
    keys = sorted(set.intersection(*(set(c) for c in [*runs, candidate["prior"]])))
    print(f"reference: {' '.join(reference['overrides']) or '(none)'}\ncandidate: {' '.join(candidate['overrides']) or '(none)'}")
    print(f"scored against: {candidate['labels']}; {len(keys)} test images both scored "
          f"(reference {len(reference['prior'])}, candidate {len(candidate['prior'])})")  # fmt: skip
    prior = iou(candidate["prior"], keys)
    print(f"mean-path prior: {prior:.4f}; margin {margin} IoU (PilotNet: {mae_margin} MAE)\n")
    print(grid_head(["network", "reference mean", "candidate mean", "paired differences (seeds in order)", "mean ± sd",
                     "standard error", "one-sided 95 % bound", "worst seed", "admissible"]))  # fmt: skip
    admissible_all = True
    for model in reference["models"]:
        ref, new = reference["models"][model], candidate["models"][model]
        if model == "pilotnet":
            frames = sorted(set.intersection(*(set(c) for c in [*ref["counts"], *new["counts"]])))
            old_score, new_score = ([mae(c, frames) for c in row["counts"]] for row in (ref, new))
            mean_d, sd, se, bound = one_sided([b - a for a, b in zip(old_score, new_score, strict=True)], -1)
            worst, floor = max(new_score), mae(new["straight"], frames)
            ok = bound < mae_margin and worst < floor
            label, worst_text = f"pilotnet (MAE, {len(frames)} frames; straight ahead {floor:.4f})", f"{worst:.4f}"
        else:
            old_score, new_score = ([iou(c, keys) for c in row["counts"]] for row in (ref, new))
            mean_d, sd, se, bound = one_sided([b - a for a, b in zip(old_score, new_score, strict=True)], +1)
            worst = min(new_score)
            ok = bound > -margin and worst > prior
            label, worst_text = model, f"{worst:.4f}"
        admissible_all &= ok
        diffs = [b - a for a, b in zip(old_score, new_score, strict=True)]
        print(grid_row([label, f"{statistics.mean(old_score):.4f}", f"{statistics.mean(new_score):.4f}",
                        ", ".join(f"{d:+.3f}" for d in diffs), f"{mean_d:+.4f} ± {sd:.4f}", f"{se:.4f}", f"{bound:+.4f}",
                        worst_text, "yes" if ok else "no"]))  # fmt: skip
    return admissible_all


# -- A run's test counts ---------------------------------------------------------------------------


def key(sample: Sample) -> str:
    return f"{sample.sequence}/{sample.f0}/{int(sample.mirrored)}"


def test_counts(run_dir: Path, yardstick: dict[str, str] | None, threshold: float = 0.5) -> dict[str, list[int]]:
    """Per test image (by frame key) the counts tp, fp, tn, fn of the run's maps, against its own test
    labels or, with a yardstick, against those (maps resized bilinearly to their size; frames it lacks left out)."""
    import cv2

    from offroad_path.data.loading import load_labels, load_maps
    from offroad_path.data.manifest import read_predictions_manifest
    from offroad_path.evaluate.pixel_scores import counts

    rows = read_predictions_manifest(run_dir / "predictions" / "manifest.csv", "train")
    if yardstick is not None:
        rows = [(replace(s, label=yardstick[key(s)]), p) for s, p in rows if key(s) in yardstick]
    samples, labels = [s for s, _ in rows], load_labels([s for s, _ in rows])
    maps = load_maps([p for _, p in rows])
    if maps.shape != labels.shape:
        maps = np.stack([cv2.resize(m, labels.shape[:0:-1], interpolation=cv2.INTER_LINEAR) for m in maps])
    per_image = counts(maps, labels, threshold)
    return {key(s): c.tolist() for s, c in zip(samples, per_image, strict=True)}


# -- Processes ------------------------------------------------------------------------------------


def tagged_processes(tag: str) -> list[int]:
    """Live processes started with OFFROAD_TEST_TAG=tag in their environment (workers inherit it,
    and keep it when their parent dies and they are re-parented)."""
    found = []
    for environ in Path("/proc").glob("[0-9]*/environ"):
        try:
            if f"OFFROAD_TEST_TAG={tag}".encode() in environ.read_bytes().split(b"\0"):
                state = (environ.parent / "stat").read_text().split(")")[-1].split()[0]
                if state != "Z":
                    found.append(int(environ.parent.name))
        except OSError:
            continue
    return found


def descendants(root: int) -> list[int]:
    """Every process below `root` (Linux /proc)."""
    children: dict[int, list[int]] = {}
    for status in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = status.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        children.setdefault(int(fields[1]), []).append(int(status.parent.name))
    found, todo = [], [root]
    while todo:
        found += (kids := children.get(todo.pop(), []))
        todo += kids
    return found


def high_water_kb(pid: int) -> int:
    try:
        return next(int(line.split()[1]) for line in Path(f"/proc/{pid}/status").read_text().splitlines() if line.startswith("VmHWM:"))
    except (OSError, StopIteration):
        return 0


# -- CPU kernel sets ------------------------------------------------------------------------------


def without_vector_kernels() -> dict[str, str]:
    """An environment in which OpenCV and NumPy use none of their CPU-specific vector kernels (the
    dispatched ones: SSE4 and up for OpenCV, AVX-512 among them, X86_V3 and up for NumPy) and
    OpenBLAS runs its oldest x86-64 kernels."""
    from numpy._core._multiarray_umath import __cpu_dispatch__, __cpu_features__

    dispatched = [f for f in __cpu_dispatch__ if __cpu_features__.get(f)]
    env = {"OPENCV_CPU_DISABLE": "SSE4.1,SSE4.2,POPCNT,AVX,FP16,AVX2,FMA3,AVX512-SKX", "OPENBLAS_CORETYPE": "Prescott"}
    return env | ({"NPY_DISABLE_CPU_FEATURES": " ".join(dispatched)} if dispatched else {})


def openblas_cores() -> list[str]:
    """OpenBLAS kernel sets this CPU can run (OPENBLAS_CORETYPE): NumPy's matmul, dot and linalg
    take the newest by default (SkylakeX here, Haswell on an AVX2 machine), and each rounds differently."""
    flags = set(Path("/proc/cpuinfo").read_text().split()) if Path("/proc/cpuinfo").is_file() else set()
    return [core for core, needs in (("Prescott", "sse3"), ("Nehalem", "sse4_2"), ("Sandybridge", "avx"), ("Haswell", "avx2"),
            ("SkylakeX", "avx512f")) if needs in flags or (needs == "sse3" and "pni" in flags)]  # fmt: skip


# -- Training steps and real recordings ------------------------------------------------------------


def step_ms(net: torch.nn.Module, x: torch.Tensor, y: torch.Tensor, steps: int) -> float:
    """Milliseconds per SGD step of `net` on one batch (x, y), after three warm-up steps."""
    import torch
    import torch.nn.functional as F

    optimiser = torch.optim.SGD(net.parameters(), lr=0.01, momentum=0.9)

    def step() -> None:
        optimiser.zero_grad()
        F.cross_entropy(net(x), y).backward()
        optimiser.step()

    for _ in range(3):
        step()
    start = time.perf_counter()
    for _ in range(steps):
        step()
    return (time.perf_counter() - start) / steps * 1000


FOOTPRINT = (
    "label.footprint.width_m=1.8",
    "label.footprint.front_m=2.0",
    "label.footprint.rear_m=-2.7",
    "label.footprint.camera_height_m=1.65",
)


def label_recording(recording: Path, out: Path, *overrides: str) -> Path:
    """The label stage on a KITTI recording (one camera or two) from its true poses, occlusion off
    (a recording of one camera has no depth to test it by; a stereo one is labelled alike)."""
    from offroad_path.config import load_config
    from offroad_path.label import label

    cfg = load_config(
        f"label.in_dir={recording}",
        f"label.out_dir={out}",
        f"label.metrics_path={out.parent / (out.name + '.json')}",
        "label.poses.source=file",
        "label.occlusion.enabled=false",
        "label.workers=1",
        "mlflow.enabled=false",
        *FOOTPRINT,
        *overrides,
    )
    label(cfg)
    return out


def development_problem(data: Path) -> str | None:
    """Why a run's development set cannot carry a search's statistics (its hierarchical bootstrap
    resamples worlds, then blocks: at least 2 worlds), or None; said before any training."""
    from offroad_path.data.manifest import read_manifest

    manifest = data / "split" / "development.csv"
    if not manifest.is_file():
        return f"{manifest}: not found; run `dvc repro split` (or --data a run's data folder)"
    worlds = {sample.sequence for sample in read_manifest(manifest)}  # a development world is one sequence
    if len(worlds) < 2:
        return (
            f"{manifest}: {len(worlds)} development world(s); the search's intervals resample worlds and need at least 2 "
            "(raise synthesize.test_worlds.development_blocks)"
        )
    return None


def repeated(values: list[int]) -> list[int]:
    """The values listed more than once, in order."""
    return sorted({v for v in values if values.count(v) > 1})


# -- Arguments ------------------------------------------------------------------------------------


def positive_int(text: str) -> int:
    """A count of at least 1 (argparse type: a count of 0 would run the work and then fail on nothing)."""
    if not text.isdigit() or int(text) < 1:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number of at least 1")
    return int(text)


def positive_float(text: str) -> float:
    """A finite number above 0 (a negative scale is no range to draw from)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not 0 < value < float("inf"):
        raise argparse.ArgumentTypeError(f"{text!r} is not a number above 0")
    return value
