"""Stage `postprocess`: the paper's post-processing of one run's test-set confidence maps (see
offroad_path.inference.path_filter and docs/design.md).

    python -m offroad_path.postprocess model=unet pretraining=none [postprocess.sigma=4]

Reads postprocess.predictions_dir (the train stage's predictions/) and the stereo disparity of each
sample's f0 (from the label stage); writes postprocess.out_dir with the same layout: float16 .npy
maps per sample and manifest.csv. A recording of one camera has no disparity: with
postprocess.use_depth=false its maps are post-processed without the depth mask (the log and the
evaluation report say so); with the default true it is refused, naming the sample.
"""

from __future__ import annotations

import logging
import time
from pathlib import Path

import numpy as np
from omegaconf import DictConfig

from offroad_path.data.loading import load_depth, load_maps
from offroad_path.data.manifest import Sample, manifest_folders, prediction_name, read_predictions_manifest, write_predictions_manifest
from offroad_path.errors import InputError
from offroad_path.inference.path_filter import PostprocessParams, postprocess
from offroad_path.stage import hydra_stage, reads
from offroad_path.utils.atomic import atomic_directory
from offroad_path.utils.outputs import Outputs

log = logging.getLogger("offroad_path.postprocess")

BATCH = 64  # maps in memory at once


def outputs(cfg: DictConfig) -> Outputs:
    postprocess_cfg = cfg.postprocess
    inputs = [postprocess_cfg.predictions_dir, *manifest_folders(Path(postprocess_cfg.predictions_dir) / "manifest.csv")]
    return Outputs("postprocess", folders={"postprocess.out_dir": postprocess_cfg.out_dir}, inputs=inputs)


@reads("postprocess", writes=outputs)
def run_postprocess(cfg: DictConfig) -> int:
    postprocess_cfg = cfg.postprocess
    params = PostprocessParams.from_config(postprocess_cfg)
    out_dir = Path(postprocess_cfg.out_dir)
    manifest = Path(postprocess_cfg.predictions_dir) / "manifest.csv"
    rows = read_predictions_manifest(manifest)
    if params.use_depth:
        check_depth([sample for sample, _ in rows], manifest)
    written, seconds = [], 0.0
    with atomic_directory(out_dir, "postprocess", key="postprocess.out_dir") as tmp:
        for start in range(0, len(rows), BATCH):
            batch = rows[start : start + BATCH]
            maps = load_maps([path for _, path in batch])  # (B, H, W)
            depth = np.stack([load_depth(sample) for sample, _ in batch]) if params.use_depth else None
            if depth is not None and depth.shape != maps.shape:
                raise ValueError(f"{batch[0][0].disparity}: disparity of shape {depth.shape[1:]} differs from the maps' {maps.shape[1:]}")
            t0 = time.perf_counter()
            filtered = postprocess(maps, depth, params)
            seconds += time.perf_counter() - t0
            for (sample, _), out in zip(batch, filtered, strict=True):
                name = prediction_name(sample)
                (tmp / name).parent.mkdir(parents=True, exist_ok=True)
                np.save(tmp / name, out.astype(np.float16))
                written.append((sample, str(out_dir / name)))
        write_predictions_manifest(tmp / "manifest.csv", written)
    log.info(
        "post-processed %d maps of %s into %s (%.2f ms per map)%s",
        len(written),
        postprocess_cfg.predictions_dir,
        out_dir,
        1000 * seconds / max(len(written), 1),
        "" if params.use_depth else ", without the depth mask (postprocess.use_depth=false)",
    )
    return len(written)


def check_depth(samples: list[Sample], manifest: Path) -> None:
    """The depth mask needs every sample's stereo disparity: refuse a recording of one camera."""
    mono = next((s for s in samples if not s.disparity), None)
    if mono is not None:
        raise InputError(
            manifest,
            f"{mono.sequence} has no disparity (a recording of one camera): the depth mask needs stereo; "
            "postprocess.use_depth=false post-processes without it",
        )


main = hydra_stage(run_postprocess)
