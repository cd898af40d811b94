"""Look at a label run in the Rerun viewer, and at one page of checks per recording.

    python -m offroad_path.label.inspect data/labels --recording data/synthetic [--out data/labels_inspect]
    rerun data/labels_inspect/<sequence>.rrd        # the viewer (pip install rerun-sdk; or drag the file into app.rerun.io)

Writes into --out (default: LABELS_inspect beside LABELS), per sequence, <sequence>.rrd: the VO
trajectory against the recording's own poses when it has them; the camera at every frame with its
image; at each label's f0 the label over the image, the vehicle footprint of the label in 3D and
the stereo point cloud of f0; the VO's inliers per step, its fallbacks and failures, and every
dropped segment with its reason, on the `frame` timeline. Per recording, summary.png (drift per
segment, label coverage, the footprint check of label/quality.py) and checks.json. Without
--recording there are no images, point clouds or footprint check.
"""

from __future__ import annotations

import errno
import json
import logging
import sys
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from offroad_path.errors import CommandParser, InputError, clear_errors, missing_extra, one_line, positive_int
from offroad_path.label.quality import FootprintCheck, LabelRun, ratio_curve, summary_figure
from offroad_path.sequence.footprint import VehicleFootprint, footprint_for, swept_polygons
from offroad_path.sequence.reader import Sequence, find_sequences, open_sequence, sequence_names
from offroad_path.stage import stop_cleanly_on_sigterm
from offroad_path.utils.atomic import atomic_directory
from offroad_path.utils.outputs import Outputs, claimed

log = logging.getLogger("offroad_path.inspect")
MAX_POINT_DEPTH_M = 30.0
PATH_CLASS = 1


def label_runs(labels: Path) -> dict[str, LabelRun]:
    runs = {p.name: LabelRun.read(p) for p in sorted(labels.iterdir()) if (p / "report.csv").is_file()}
    if not runs:
        raise InputError(labels, "holds no label run (a folder with report.csv per sequence: the label stage's label.out_dir)")
    return runs


def recordings_by_name(recording: Path) -> dict[str, Sequence]:

    roots = find_sequences(recording)
    return {name: open_sequence(root) for name, root in zip(sequence_names(roots, recording), roots, strict=True)}


def stereo_points(seq: Sequence, run: LabelRun, f0: int, every: int) -> tuple[np.ndarray, np.ndarray]:
    """f0's stereo point cloud in its camera frame (N, 3) with colours (N, 3), every `every`-th pixel."""
    disparity = run.disparity(f0)[::every, ::every]
    v, u = np.nonzero(disparity > 0)
    z = seq.calibration.fx * seq.calibration.baseline_m / disparity[v, u]
    keep = z < MAX_POINT_DEPTH_M
    u, v, z = u[keep] * every, v[keep] * every, z[keep]
    K = seq.calibration.K
    points = np.stack([(u - K[0, 2]) / K[0, 0] * z, (v - K[1, 2]) / K[1, 1] * z, z], axis=1)
    return points, seq.load_left(f0)[v, u]


def to_world(pose: np.ndarray, points: np.ndarray) -> np.ndarray:
    return points @ pose[:3, :3].T + pose[:3, 3]


@dataclass
class Inspected:
    """One sequence: its label run, and its recording and footprint when the recording is given."""

    name: str
    run: LabelRun
    seq: Sequence | None
    footprint: VehicleFootprint | None
    every: int = 4  # the point clouds take every every-th pixel of each row and column
    check: FootprintCheck = field(default_factory=FootprintCheck)  # filled in as the labels are logged

    @property
    def poses(self) -> np.ndarray | None:  # the poses the labels were drawn with
        return self.run.poses if self.run.poses is not None else self.seq.poses if self.seq is not None else None


def log_static(rr, rec, it: Inspected) -> None:
    """The frame convention, the trajectories and the camera's intrinsics."""
    rec.log("world", rr.ViewCoordinates.RDF, static=True)  # the first camera's frame: x right, y down, z forward
    rec.log("world/camera/image", rr.AnnotationContext([(PATH_CLASS, "path", (0, 220, 0))]), static=True)
    if it.run.poses is not None and it.run.steps:  # steps.csv: the poses are the VO's
        rec.log("world/vo_trajectory", rr.LineStrips3D([it.run.poses[:, :3, 3]], colors=[(255, 140, 0)]), static=True)
    if it.seq is not None and it.seq.poses is not None:
        recorded = np.linalg.inv(it.seq.poses[0]) @ it.seq.poses
        rec.log("world/recorded_trajectory", rr.LineStrips3D([recorded[:, :3, 3]], colors=[(80, 160, 255)]), static=True)
    if it.seq is not None:
        width, height = it.seq.image_size
        rec.log("world/camera/image", rr.Pinhole(image_from_camera=it.seq.calibration.K, resolution=[width, height]), static=True)


def log_events(rr, rec, run: LabelRun) -> None:
    """The VO's inliers, fallbacks and failures per step, and the dropped segments, on the timeline."""
    for step in run.steps:
        rec.set_time("frame", sequence=int(step["to"]))
        if step["inliers"]:
            rec.log("vo/inliers", rr.Scalars(float(step["inliers"])))
        if step["fallback"]:
            rec.log("vo/events", rr.TextLog(f"step {step['from']}->{step['to']}: fallback {step['fallback']}", level="INFO"))
        if step["ok"] != "True":
            rec.log("vo/events", rr.TextLog(f"step {step['from']}->{step['to']} failed: {step['reason']}", level="WARN"))
    for segment in run.segments:
        if segment["kept"] != "True":
            rec.set_time("frame", sequence=int(segment["f0"]))
            rec.log("labels/dropped", rr.TextLog(f"segment {segment['f0']}-{segment['fn']} dropped: {segment['reason']}", level="WARN"))


def log_label(rr, rec, it: Inspected, f0: int, fn: int) -> None:
    """At a label's f0: the label over the image, its footprint in 3D, f0's point cloud, the footprint check."""
    poses = it.poses
    mask = cv2.imread(str(it.run.folder / "label" / f"{f0:06d}.png"), cv2.IMREAD_GRAYSCALE)
    rec.log("world/camera/image/label", rr.SegmentationImage((mask > 0).astype(np.uint8) * PATH_CLASS, opacity=0.5))
    if it.footprint is not None:
        corners = np.c_[it.footprint.corners(), np.ones(4)]
        rectangles = [(poses[j] @ corners.T).T[:, :3] for j in range(f0 + 1, fn + 1)]
        rec.log("world/footprint", rr.LineStrips3D([np.vstack([r, r[:1]]) for r in rectangles], colors=[(0, 220, 0)]))
    stereo = it.seq is not None and not it.seq.mono  # one camera: no disparity, no point cloud, no depth check
    if stereo:
        points, colours = stereo_points(it.seq, it.run, f0, it.every)
        rec.log("world/points", rr.Points3D(to_world(poses[f0], points), colors=colours, radii=0.03))
    if stereo and it.footprint is not None:
        it.check.add(it.seq, it.run.disparity(f0), swept_polygons(poses, f0, fn, it.footprint))
        ratio = float(np.median(it.check.ratios[-1])) if len(it.check.ratios[-1]) else float("nan")
        rec.log("checks/stereo_over_footprint", rr.Scalars(ratio))


def log_sequence(rr, path: Path, it: Inspected) -> None:
    """Write one sequence's recording to `path` (and its labels into it.check)."""
    rec = rr.RecordingStream("offroad_path_labels", recording_id=it.name)
    rec.save(path)
    log_static(rr, rec, it)
    log_events(rr, rec, it.run)
    labelled = {int(s["f0"]): int(s["fn"]) for s in it.run.kept}
    poses = it.poses
    for i in range(len(poses) if poses is not None else 0):
        rec.set_time("frame", sequence=i)
        rec.log("world/camera", rr.Transform3D(translation=poses[i][:3, 3], mat3x3=poses[i][:3, :3]))
        if it.seq is not None:
            rec.log("world/camera/image", rr.Image(it.seq.load_left(i)).compress(jpeg_quality=85))
        if i in labelled:
            log_label(rr, rec, it, i, labelled[i])
        else:
            rec.log("world/camera/image/label", rr.Clear(recursive=False))
    rec.flush()
    rec.disconnect()


def inspect(labels: Path, recording: Path | None, out: Path, every: int = 4) -> dict:
    try:
        import rerun as rr
    except ImportError as e:
        raise missing_extra("label.inspect", "inspect", e.name) from e
    runs = label_runs(labels)
    sequences = recordings_by_name(recording) if recording is not None else {}
    if recording is not None and (missing := sorted(set(runs) - set(sequences))):
        raise InputError(recording, f"holds no sequence {', '.join(missing)} of {labels}")
    for name, run in runs.items():
        frames = len(run.poses) if run.poses is not None else 1 + max((int(s["fn"]) for s in run.segments), default=0)
        if name in sequences and len(sequences[name]) < frames:
            raise InputError(
                sequences[name].root,
                f"has {len(sequences[name])} frames, fewer than the {frames} of {run.folder}: not the recording it labelled",
            )
    checks = {}
    with (
        claimed(Outputs("inspect", folders={"--out": out}, inputs=[labels, recording])),
        atomic_directory(out, "inspect", key="--out") as tmp,
    ):
        for name, run in runs.items():
            seq = sequences.get(name)
            it = Inspected(name, run, seq, footprint_for(seq, {}) if seq is not None else None, every)
            try:
                log_sequence(rr, tmp / f"{name}.rrd", it)
            except RuntimeError as e:  # rerun's writer: a full disk, a folder that may not be written
                # named where it was to go: the temporary folder is gone with the error
                raise OSError(errno.EIO, f"the recording could not be written ({one_line(e)})", str(out / f"{name}.rrd")) from e
            if it.footprint is not None and not seq.mono:  # the check compares stereo depth with the footprint
                checks[name] = it.check.verdict(it.footprint.camera_height_m)
                checks[name]["curve_depth"], checks[name]["curve_ratio"] = ratio_curve(it.check, np.arange(2.0, 16.0, 1.0))
        summary_figure(str(labels), runs, checks, tmp / "summary.png")
        (tmp / "checks.json").write_text(json.dumps(checks, indent=2) + "\n")
    for name, check in checks.items():
        for flag in check["flags"]:
            log.warning("%s: %s", name, flag)
    return checks


def main(argv: list[str] | None = None) -> None:
    parser = CommandParser(prog="python -m offroad_path.label.inspect", description=__doc__.splitlines()[0])
    parser.add_argument("labels", type=Path, help="the label stage's output folder (label.out_dir)")
    parser.add_argument("--recording", type=Path, help="the recordings it labelled (label.in_dir): images, point clouds, footprint check")
    parser.add_argument("--out", type=Path, help="where the .rrd files and summary go (default: LABELS_inspect beside LABELS)")
    parser.add_argument(
        "--points-every", type=positive_int, default=4, help="the point cloud takes every N-th pixel of each row and column"
    )
    args = parser.parse_args(argv)
    stop_cleanly_on_sigterm()
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    with clear_errors():
        out = args.out or args.labels.parent / f"{args.labels.name}_inspect"
        checks = inspect(args.labels, args.recording, out, args.points_every)
    print(
        f"wrote {out}: one .rrd per sequence (open with `rerun {out}/<sequence>.rrd`), summary.png, checks.json"
        + "".join(f"\n{name}: FLAG {flag}" for name, check in checks.items() for flag in check["flags"])
    )


if __name__ == "__main__":
    main(sys.argv[1:])
