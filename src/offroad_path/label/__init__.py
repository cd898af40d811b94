"""Stage `label`: stereo visual odometry and vehicle-footprint path labels (see docs/design.md).
A sequence of one camera (no right images) is labelled from its pose file, without occlusion and
without disparity/; the stage says so once.

    python -m offroad_path.label [label.in_dir=/my/recordings] [label.poses.source=file]
        [label.strategy=stride label.stride_m=5] [label.occlusion.enabled=false]

Reads every sequence under label.in_dir and writes, per sequence, under label.out_dir:
label/NNNNNN.png (0/255 path masks at each f0), disparity/NNNNNN.png (StereoSGBM of f0, KITTI
format: uint16 = 256 x disparity), poses_vo.txt and steps.csv (with VO) or poses.txt (the file's), report.csv (every
segment, kept or dropped and why); and summary.json for the run, metrics for DVC and MLflow.

Across machines: label.shards=N label.shard=i labels every N-th sequence from the i-th into a
folder of its own, and label.merge_from=FOLDER merges those into what one run writes, byte for
byte (label/shards.py).
"""

from __future__ import annotations

import json
import logging
import shutil
from contextlib import nullcontext
from pathlib import Path

import numpy as np
from omegaconf import DictConfig

from offroad_path.label import shards
from offroad_path.label.labeller import check_inputs, label_job
from offroad_path.odometry.steps import FALLBACKS
from offroad_path.sequence.reader import find_sequences, open_sequence, sequence_names
from offroad_path.stage import hydra_stage, reads
from offroad_path.utils.atomic import atomic_directory, write_text_atomic
from offroad_path.utils.blas_kernels import pinned_blas
from offroad_path.utils.outputs import Outputs
from offroad_path.utils.parallel import map_processes
from offroad_path.utils.rules import ConfigValueError
from offroad_path.utils.tracking import stage_run

log = logging.getLogger("offroad_path.label")


def drift_metrics(drifts: list[dict]) -> dict[str, float]:
    """Over the sequences with a drift figure: the mean and the worst sequence's drift, and the
    extreme scale ratios of any segment and any step."""
    return {
        "translation_drift_pct": float(np.mean([d["translation_drift_pct"] for d in drifts])),
        "translation_drift_pct_worst": max(d["translation_drift_pct"] for d in drifts),
        "rotation_drift_deg_per_m": float(np.mean([d["rotation_drift_deg_per_m"] for d in drifts])),
        "rotation_drift_deg_per_m_worst": max(d["rotation_drift_deg_per_m"] for d in drifts),
        "scale_ratio_min": min(d["scale_ratio_min"] for d in drifts),
        "scale_ratio_max": max(d["scale_ratio_max"] for d in drifts),
        "step_scale_ratio_min": min(d["step_scale_ratio_min"] for d in drifts),
        "step_scale_ratio_max": max(d["step_scale_ratio_max"] for d in drifts),
    }


def offset_metrics(summaries: list[dict]) -> dict[str, float]:
    """The rig offsets the odometry estimated: the mean over sequences and the largest in size."""
    metrics = {}
    for what in ("disparity", "row"):
        offsets = [s[f"vo_{what}_offset_px"] for s in summaries if s.get(f"vo_{what}_offset_px") is not None]
        if offsets:
            metrics[f"vo_{what}_offset_px_mean"] = float(np.mean(offsets))
            metrics[f"vo_{what}_offset_px_largest"] = float(max(offsets, key=abs))
    return metrics


def run_metrics(summaries: list[dict], in_dir: Path, need_labels: bool = True) -> dict:
    """The run's metrics from its sequences' summaries; ValueError when no label could be made and
    `need_labels` (a shard may have none: the run is judged when the shards are merged)."""
    drifts = [s["drift"] for s in summaries if s["drift"]]
    metrics = {
        "sequences": len(summaries),
        "labels": sum(s["kept"] for s in summaries),
        "segments_dropped": sum(s["dropped"] for s in summaries),
        "vo_failed_steps": sum(s.get("vo_failed_steps", 0) for s in summaries),
        "warnings": sum(len(s["warnings"]) for s in summaries),
    }
    if any("vo_fallbacks" in s for s in summaries):
        for name in FALLBACKS:
            metrics[f"vo_{name}"] = sum(s["vo_fallbacks"][name] for s in summaries if "vo_fallbacks" in s)
    if drifts:
        metrics |= drift_metrics(drifts)
    metrics |= offset_metrics(summaries)
    mono = sum(s.get("one_camera", False) for s in summaries)
    if mono:  # the key only then: a stereo run's metrics keep their bytes
        metrics["one_camera_sequences"] = mono
    if need_labels and not metrics["labels"]:
        raise ValueError(f"{in_dir}: no label could be made; " + "; ".join(f"{s['name']}: {w}" for s in summaries for w in s["warnings"]))
    return metrics


def sharded(cfg: DictConfig) -> bool:
    return cfg.label.shards > 1


def stage_name(cfg: DictConfig) -> str:
    """What the output's marker names: a shard is not a label run, so neither replaces the other."""
    return "label_shard" if sharded(cfg) else "label"


def outputs(cfg: DictConfig) -> Outputs:
    label_cfg = cfg.label
    files = {} if sharded(cfg) else {"label.metrics_path": label_cfg.metrics_path}  # a shard's metrics stay in its folder
    return Outputs(
        stage_name(cfg), folders={"label.out_dir": label_cfg.out_dir}, files=files, inputs=[label_cfg.in_dir, label_cfg.merge_from]
    )


@reads("label", "mlflow", writes=outputs)
def label(cfg: DictConfig) -> dict:
    in_dir, out_dir = Path(cfg.label.in_dir), Path(cfg.label.out_dir)
    if cfg.label.strategy == "stride" and cfg.label.stride_m > cfg.label.distance_m:
        raise ConfigValueError(f"label.stride_m={cfg.label.stride_m:g}: must be at most label.distance_m ({cfg.label.distance_m:g})")
    if cfg.label.merge_from and sharded(cfg):
        raise ConfigValueError(f"label.merge_from={cfg.label.merge_from}: merges every shard; leave label.shards at 1")
    roots = find_sequences(in_dir)
    names = sequence_names(roots, in_dir)
    if cfg.label.merge_from:
        merged = shards.read_shards(cfg.label, names)
    else:
        picked = shards.chosen(names, cfg.label)
        roots, names = [roots[i] for i in picked], [names[i] for i in picked]
        for root in roots:  # validate everything before any work
            check_inputs(open_sequence(root), cfg.label)
    with (
        stage_run(cfg, "label") if not sharded(cfg) else nullcontext() as run,
        atomic_directory(out_dir, stage_name(cfg), key="label.out_dir") as tmp,
    ):
        if cfg.label.merge_from:
            for folder, summary in merged:
                shutil.copytree(folder / summary["name"], tmp / summary["name"])
            summaries = [summary for _, summary in merged]
        else:
            jobs = [(str(root), str(tmp / name), cfg.label) for root, name in zip(roots, names, strict=True)]
            # in workers whose OpenBLAS (NumPy's and OpenCV's) takes the same kernels on every CPU: the same labels
            summaries = map_processes(label_job, jobs, cfg.label.workers, [str(root) for root in roots], "label", env=pinned_blas())
        metrics = run_metrics(summaries, in_dir, need_labels=not sharded(cfg))
        if metrics.get("one_camera_sequences"):
            log.warning(
                "%d of %d sequences have one camera: labelled from their poses without %sdisparity (they need a right image)",
                metrics["one_camera_sequences"],
                metrics["sequences"],
                "occlusion and " if cfg.label.occlusion.enabled else "",
            )
        (tmp / "summary.json").write_text(json.dumps({"metrics": metrics, "sequences": summaries}, indent=2) + "\n")
        if sharded(cfg):
            (tmp / shards.SHARD_FILE).write_text(shards.shard_record(cfg.label, names))
        else:
            # Before the labels replace the last run's: a metrics file that cannot be written (a full
            # disk) leaves both as they were.
            write_text_atomic(cfg.label.metrics_path, json.dumps(metrics, indent=2) + "\n", "label")
        if run is not None:
            import mlflow

            mlflow.log_metrics(metrics)
            mlflow.log_artifact(str(tmp / "summary.json"))
    log.info(
        "labelled %d sequences%s: %d segments kept, %d dropped, %d labels written to %s%s",
        metrics["sequences"],
        f" (shard {cfg.label.shard} of {cfg.label.shards})" if sharded(cfg) else "",
        metrics["labels"],
        metrics["segments_dropped"],
        metrics["labels"],
        out_dir,
        f"; VO drift {metrics['translation_drift_pct']:.2f} % (worst sequence {metrics['translation_drift_pct_worst']:.2f} %), "
        f"{metrics['rotation_drift_deg_per_m']:.4f} deg/m"
        if "translation_drift_pct" in metrics
        else "",
    )
    return metrics


main = hydra_stage(label)
