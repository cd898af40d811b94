"""Schemas of the labelling side: poses, occlusion, the footprint, ingest, disparity, odometry, label and split."""

from __future__ import annotations

from dataclasses import dataclass, field

from omegaconf import MISSING

from offroad_path.config.common import IMAGE_SIZE, PITCH
from offroad_path.utils.rules import FINITE, SEED, at_least, between, numbers, one_of, positive, rule, setting

# The choices these schemas accept, each implemented by the module named beside it (which imports
# its list from here; tests/config/test_config.py checks an implementation that keys a table by them).
POSE_SOURCES = ("vo", "file")  # label.poses.source: label.labeller
OCCLUSION_DEPTHS = ("stereo", "ground_truth")  # label.occlusion.depth: label.labeller
ODOMETRY_METHODS = ("windowed", "frame_to_frame")  # label.odometry.method: odometry.sequence_trajectory.ESTIMATORS
FRAME_STRATEGIES = ("midway", "stride")  # label.strategy: label.frame_selection
SPLIT_STRATEGIES = ("grouped", "stretch", "random")  # split.strategy: data.splitting


@dataclass
class PosesConfig:
    # vo: stereo visual odometry; file: a KITTI-format pose file per sequence
    source: str = setting(one_of(POSE_SOURCES))
    # With source=file: a path pattern with {name} (the sequence folder's name), or None for
    # the sequence's own poses (poses.txt, or KITTI's poses/XX.txt).
    file: str | None = MISSING
    max_speed_mps: float = setting(positive())  # with source=file: a longer step between poses is refused


@dataclass
class OcclusionConfig:
    enabled: bool = MISSING  # beyond the paper: no path label on ground hidden behind a crest or obstacle
    # stereo: from the f0 disparity; ground_truth: the sequence's depth/ (synthetic)
    depth: str = setting(one_of(OCCLUSION_DEPTHS))
    margin_m: float = setting(at_least(0))
    margin_rel: float = setting(at_least(0))


@dataclass
class FootprintConfig:
    """The vehicle's ground footprint relative to the camera; None: take it from meta.json."""

    width_m: float | None = setting(positive())
    front_m: float | None = setting(FINITE)
    rear_m: float | None = setting(FINITE)
    camera_height_m: float | None = setting(positive())
    camera_pitch_deg: float | None = setting(PITCH)


@dataclass
class IngestTopicsConfig:
    left: str | None = MISSING
    right: str | None = MISSING
    left_info: str | None = MISSING
    right_info: str | None = MISSING
    odometry: str | None = MISSING


@dataclass
class IngestVideosConfig:
    left: str | None = MISSING
    right: str | None = MISSING
    offset_frames: int | None = setting(FINITE)
    max_offset_frames: int = setting(at_least(1))


@dataclass
class IngestConfig:
    """A ROS bag or two videos to a rectified sequence (offroad_path.recordings)."""

    bag: str | None = MISSING
    list_topics: bool = MISSING
    mono: bool = MISSING  # one camera (topics.left) and poses from topics.odometry: a mono sequence
    tf_child_frame: str = MISSING  # with a TF topic as topics.odometry: the frame whose transforms are the poses
    max_speed_mps: float = setting(positive())  # an odometry step faster than this is refused
    topics: IngestTopicsConfig = field(default_factory=IngestTopicsConfig)
    videos: IngestVideosConfig = field(default_factory=IngestVideosConfig)
    calibration: str | None = MISSING
    right_calibration: str | None = MISSING
    calibration_unit_m: float = setting(positive())
    body_to_camera: list[float] | None = setting(numbers(16))  # a 4x4 matrix, row-major
    width: int = setting(IMAGE_SIZE)
    height: int = setting(IMAGE_SIZE)
    alpha: float = setting(between(0, 1))
    fps: float | None = setting(positive())
    sync_tolerance_s: float = setting(positive())
    max_unpaired_fraction: float = setting(between(0, 1))
    max_epipolar_px: float = setting(positive())
    footprint: FootprintConfig = field(default_factory=FootprintConfig)
    out_dir: str = MISSING


@dataclass
class DisparityConfig:
    """OpenCV StereoSGBM on the f0 pair; the disparity is written beside each label."""

    num_disparities: int = setting(rule(lambda v: v > 0 and v % 16 == 0, "must be a positive multiple of 16"))
    block_size: int = setting(rule(lambda v: v >= 1 and v % 2 == 1, "must be an odd number >= 1"))
    uniqueness_ratio: int = setting(between(0, 100))
    speckle_window: int = setting(at_least(0))
    speckle_range: int = setting(at_least(0))


@dataclass
class OdometryConfig:
    """Stereo visual odometry (offroad_path.odometry): the front end's settings are shared; the
    window, fallback and depth-weighting settings are the windowed estimator's."""

    method: str = setting(one_of(ODOMETRY_METHODS))
    max_features: int = setting(at_least(1))
    bucket_rows: int = setting(at_least(1))
    bucket_cols: int = setting(at_least(1))
    corner_quality: float = setting(between(0, 1, low_open=True))  # corners weaker than this fraction of the strongest are ignored
    lk_window: int = setting(at_least(3))  # small windows: less perspective distortion of slanted ground between views
    lk_levels: int = setting(at_least(0))
    max_row_error_px: float = setting(positive())  # stereo matches must stay on the same row (rectified)
    min_disparity_px: float = setting(positive())
    max_depth_m: float = setting(positive())
    forward_backward_px: float = setting(positive())
    ransac_reprojection_px: float = setting(positive())
    ransac_iterations: int = setting(at_least(1))
    refine_iterations: int = setting(at_least(0))
    huber_px: float = setting(positive())
    min_inliers: int = setting(at_least(4))
    window: int = setting(at_least(2))  # keyframes in the bundle adjustment
    keyframe_distance_m: float = setting(at_least(0))  # a frame this far from the last keyframe becomes one
    window_iterations: int = setting(at_least(1))
    stereo_depth_m: float = setting(positive())  # beyond it, the right image's sigma grows as (z / this)^2
    max_skipped_frames: int = setting(at_least(0))
    fallback_feature_factor: int = setting(at_least(1))
    # The rig's disparity offset, estimated in the bundle adjustment: its prior's sigma at a
    # sequence's start (0: not estimated), and the estimate beyond which the stage warns.
    disparity_offset_sigma_px: float = setting(at_least(0))
    disparity_offset_every: int = setting(at_least(1))  # windows: every n-th one estimates it, the rest use it
    disparity_offset_warn_px: float = setting(positive())


@dataclass
class LabelConfig:
    in_dir: str = MISSING
    out_dir: str = MISSING
    metrics_path: str = MISSING
    distance_m: float = setting(positive())
    strategy: str = setting(one_of(FRAME_STRATEGIES))
    stride_m: float = setting(at_least(0.05))  # denser than the frames gives no more labels; the stage also wants it <= distance_m
    min_motion_m: float = setting(at_least(0))
    poses: PosesConfig = field(default_factory=PosesConfig)
    occlusion: OcclusionConfig = field(default_factory=OcclusionConfig)
    footprint: FootprintConfig = field(default_factory=FootprintConfig)
    odometry: OdometryConfig = field(default_factory=OdometryConfig)
    disparity: DisparityConfig = field(default_factory=DisparityConfig)
    workers: int = setting(at_least(0))
    shards: int = setting(at_least(1))  # label.shard of label.shards: this job labels every shards-th sequence (label/shards.py)
    shard: int = setting(at_least(0))
    merge_from: str | None = MISSING  # a folder of shard folders to merge into out_dir, instead of labelling


@dataclass
class SplitConfig:
    labels_dir: str = MISSING
    out_dir: str = MISSING
    # grouped: by blocks of driving, no leakage; stretch: each recording's last stretch; random: the paper's per-image split
    strategy: str = setting(one_of(SPLIT_STRATEGIES))
    test_fraction: float = setting(between(0, 1, low_open=True, high_open=True))
    val_fraction: float = setting(between(0, 1, high_open=True))
    block_m: float = setting(positive())
    guard_m: float = setting(at_least(0))
    mirror: bool = MISSING
    seed: int = setting(SEED)
