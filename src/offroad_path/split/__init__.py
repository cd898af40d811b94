"""Stage `split`: train / validation / test manifests of the labelled frames (see docs/design.md).

    python -m offroad_path.split [split.strategy=random] [split.mirror=false]

Frames are split by blocks of driving (see offroad_path.data.splitting) with a fixed seed;
each frame's mirrored copy is added beside it, in the same split.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path

from omegaconf import DictConfig

from offroad_path.data.labels import label_run_folders, read_label_run
from offroad_path.data.manifest import Sample, data_root, write_manifest
from offroad_path.data.splitting import Frame, block_of, split_frames
from offroad_path.sequence import meta
from offroad_path.stage import hydra_stage, reads
from offroad_path.utils.atomic import atomic_directory
from offroad_path.utils.outputs import Outputs
from offroad_path.utils.tracking import stage_run

log = logging.getLogger("offroad_path.split")


def labelled_frames(labels_dir: Path) -> tuple[list[Frame], dict[tuple[str, int], Sample]]:
    """Every labelled f0 under labels_dir, with its position along the path, whether it comes from
    a held-out world (and whether that is a development world), and its sample row."""
    frames, samples = [], {}
    for run in read_label_run(labels_dir):
        name, seq, travelled = run.name, run.sequence, run.distance()
        held_out = meta.held_out(seq.meta, seq.root / "meta.json")
        development = held_out and meta.test_set(seq.meta) == meta.DEVELOPMENT
        for label in run.labels():
            f0 = int(label.stem)
            frames.append(Frame(name, f0, float(travelled[f0]), held_out, development))
            semantic = str(seq.semantic[f0]) if seq.semantic is not None else ""
            samples[(name, f0)] = Sample(
                name,
                f0,
                False,
                str(seq.left[f0]),
                str(label),
                "" if seq.mono else str(run.folder / "disparity" / label.name),  # one camera: no disparity
                semantic,
                seq.calibration.fx,
                seq.calibration.baseline_m,
            )
    return frames, samples


def outputs(cfg: DictConfig) -> Outputs:
    return Outputs("split", folders={"split.out_dir": cfg.split.out_dir}, inputs=label_run_folders(cfg.split.labels_dir))


@reads("split", "mlflow", writes=outputs)
def split(cfg: DictConfig) -> dict:
    split_cfg = cfg.split
    frames, samples = labelled_frames(Path(split_cfg.labels_dir))
    if not frames:
        raise ValueError(f"{split_cfg.labels_dir}: holds no labels to split")
    parts, guarded = split_frames(frames, split_cfg)
    counts = {}
    listed = [split_cfg.labels_dir, *(p for sample in samples.values() for p in (sample.image, sample.label))]
    with stage_run(cfg, "split") as run, atomic_directory(split_cfg.out_dir, "split", key="split.out_dir") as tmp:
        for name, part in parts.items():
            rows = []
            for frame in part:
                sample = samples[(frame.sequence, frame.f0)]
                rows.append(sample)
                if split_cfg.mirror:
                    rows.append(Sample(**{**sample.__dict__, "mirrored": True}))
            write_manifest(tmp / f"{name}.csv", rows)
            counts[name] = len(rows)
        worlds = sorted({f.sequence for f in frames if f.held_out and not f.development})
        test_blocks = len({block_of(f.sequence, f.travelled_m, split_cfg.block_m) for f in parts["test"]})
        summary = {
            "frames": len(frames),
            "guarded_out": guarded,
            "samples": counts,
            "strategy": split_cfg.strategy,
            "mirror": split_cfg.mirror,
            "test_worlds": worlds,
            "development_worlds": sorted({f.sequence for f in frames if f.development}),
            "test_blocks": test_blocks,
            "data_root": data_root(listed),
        }
        (tmp / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
        if run is not None:
            import mlflow

            mlflow.log_metrics({"frames": len(frames), "guarded_out": guarded, "test_blocks": test_blocks, **counts})
    log.info(
        "split %d labelled frames: %s samples%s, %d training frames left out beside held-out ones; test: %d blocks of driving%s",
        len(frames),
        counts,
        " (with mirrored copies)" if split_cfg.mirror else "",
        guarded,
        test_blocks,
        f" from {len(worlds)} held-out test worlds" if worlds else " from the drives",
    )
    return summary


main = hydra_stage(split)
