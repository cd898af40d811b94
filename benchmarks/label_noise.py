"""How much odometry error the labels tolerate: labels made from poses with a controlled drift,
each scored against the labels of the true poses, and one network (U-Net, laptop preset, seed 0)
trained on each and scored on the held-out test worlds' exact labels.

    python benchmarks/label_noise.py [--drifts 0.5 1.7 3.4 8.5] [--out docs/images/label_noise.png]

Needs a finished `dvc repro` (data/synthetic, and data/labels for the windowed VO's poses). The
variants: the true poses; the pipeline's windowed VO (data/labels/<seq>/poses_vo.txt); the frame-to-
frame VO (a label run with label.odometry.method=frame_to_frame); the true poses with a smooth
random-walk error in step length and heading (offroad_path.odometry.perturb) set by each --drifts
value (which makes a drift of about 0.6 times it; the table gives the drift measured). Only the
training drives get the variant's poses; the test worlds are labelled from their true poses in every
variant, so every network is scored against the same exact labels. Each variant: the label stage
(label.poses.source=file), the split stage, the train stage, then the test IoU the evaluate stage's
way (pooled at 0.5). Prints a Markdown table and writes a figure.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from offroad_path.data.labels import read_label_run
from offroad_path.evaluation.metrics import counts, pooled
from offroad_path.odometry.perturb import drifted_poses
from offroad_path.odometry.trajectory import drift
from offroad_path.sequence.poses import poses_to_text, read_poses
from offroad_path.sequence.reader import find_sequences, open_sequence

sys.path.insert(0, str(Path(__file__).parent))
from seed_spread import pooled_test_iou


def run(*args: str) -> None:
    done = subprocess.run([sys.executable, "-m", *args], capture_output=True, text=True)
    if done.returncode:
        sys.exit(f"{' '.join(args)} failed:\n{done.stderr[-3000:]}")


def write_poses(folder: Path, poses_of: dict[str, np.ndarray]) -> str:
    folder.mkdir(parents=True)
    for name, poses in poses_of.items():
        first = np.linalg.inv(poses[0])
        (folder / f"{name}.txt").write_text(poses_to_text(first[None] @ poses))
    return str(folder / "{name}.txt")


def label_agreement(labels: Path, exact: Path) -> float:
    """Pooled IoU of a variant's training-drive labels against the true poses' labels at the same f0."""
    import cv2

    total = np.zeros(4)
    for run_ in read_label_run(labels):
        if open_sequence(run_.sequence.root).meta.get("split") == "test":
            continue
        for path in run_.labels():
            truth = exact / run_.name / "label" / path.name
            if truth.is_file():
                a, b = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE) > 0, cv2.imread(str(truth), cv2.IMREAD_GRAYSCALE) > 0
                total += counts(a[None].astype(np.float32), b[None]).sum(axis=0)
    return pooled(total[None]).iou


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--drifts", type=float, nargs="+", default=[0.5, 1.7, 3.4, 8.5])
    parser.add_argument("--out", type=Path, default=Path("docs/images/label_noise.png"))
    parser.add_argument("--seed", type=int, default=0, help="of the drift's random walk")
    parser.add_argument("--redraw", type=Path, help="only draw the figure from the JSON rows a run printed last")
    parser.add_argument("--seed-sd", type=float, default=0.008, help="U-Net's seed-to-seed sd (seed study), drawn as a band")
    args = parser.parse_args()
    if args.redraw:
        figure(json.loads(args.redraw.read_text()), args.out, args.seed_sd)
        return
    recordings = {p.name: open_sequence(p) for p in find_sequences("data/synthetic")}
    true = {name: seq.poses for name, seq in recordings.items()}
    training = [name for name, seq in recordings.items() if seq.meta.get("split") != "test"]
    rows = []
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        run("offroad_path.label", "label.odometry.method=frame_to_frame", f"label.out_dir={tmp / 'f2f'}",
            f"label.metrics_path={tmp / 'f2f.json'}", "mlflow.enabled=false")  # fmt: skip
        variants: dict[str, dict[str, np.ndarray]] = {"true poses": {}, "windowed VO (the pipeline's)": {}, "frame-to-frame VO": {}}
        for name in training:
            n = len(true[name])
            variants["windowed VO (the pipeline's)"][name] = read_poses(Path(f"data/labels/{name}/poses_vo.txt"), n)
            variants["frame-to-frame VO"][name] = read_poses(tmp / "f2f" / name / "poses_vo.txt", n)
        for percent in args.drifts:
            variants[f"true poses, drift setting {percent:g}"] = {
                name: drifted_poses(true[name], percent, seed=args.seed + i) for i, name in enumerate(training)
            }
        print("| labels from | translation drift over 20 m (%) | heading drift (deg/m) | training labels against exact (IoU) "
              "| U-Net test IoU (exact test labels) | seconds |\n| --- | --- | --- | --- | --- | --- |", flush=True)  # fmt: skip
        exact = tmp / "true_poses" / "labels"
        for title, estimated in variants.items():
            start = time.perf_counter()
            folder = tmp / "".join(c if c.isalnum() else "_" for c in title)
            poses = {name: true[name] for name in recordings} | estimated
            pattern = write_poses(folder / "poses", poses)
            run("offroad_path.label", "label.poses.source=file", f"label.poses.file='{pattern}'", f"label.out_dir={folder / 'labels'}",
                f"label.metrics_path={folder / 'label.json'}", "mlflow.enabled=false")  # fmt: skip
            run("offroad_path.split", f"split.labels_dir={folder / 'labels'}", f"split.out_dir={folder / 'split'}")
            run("offroad_path.train", "model=unet", "pretraining=none", "seed=0", f"data.split_dir={folder / 'split'}",
                f"train.out_dir={folder / 'run'}", "resume=false", "mlflow.enabled=false")  # fmt: skip
            drifts = [drift(poses[name], true[name])[0] for name in training]
            translation = float(np.mean([d.translation_drift_pct for d in drifts if d]))
            rotation = float(np.mean([d.rotation_drift_deg_per_m for d in drifts if d]))
            agreement = label_agreement(folder / "labels", exact)
            iou = pooled_test_iou(folder / "run")
            rows.append({"labels": title, "translation_drift_pct": translation, "rotation_drift_deg_per_m": rotation,
                         "label_iou": agreement, "test_iou": iou})  # fmt: skip
            print(f"| {title} | {translation:.2f} | {rotation:.4f} | {agreement:.3f} | {iou:.3f} | {time.perf_counter() - start:.0f} |",
                  flush=True)  # fmt: skip
    print(json.dumps(rows))
    figure(rows, args.out, args.seed_sd)


def figure(rows: list[dict], out: Path, seed_sd: float) -> None:
    """Both IoUs against the measured drift; the band: two seed standard deviations around the
    test IoU from exact labels, inside which no difference is a finding."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 3.6), dpi=120)
    x = np.array([max(r["translation_drift_pct"], 0.01) for r in rows])  # exact poses drawn at 0.01 % on the log axis
    exact = next(r["test_iou"] for r in rows if r["translation_drift_pct"] < 1e-6)
    ax.axhspan(exact - 2 * seed_sd, exact + 2 * seed_sd, color="C1", alpha=0.15, label="exact labels' test IoU ± 2 seed sd")
    ax.plot(x, [r["label_iou"] for r in rows], "o", label="training labels against exact labels")
    ax.plot(x, [r["test_iou"] for r in rows], "s", label="U-Net test IoU (exact test labels)")
    for r, xi in zip(rows, x, strict=True):
        if "setting" not in r["labels"]:  # the odometries and the exact poses; the settings read off the axis
            ax.annotate(r["labels"].split(" (")[0], (xi, r["test_iou"]), fontsize=7, xytext=(0, -14), textcoords="offset points",
                        rotation=-30)  # fmt: skip
    ax.set_xscale("log")
    ax.set_xlabel("odometry translation drift over 20 m (%; exact poses at 0.01)")
    ax.set_ylabel("IoU")
    ax.set_ylim(0.5, 1.02)
    ax.legend(loc="lower left", fontsize=7)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out)


if __name__ == "__main__":
    main()
