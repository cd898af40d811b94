"""Ingest throughput: rectified 512 x 288 stereo pairs written per second, from each kind of input,
beside the label stage's throughput on the same sequence (one process each, in one run).

    python benchmarks/ingest_speed.py [--frames 100]

A drive is rendered, recorded by the raw test rig of tests/raw_rig.py (its own K and distortion
per camera, the right one rotated) into a ROS 2 bag of raw rgb8 images, a ROS 1 bag of PNG
CompressedImage and two MP4 files, and each is ingested (decode, pair, rectify, write PNGs,
epipolar check, preview). Then the label stage runs on the ingested sequence with one worker.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import cv2

ROOT = Path(__file__).resolve().parents[1]

from raw_rig import body_poses, raw_frames, raw_rig, write_bag, write_videos  # noqa: E402

from offroad_path.config import load_config  # noqa: E402
from offroad_path.ingest import ingest  # noqa: E402
from offroad_path.label import label  # noqa: E402
from offroad_path.world.record import record_sequence  # noqa: E402

TOPICS = ["ingest.topics.left=/stereo/left/image_raw", "ingest.topics.right=/stereo/right/image_raw"]


def timed(what: str, frames: int, run) -> float:
    start = time.perf_counter()
    run()
    elapsed = time.perf_counter() - start
    print(f"{what}: {frames} frames in {elapsed:.2f} s: {frames / elapsed:.1f} frames/s")
    return elapsed


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=100)
    args = parser.parse_args()
    cv2.setNumThreads(1)  # one core per process, as the stages' workers run
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        drive = root / "render" / "drive"
        record_sequence(load_config(f"world.frames={args.frames}").world, seed=21, out_dir=drive)
        rig = raw_rig(drive)
        frames = raw_frames(drive, rig)
        ros2 = write_bag(root / "ros2", "sqlite3", frames, rig, poses=body_poses(drive))
        ros1 = write_bag(root / "drive.bag", "ros1", frames, rig, compressed=(True, True))
        left, right = write_videos(root, frames, fps=5.0, right_offset=3)
        calibration = root / "stereo.yaml"
        from offroad_path.recordings.rig_calibration import CameraModel, StereoRig, write_opencv

        write_opencv(
            calibration, StereoRig(*[CameraModel(K, D, rig.size) for K, D in zip(rig.K, rig.D, strict=True)], rig.R, rig.T, calibration)
        )
        n = len(frames)
        compressed = [t + "/compressed" for t in TOPICS]
        videos = [f"ingest.videos.left={left}", f"ingest.videos.right={right}", f"ingest.calibration={calibration}"]
        runs = {
            "ROS 2 bag (SQLite), raw rgb8, with /odom": [f"ingest.bag={ros2}", *TOPICS, "ingest.topics.odometry=/odom"],
            "ROS 1 bag, PNG CompressedImage": [f"ingest.bag={ros1}", *compressed],
            "two MP4 files, offset given": [*videos, "ingest.videos.offset_frames=-3"],
            "two MP4 files, offset estimated": [*videos, "ingest.videos.max_offset_frames=30"],
        }
        for i, (what, overrides) in enumerate(runs.items()):
            timed(
                f"ingest, {what}",
                n - 3 * ("MP4" in what),
                lambda o=overrides, i=i: ingest(load_config(*o, f"ingest.out_dir={root / f'out{i}' / 'drive'}")),
            )
        out = root / "labels"
        timed("label stage (windowed VO), 1 worker, on the ROS 2 ingest", n, lambda: label(load_config(
            f"label.in_dir={root / 'out0'}", f"label.out_dir={out}", f"label.metrics_path={root / 'm.json'}", "label.workers=1",
            "mlflow.enabled=false", "label.footprint.width_m=1.9", "label.footprint.front_m=1.7", "label.footprint.rear_m=-2.5",
            "label.footprint.camera_height_m=1.8", "label.footprint.camera_pitch_deg=7.2")))  # fmt: skip


if __name__ == "__main__":
    main()
