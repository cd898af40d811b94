"""Transfer to real frames: every network trained only on the rendered world, all its
training seeds, on a real KITTI drive with a turn (`../shared/data/kitti00_mono`, labelled from its
true poses), beside what needs no perception.

    python benchmarks/transfer_real.py [--recording ../shared/data/kitti00_mono] [--json out.json]

Run after `dvc repro` (it reads data/runs/<run>/seed<k>/checkpoints/best.ckpt and data/split/train.csv).
The recording has one camera: the label stage labels it from its poses.txt, without occlusion. Rows (evaluate/real.py): IoU against
each frame's own label; against the other frames' labels; the label-centred gain over the frames that
bend the other way (0 for any constant prediction); the correlation of the predicted path's far end
with the label's. Baselines: the mean path of the synthetic training labels, the other frames' mean
label, and the colour classifier fitted on the synthetic training split. Intervals: 95 % bootstrap over
the recording's blocks of driving and the training seeds.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from dataclasses import asdict
from pathlib import Path

import cv2
import numpy as np
from common import label_recording

from offroad_path.report.tables import grid_head, grid_row

ROOT = Path(__file__).resolve().parents[1]


def colour_row(frames, resampling):
    """The colour classifier fitted on the synthetic training split, run on the real frames."""
    from offroad_path.data.manifest import read_manifest
    from offroad_path.evaluate.colour import ColourBaseline, pixel_features
    from offroad_path.evaluate.real import real_row

    model = ColourBaseline(400, 0).fit(read_manifest(str(ROOT / "data/split/train.csv")))
    h, w = frames.labels.shape[1:]
    small = (h // 4, w // 4)  # a quarter of each side: 16 times fewer pixels through the trees
    column = list(model.model.classes_).index(True)
    paths = []
    for image in frames.images:
        tiny = cv2.resize(image, small[::-1], interpolation=cv2.INTER_AREA)
        probability = model.model.predict_proba(pixel_features(tiny))[:, column].reshape(small)
        paths.append(cv2.resize(probability, (w, h), interpolation=cv2.INTER_LINEAR) > 0.5)
    return real_row("colour classifier (synthetic training split)", np.stack(paths), frames, resampling)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--recording", type=Path, default=ROOT.parent / "shared/data/kitti00_mono")
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args()
    if not (args.recording / "poses.txt").is_file():
        sys.exit(f"{args.recording}: not found (a recording with poses.txt); nothing measured")
    from offroad_path.config import load_config
    from offroad_path.data.loading import load_labels
    from offroad_path.data.manifest import read_manifest
    from offroad_path.evaluate.pixel_scores import mean_path
    from offroad_path.evaluate.real import RealFrames, score_real
    from offroad_path.statistics.bootstrap import Resampling

    cfg = load_config()
    e = cfg.evaluate
    with tempfile.TemporaryDirectory() as tmp:
        labels = label_recording(args.recording, Path(tmp) / "labels")
        frames = RealFrames.read(labels, cfg.split.block_m, cfg.label.distance_m)
        prior = mean_path(load_labels(read_manifest(e.train_manifest))) > e.threshold
        checkpoints = {run: [ROOT / e.runs_dir / run / f"seed{seed}" / "checkpoints" / "best.ckpt" for seed in e.seeds] for run in e.runs}
        resampling = Resampling(e.bootstrap.resamples, e.bootstrap.seed)
        rows = score_real(checkpoints, frames, prior, e.threshold, resampling)
        rows["colour_classifier"] = colour_row(frames, resampling)
    bends = np.bincount(np.array(frames.direction) + 1, minlength=3).tolist()
    blocks = len(set(frames.blocks))
    print(f"{args.recording.name}: {len(frames.labels)} labelled frames, {blocks} blocks, {bends} bending left, straight, right")
    print(grid_head(["method", "IoU [95 %]", "vs other frames' labels", "label-centred gain [95 %]", "far-end correlation [95 %]"]))
    for row in rows.values():
        iou = f"{row.iou:.3f} [{row.iou_low:.3f}, {row.iou_high:.3f}]"
        gain = f"{row.gain:+.3f} [{row.gain_low:+.3f}, {row.gain_high:+.3f}]"
        far_end = f"{row.far_end:+.2f} [{row.far_end_low:+.2f}, {row.far_end_high:+.2f}]"
        print(grid_row([row.method, iou, f"{row.non_corresponding_iou:.3f}", gain, far_end]))
    if args.json:
        args.json.write_text(json.dumps({key: asdict(row) for key, row in rows.items()}, indent=2) + "\n")


if __name__ == "__main__":
    main()
