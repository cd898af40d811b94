"""How much odometry error the labels tolerate: labels made from poses with a controlled error,
each scored against the labels of the true poses, and U-Net (laptop preset, seeds 0-2) trained on
each and scored on the held-out test worlds' exact labels, with a hierarchical interval (test
worlds, their blocks, the seeds) of each row minus the true poses' row, paired seed by seed.

    python benchmarks/label_noise.py [--drifts 0.5 1.7 3.4 8.5] [--kinds pitch height roll drops reset]
                                     [--seeds 0 1 2] [--out docs/images/label_noise.png]

Needs a finished `dvc repro` (data/synthetic, and data/labels for the windowed VO's poses). The
variants: the true poses; the pipeline's windowed VO (data/labels/<seq>/poses_vo.txt); the frame-to-
frame VO (a label run with label.odometry.method=frame_to_frame); the true poses with a smooth
random-walk error in step length and heading (offroad_path.odometry.perturb) set by each --drifts
value (which makes a drift of about 0.6 times it; the table gives the drift measured); and each of
--kinds at --kind-setting (offroad_path.odometry.perturb.PoseError): the same smooth error in pitch,
in camera height or in roll, steps the VO lost (--drops-per-km) and a reset of the pose chain in the
middle of every drive. Only the training drives get the variant's poses; the test worlds are
labelled from their true poses in every variant, so every network is scored against the same exact
labels. Each variant: the label stage (label.poses.source=file), the split stage, the train stage
once per seed, then the test IoU the evaluate stage's way (counts pooled over the seeds at 0.5).
Prints a Markdown table and writes a figure.
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
from common import key, test_counts

from offroad_path.data.labels import read_label_run
from offroad_path.data.manifest import read_manifest
from offroad_path.evaluate.pixel_scores import counts, pooled
from offroad_path.evaluate.uncertainty import HierarchicalBootstrap, sample_blocks
from offroad_path.odometry.perturb import PoseError, drifted_poses, erroneous_poses
from offroad_path.odometry.sequence_trajectory import drift
from offroad_path.report.tables import grid_head, grid_row
from offroad_path.sequence.poses import poses_to_text, read_poses
from offroad_path.sequence.reader import find_sequences, open_sequence
from offroad_path.statistics.bootstrap import Resampling
from offroad_path.statistics.scores import iou

BLOCK_M = 20.0  # the split's blocks of driving, which the intervals resample


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


def kind_error(kind: str, setting: float, drops_per_km: float) -> PoseError:
    """The PoseError of one --kinds name: a smooth error at `setting` in pitch, height or roll, lost
    steps at drops_per_km, or one reset in the middle of every drive."""
    return {
        "pitch": PoseError(pitch=setting),
        "height": PoseError(height=setting),
        "roll": PoseError(roll=setting),
        "drops": PoseError(drops_per_km=drops_per_km),
        "reset": PoseError(resets=1),
    }[kind]


def seed_counts(folder: Path, seeds: list[int]) -> tuple[list[str], np.ndarray]:
    """The test frames' keys and their counts (seeds, frames, 4), each seed's run at folder/run<seed>."""
    per_seed = [test_counts(folder / f"run{seed}", None) for seed in seeds]
    keys = sorted(per_seed[0])
    return keys, np.array([[found[k] for k in keys] for found in per_seed], float)


def pose_variants(
    args: argparse.Namespace, true: dict[str, np.ndarray], training: list[str], tmp: Path
) -> dict[str, dict[str, np.ndarray]]:
    """Each row's poses of the training drives: the true ones, the two odometries', each drift setting and each kind."""
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
    for kind in args.kinds:
        error = kind_error(kind, args.kind_setting, args.drops_per_km)
        variants[f"true poses, {error.describe()}"] = {
            name: erroneous_poses(true[name], error, seed=args.seed + i) for i, name in enumerate(training)
        }
    return variants


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--drifts", type=float, nargs="*", default=[0.5, 1.7, 3.4, 8.5])
    parser.add_argument("--kinds", nargs="*", default=["pitch", "height", "roll", "drops", "reset"], help="PoseError kinds")
    parser.add_argument("--kind-setting", type=float, default=3.4, help="pitch, height and roll's setting (percent units)")
    parser.add_argument("--drops-per-km", type=float, default=20.0, help="the drops kind: lost VO steps per km")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2], help="U-Net's training seeds per row")
    parser.add_argument("--out", type=Path, default=Path("docs/images/label_noise.png"))
    parser.add_argument("--seed", type=int, default=0, help="of the errors' random draws")
    parser.add_argument("--redraw", type=Path, help="only draw the figure from the JSON rows a run printed last")
    args = parser.parse_args()
    if args.redraw:
        figure(json.loads(args.redraw.read_text()), args.out)
        return
    recordings = {p.name: open_sequence(p) for p in find_sequences("data/synthetic")}
    true = {name: seq.poses for name, seq in recordings.items()}
    training = [name for name, seq in recordings.items() if seq.meta.get("split") != "test"]
    rows = []
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        variants = pose_variants(args, true, training, tmp)
        test_iou = f"U-Net test IoU, seeds {', '.join(map(str, args.seeds))} [95 %]"
        print(grid_head(["labels from", "translation drift over 20 m (%)", "heading drift (deg/m)", "training labels against exact (IoU)",
                         test_iou, "minus true poses [95 %]", "seconds"]), flush=True)  # fmt: skip
        exact = tmp / "true_poses" / "labels"
        reference: np.ndarray | None = None
        for title, estimated in variants.items():
            start = time.perf_counter()
            folder = tmp / "".join(c if c.isalnum() else "_" for c in title)
            poses = {name: true[name] for name in recordings} | estimated
            pattern = write_poses(folder / "poses", poses)
            run("offroad_path.label", "label.poses.source=file", f"label.poses.file='{pattern}'", f"label.out_dir={folder / 'labels'}",
                f"label.metrics_path={folder / 'label.json'}", "mlflow.enabled=false")  # fmt: skip
            run("offroad_path.split", f"split.labels_dir={folder / 'labels'}", f"split.out_dir={folder / 'split'}")
            for seed in args.seeds:
                run("offroad_path.train", "model=unet", "pretraining=none", f"seed={seed}", f"data.split_dir={folder / 'split'}",
                    f"train.out_dir={folder / f'run{seed}'}", "resume=false", "mlflow.enabled=false")  # fmt: skip
            keys, found = seed_counts(folder, args.seeds)
            if reference is None:  # the true poses' row, first: the test frames every row is compared on
                reference, reference_keys = found, keys
                samples = {key(s): s for s in read_manifest(folder / "split" / "test.csv")}
                bootstrap = HierarchicalBootstrap(sample_blocks([samples[k] for k in keys], folder / "labels", BLOCK_M), Resampling())
            if keys != reference_keys:
                sys.exit(f"{title}: its test frames differ from the true poses' row (the test worlds must be labelled alike)")
            score = bootstrap.interval(found, iou)
            gain = bootstrap.paired(found, reference, iou)
            drifts = [drift(poses[name], true[name])[0] for name in training]
            translation = float(np.mean([d.translation_drift_pct for d in drifts if d]))
            rotation = float(np.mean([d.rotation_drift_deg_per_m for d in drifts if d]))
            agreement = label_agreement(folder / "labels", exact)
            rows.append({"labels": title, "translation_drift_pct": translation, "rotation_drift_deg_per_m": rotation,
                         "label_iou": agreement, "test_iou": score.estimate, "low": score.low, "high": score.high,
                         "minus_true": [gain.estimate, gain.low, gain.high]})  # fmt: skip
            print(grid_row([title, f"{translation:.2f}", f"{rotation:.4f}", f"{agreement:.3f}", score.text(), gain.difference_text(),
                            f"{time.perf_counter() - start:.0f}"]), flush=True)  # fmt: skip
    print(json.dumps(rows))
    figure(rows, args.out)


def figure(rows: list[dict], out: Path) -> None:
    """Both IoUs against the measured drift; the test IoU with its hierarchical interval (worlds,
    blocks, seeds), and the true poses' interval as a band."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 3.6), dpi=120)
    x = np.array([max(r["translation_drift_pct"], 0.01) for r in rows])  # exact poses drawn at 0.01 % on the log axis
    exact = next(r for r in rows if r["labels"] == "true poses")
    ax.axhspan(exact["low"], exact["high"], color="C1", alpha=0.15, label="true poses' test IoU, 95 % interval")
    ax.plot(x, [r["label_iou"] for r in rows], "o", label="training labels against exact labels")
    low, high = np.array([r["low"] for r in rows]), np.array([r["high"] for r in rows])
    y = np.array([r["test_iou"] for r in rows])
    ax.errorbar(x, y, yerr=[y - low, high - y], fmt="s", capsize=2, label="U-Net test IoU (exact test labels), 95 %")
    for r, xi in zip(rows, x, strict=True):
        if "setting" not in r["labels"]:  # the odometries, the exact poses and the other kinds; the settings read off the axis
            ax.annotate(r["labels"].split(" (")[0].removeprefix("true poses, "), (xi, r["test_iou"]), fontsize=6,
                        xytext=(0, -14), textcoords="offset points", rotation=-30)  # fmt: skip
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
