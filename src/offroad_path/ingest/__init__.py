"""Stage `ingest`: a real stereo recording to a rectified sequence that the label stage reads.

    python -m offroad_path.ingest ingest.bag=drive.bag ingest.list_topics=true   # what is inside
    python -m offroad_path.ingest ingest.bag=drive.bag ingest.topics.left=/stereo/left/image_raw \
        ingest.topics.right=/stereo/right/image_raw ingest.out_dir=data/recordings/drive
    python -m offroad_path.ingest ingest.videos.left=GOPR_L.MP4 ingest.videos.right=GOPR_R.MP4 \
        ingest.calibration=stereo.yaml ingest.fps=10 ingest.out_dir=data/recordings/gopro
    python -m offroad_path.ingest ingest.bag=drive.bag ingest.mono=true ingest.topics.left=/camera/image_raw \
        ingest.topics.odometry=/odometry/filtered   # one camera: poses from odometry or /tf

Reads a ROS 1 bag, a ROS 2 bag (SQLite or MCAP) or an MCAP file through `rosbags`, or two video
files with a calibration; pairs left and right by timestamp (or by the videos' estimated offset),
rectifies with OpenCV at ingest.width x ingest.height, and writes the sequence layout of
docs/design.md with a preview contact sheet. With ingest.mono=true, one camera's frames are
undistorted (image_l/ only) and its poses come from the odometry topic (a mono sequence).
Everything is checked before anything is written; a failure leaves nothing behind.
"""

from __future__ import annotations

import logging
from pathlib import Path

from omegaconf import DictConfig

from offroad_path.recordings.bags import Bag
from offroad_path.recordings.sources import open_source
from offroad_path.recordings.writer import write_sequence
from offroad_path.stage import hydra_stage, reads
from offroad_path.utils.atomic import atomic_directory
from offroad_path.utils.outputs import Outputs

log = logging.getLogger("offroad_path.ingest")


def list_topics(bag: str) -> list[str]:
    with Bag(bag) as opened:
        return [f"{topic}  {msgtype}  {count} messages" for topic, (msgtype, count) in opened.topics().items()]


def outputs(cfg: DictConfig) -> Outputs:
    ingest_cfg = cfg.ingest
    inputs = (ingest_cfg.bag, ingest_cfg.videos.left, ingest_cfg.videos.right, ingest_cfg.calibration, ingest_cfg.right_calibration)
    return Outputs("ingest", folders={} if ingest_cfg.list_topics else {"ingest.out_dir": ingest_cfg.out_dir}, inputs=inputs)


@reads("ingest", writes=outputs)
def ingest(cfg: DictConfig) -> dict:
    ingest_cfg = cfg.ingest
    if ingest_cfg.list_topics:
        if ingest_cfg.bag is None:
            raise ValueError("ingest.list_topics needs ingest.bag=PATH")
        for line in list_topics(ingest_cfg.bag):
            print(line)
        return {}
    out_dir = Path(ingest_cfg.out_dir)
    source = open_source(ingest_cfg)
    try:
        with atomic_directory(out_dir, "ingest", key="ingest.out_dir") as tmp:
            meta = write_sequence(source, ingest_cfg, tmp)
    finally:
        source.close()
    epipolar = "not measurable" if meta["epipolar_error_px"] is None else f"{meta['epipolar_error_px']:.2f} px"
    what = (
        f"undistorted frames of one camera %dx%d (fx {meta['fx']:.1f} px)"
        if ingest_cfg.mono
        else f"rectified stereo pairs %dx%d (baseline {meta['baseline_m']:.3f} m, fx {meta['fx']:.1f} px, epipolar error {epipolar})"
    )
    log.info(
        f"wrote %d {what}%s to %s",
        meta["frames"],
        ingest_cfg.width,
        ingest_cfg.height,
        f", {meta['distance_m']:.1f} m of poses" if "distance_m" in meta else "",
        out_dir,
    )
    return meta


main = hydra_stage(ingest)
