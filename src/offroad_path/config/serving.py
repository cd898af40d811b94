"""Schemas of what runs a trained network: predict (with its ROS output), export and the MLflow store."""

from __future__ import annotations

from dataclasses import dataclass, field

from omegaconf import MISSING

from offroad_path.config.common import PITCH, THREADS
from offroad_path.utils.rules import at_least, between, one_of, positive, setting


@dataclass
class RosOutputConfig:
    """predict with a bag input: the output bag's topics and the vehicle that steers by it."""

    namespace: str = MISSING
    frame_id: str | None = MISSING  # None: the left image's frame_id
    steering: str = setting(one_of(("ackermann", "twist")))
    speed_mps: float = setting(at_least(0))
    camera_height_m: float | None = setting(positive())  # None: ingest.footprint's
    camera_pitch_deg: float | None = setting(PITCH)  # of the raw left camera, down; None: ingest.footprint's
    wheelbase_m: float = setting(positive())
    rear_axle_behind_camera_m: float = setting(at_least(0))
    lookahead_m: float = setting(positive())
    jpeg_quality: int = setting(between(1, 100))


@dataclass
class PredictConfig:
    """Run a trained path model on new footage."""

    checkpoint: str | None = MISSING  # a train checkpoint (.ckpt) or an exported model (.onnx)
    run_id: str | None = MISSING  # or an MLflow training run: its best checkpoint
    input: str = MISSING  # a folder of images, a sequence folder (stereo, with calib.txt) or a video file
    out_dir: str = MISSING
    threshold: float = setting(between(0, 1))  # path where confidence > threshold, for the overlay
    postprocess: bool = MISSING  # the paper's post-processing (depth mask only for stereo sequences)
    video_fps: float | None = setting(positive())  # MP4 frame rate; None: the video's own, or the sequence's times, or 10
    max_frames: int | None = setting(at_least(1))
    # Images larger than this are refused from their header, before decoding (8K is 33 million).
    max_image_pixels: int = setting(at_least(1))
    device: str = MISSING
    threads: str = setting(THREADS)  # free (default): the cores not busy when predict starts
    ros: RosOutputConfig = field(default_factory=RosOutputConfig)


@dataclass
class ExportConfig:
    """ONNX export of a trained path model, checked against PyTorch."""

    checkpoint: str = MISSING
    out: str = MISSING  # outside DVC's outputs
    opset: int = setting(at_least(9))
    tolerance: float = setting(positive())  # max abs difference of the path confidence against PyTorch


@dataclass
class MlflowConfig:
    enabled: bool = MISSING
    experiment: str = MISSING
    # None: $MLFLOW_TRACKING_URI if set, else sqlite:///mlflow.db at the project root.
    tracking_uri: str | None = MISSING
    log_models: bool = MISSING  # each training run's network with its signature, and a registered version (training/published.py)
