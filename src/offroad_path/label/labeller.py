"""Label one sequence: poses (stereo VO or a file), frame selection, footprint labels, f0 disparity,
and a report of every segment, kept or dropped and why. A mono sequence (one camera) is labelled
from a pose file, without occlusion and without disparity: both need the right image."""

from __future__ import annotations

import csv
import logging
from collections import Counter
from dataclasses import asdict, dataclass, fields
from pathlib import Path

import cv2
import numpy as np
from omegaconf import DictConfig

from offroad_path.config.label_schema import OCCLUSION_DEPTHS, POSE_SOURCES, OdometryConfig
from offroad_path.errors import InputError
from offroad_path.geometry.path import distance_along
from offroad_path.geometry.stereo import compute_disparity, depth_from_disparity, encode_disparity, sgbm
from offroad_path.label.frame_selection import select_segments
from offroad_path.odometry.sequence_trajectory import OdometryRun, drift, run_odometry
from offroad_path.odometry.steps import FALLBACKS
from offroad_path.sequence.footprint import Occlusion, VehicleFootprint, footprint_for, path_label
from offroad_path.sequence.poses import max_steps, poses_to_text, read_poses
from offroad_path.sequence.reader import Sequence, open_sequence
from offroad_path.utils.media import write_image

log = logging.getLogger(__name__)


@dataclass
class SegmentReport:
    f0: int
    fn: int
    path_length_m: float  # driven along the poses from f0 to fn
    distance_m: float  # straight line from f0 to fn
    min_inliers: int | None  # weakest VO step inside the segment (None: poses from a file)
    mean_inliers: float | None
    kept: bool
    reason: str  # why it was dropped; empty when kept
    label_pixels: int


def pose_file(seq: Sequence, cfg) -> Path:
    """The pose file label.poses.source=file reads for `seq`; InputError when there is none."""
    path = Path(cfg.poses.file.format(name=seq.name)) if cfg.poses.file else seq.poses_path
    if path is None:
        raise InputError(seq.root, "has no poses.txt (or poses/XX.txt) for label.poses.source=file")
    if not path.is_file():
        raise InputError(path, "is missing (label.poses.file)")
    return path


def check_inputs(seq: Sequence, cfg) -> None:
    """What label_sequence needs besides the images, checked before any work: footprint and poses."""
    footprint_for(seq, cfg.footprint)
    if cfg.poses.source == "vo":
        seq.require_stereo("the stereo odometry (label.poses.source=vo; give poses.txt and label.poses.source=file)")
    if cfg.poses.source == "file":
        file_poses(seq, cfg)


def file_poses(seq: Sequence, cfg) -> np.ndarray:
    """The sequence's poses from its file (label.poses), checked: rotations, and steps a vehicle can make."""
    return read_poses(pose_file(seq, cfg), expected_rows=len(seq), max_steps_m=max_steps(seq.times, len(seq), cfg.poses.max_speed_mps))


def poses_for(seq: Sequence, cfg) -> tuple[np.ndarray, OdometryRun | None]:
    if cfg.poses.source == "vo":
        run = run_odometry(seq, OdometryConfig(**cfg.odometry))
        return run.poses, run
    if cfg.poses.source == "file":
        return file_poses(seq, cfg), None
    raise ValueError(f"unknown label.poses.source {cfg.poses.source!r}; valid: {', '.join(POSE_SOURCES)}")


def measured_depth(seq: Sequence, f0: int, disparity: np.ndarray | None, cfg) -> np.ndarray:
    """Depth seen at f0 for the occlusion test: from stereo, or the renderer's exact depth."""
    if cfg.depth == "stereo":
        seq.require_stereo("occlusion from stereo depth (label.occlusion.depth=stereo)")
        return depth_from_disparity(disparity, seq.calibration.fx, seq.calibration.baseline_m)
    if cfg.depth == "ground_truth":
        return seq.load_depth(f0)
    raise ValueError(f"unknown label.occlusion.depth {cfg.depth!r}; valid: {', '.join(OCCLUSION_DEPTHS)}")


def label_sequence(seq: Sequence, cfg, out_dir: Path) -> dict:
    """Write labels, disparities, poses and reports of one sequence into out_dir; returns a summary."""
    footprint = footprint_for(seq, cfg.footprint)
    poses, run = poses_for(seq, cfg)
    positions = poses[:, :3, 3]
    travelled = distance_along(positions)
    out_dir.mkdir()  # not parents: a worker must not re-create a stopped run's temporary folder
    for sub in ("label",) if seq.mono else ("label", "disparity"):
        (out_dir / sub).mkdir()

    reports = []
    for f0, fn in select_segments(positions, cfg.distance_m, cfg.strategy, cfg.stride_m, cfg.min_motion_m):
        report = SegmentReport(
            f0, fn, float(travelled[fn] - travelled[f0]), float(np.linalg.norm(positions[fn] - positions[f0])), None, None, True, "", 0
        )
        if run is None or odometry_holds(run, report):
            label_segment(seq, report, poses, footprint, cfg, out_dir)
        reports.append(report)

    _write_csv(out_dir / "report.csv", [asdict(r) for r in reports], [f.name for f in fields(SegmentReport)])
    summary = {
        "name": out_dir.name,
        "root": str(seq.root),
        "frames": len(seq),
        "poses_source": cfg.poses.source,
        "segments": len(reports),
        "kept": sum(r.kept for r in reports),
        "dropped": sum(not r.kept for r in reports),
        "drift": None,
        "warnings": [],
    }
    if seq.mono:  # only then: a stereo run's summary keeps its bytes
        summary["one_camera"] = True
    if run is None:  # the poses the labels were made from, beside them (label.poses.file may be a pattern)
        (out_dir / "poses.txt").write_text(poses_to_text(poses))
    else:
        summary |= write_odometry(out_dir, run, seq, cfg.distance_m, cfg.odometry.disparity_offset_warn_px)
    if not reports:
        summary["warnings"].append(
            f"no label: the {'estimated ' if run is not None else ''}path ({travelled[-1]:.1f} m over {len(seq)} frames) never gets "
            f"{cfg.distance_m:g} m (label.distance_m) from a frame"
            + (f"; {summary['vo_failed_steps']} of {len(run.steps)} odometry steps failed" if run is not None else "")
        )
    for r in reports:
        if not r.kept:
            log.warning("%s: dropped segment %d-%d: %s", seq.name, r.f0, r.fn, r.reason)
    for warning in summary["warnings"]:
        log.warning("%s: %s", seq.name, warning)
    return summary


def label_segment(seq: Sequence, report: SegmentReport, poses: np.ndarray, footprint: VehicleFootprint, cfg, out_dir: Path) -> None:  # noqa: PLR0913, PLR0917
    """Write the segment's label (and f0's disparity, with stereo) into out_dir; fill the report's
    label pixels, or drop it when the footprint falls outside the image. One camera: no disparity,
    no occlusion (the label stage's log says so once)."""
    f0, occlusion_cfg = report.f0, cfg.occlusion
    if seq.mono:  # decoded, as the stereo odometry decodes every image: a broken one is named now, not at training
        seq.load_left(f0)
    disparity = None if seq.mono else compute_disparity(sgbm(cfg.disparity), seq.load_left(f0, grey=True), seq.load_right(f0, grey=True))
    occlusion = (
        Occlusion(measured_depth(seq, f0, disparity, occlusion_cfg), occlusion_cfg.margin_m, occlusion_cfg.margin_rel)
        if occlusion_cfg.enabled and disparity is not None
        else None
    )
    mask = path_label(seq, poses, (f0, report.fn), footprint, occlusion)
    report.label_pixels = int(np.count_nonzero(mask))
    if report.label_pixels == 0:
        report.kept, report.reason = False, "the footprint falls outside the image"
        return
    name = f"{f0:06d}.png"
    write_image(out_dir / "label" / name, mask)
    if disparity is not None:
        write_image(out_dir / "disparity" / name, encode_disparity(disparity))


def odometry_holds(run: OdometryRun, report: SegmentReport) -> bool:
    """Fill the segment's inlier figures; False (the segment dropped, with the reason) when a VO
    step inside it failed."""
    steps = run.steps[report.f0 : report.fn]
    report.min_inliers = min(s.inliers for s in steps)
    report.mean_inliers = float(np.mean([s.inliers for s in steps]))
    failed = [k for k in range(report.f0, report.fn) if not run.steps[k].ok]
    if failed:
        k = failed[0]
        report.kept, report.reason = False, f"odometry failed from frame {k} to {k + 1}: {run.steps[k].reason}"
    return not failed


def write_odometry(out_dir: Path, run: OdometryRun, seq: Sequence, segment_m: float, warn_offset_px: float) -> dict:
    """poses_vo.txt, steps.csv (every step, with the fallback that made it and the disparity offset
    estimated after it) and, when the sequence has its own poses, drift.csv (every scored segment);
    the summary's VO figures, with a warning when the rig's estimated offsets pass warn_offset_px."""
    (out_dir / "poses_vo.txt").write_text(poses_to_text(run.poses))
    columns = ["from", "to", "ok", "keyframe", "features", "tracked", "inliers", "fallback", "reason", "disparity_offset_px"]
    rows = [{"from": k, "to": k + 1, **{c: getattr(s, c) for c in columns[2:]}} for k, s in enumerate(run.steps)]
    _write_csv(out_dir / "steps.csv", rows, columns)
    fallbacks = Counter(s.fallback for s in run.steps if s.fallback)
    found: dict = {
        "vo_failed_steps": int(run.failed.sum()),
        "vo_pieces": len(run.pieces),
        "vo_fallbacks": {name: fallbacks.get(name, 0) for name in FALLBACKS},
        "vo_disparity_offset_px": run.disparity_offset_px,
        "vo_row_offset_px": run.row_offset_px,
        "drift": None,
        "warnings": [],
    }
    for what, offset in (("disparity", run.disparity_offset_px), ("row", run.row_offset_px)):
        if offset is not None and abs(offset) > warn_offset_px:
            found["warnings"].append(
                f"the odometry estimated a {what} offset of {offset:+.2f} px between the rectified images "
                f"(beyond label.odometry.disparity_offset_warn_px = {warn_offset_px:g}): the rig needs recalibrating"
            )
    if seq.poses is not None:
        result, problem = drift(run.poses, seq.poses, segment_m, run.pieces)
        if problem:
            found["warnings"].append(f"no drift figure: {problem}")
        else:
            found["drift"] = result.summary()
            _write_csv(out_dir / "drift.csv", result.segments, list(result.segments[0]))
    return found


def _write_csv(path: Path, rows: list[dict], fieldnames: list[str]) -> None:
    with open(path, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=fieldnames)
        writer.writeheader()
        writer.writerows(rows)


def label_job(args: tuple[str, str, DictConfig]) -> dict:
    """One sequence labelled in a worker of the label stage ((its folder, the output folder, the
    config)); a module's function, so that it pickles by name under any launcher."""
    cv2.setNumThreads(1)
    # OpenCV's kernels chosen by CPU (AVX2, AVX-512, IPP's) round differently from its baseline ones
    # (SSE2/SSE3, on every x86-64 CPU): the corners, tracks and PnP, and so the labels, moved with them.
    cv2.setUseOptimized(False)
    root, out_dir, cfg = args
    return label_sequence(open_sequence(root), cfg, Path(out_dir))
