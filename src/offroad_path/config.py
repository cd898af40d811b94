"""Typed schemas of the Hydra configuration, registered in Hydra's ConfigStore.

The values live in the YAML files under `conf/`, once; these schemas hold only types and rules
(`setting(positive())`: checked by `validate_config` before a stage works). A misspelt key or a
value of the wrong type fails at composition, a value a rule refuses before any work, each with
an error naming the key. Library code reads its settings from a composed config
(`load_config()`), never from defaults of its own.
"""

from __future__ import annotations

import importlib
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from hydra import compose, initialize_config_dir
from hydra.core.config_store import ConfigStore
from omegaconf import MISSING, DictConfig, OmegaConf

from offroad_path.looks import axis_values
from offroad_path.utils.rules import Rule, at_least, between, each, numbers, one_of, positive, rule, setting, validate
from offroad_path.utils.threads import is_thread_setting

CONF_DIR = Path(__file__).resolve().parents[2] / "conf"
IMAGE_SIZE = between(16, 8192)  # pixels of an image side
MAX_STEPS = rule(lambda v: v == -1 or v >= 1, "must be -1 (no cap) or an integer >= 1")  # SGD steps, besides max_epochs
FINITE = rule(lambda v: True, "must be a finite number")
PITCH = between(-90, 90, low_open=True, high_open=True)  # a camera's pitch in degrees, down
THREADS = {"rule": Rule(is_thread_setting, "must be all, free or a whole number >= 1")}  # offroad_path.utils.threads


def config_names(group: str) -> Callable[[], list[str]]:
    """The choices of a config group that has one file per implemented choice (conf/<group>/<name>.yaml):
    tests check them against the registry that implements them (offroad_path.models.MODELS,
    offroad_path.training.pretrained.CHOICES), which validating a value then need not import (torch)."""
    return lambda: sorted(p.stem for p in (CONF_DIR / group).glob("*.yaml"))


_model_names = config_names("model")


def registry(module: str, name: str) -> Callable[[], list[str]]:
    """The valid names of a choice, read from the registry `module.name` that implements it when a
    value is checked (a stage checks only the groups it reads, so it imports only its own modules)."""
    return lambda: list(getattr(importlib.import_module(f"offroad_path.{module}"), name))


PRETRAININGS = config_names("pretraining")


@dataclass
class PathsConfig:
    """Where the stages read and write (conf/paths): every stage's *_dir and *_path is made from these."""

    root: str = MISSING
    data_dir: str = MISSING
    metrics_dir: str = MISSING
    recordings_dir: str = MISSING
    logs_dir: str = MISSING
    exports_dir: str = MISSING
    predictions_dir: str = MISSING


@dataclass
class RigConfig:
    name: str = MISSING
    baseline_m: float = MISSING


@dataclass
class VehicleConfig:
    width_m: float = setting(positive())
    length_m: float = setting(positive())
    wheelbase_m: float = setting(positive())
    track_m: float = setting(positive())
    camera_height_m: float = setting(positive())
    camera_forward_m: float = setting(FINITE)  # camera ahead of the body centre
    camera_pitch_deg: float = setting(PITCH)  # optical axis tilted down
    max_steering_deg: float = setting(between(0, 90, low_open=True, high_open=True))


@dataclass
class SlipConfig:
    """Traction below the kinematic bicycle model's (offroad_path.world.slip): off by default."""

    enabled: bool = MISSING  # synthesize: the recorded steering is the input that made the motion under slip
    factors: dict[str, float] = setting(each(positive()))  # yaw-rate factor per surface class name; 1 where absent
    # The factor's jitter is drawn once per square patch this wide (a grid over the whole world: smaller ones do not fit memory).
    patch_m: float = setting(at_least(0.5))
    jitter: float = setting(between(0, 1, high_open=True))  # patch factors in [1 - jitter, 1 + jitter] times the surface's
    noise: float = setting(at_least(0))  # per-step (per-frame) noise of the factor, a standard deviation


def _valid_looks(combinations: Any) -> bool:
    axes = axis_values()
    return all(c and all(axes.get(k) and v in axes[k] for k, v in c.items()) for c in combinations)


LOOKS = {
    "rule": Rule(
        _valid_looks,
        "must list combinations such as {track: mud, season: autumn} of the axes track, season, light, vegetation",
    )
}


def _valid_weights(weights: Any) -> bool:
    axes = axis_values()
    return all(
        axis in axes
        and set(values) <= set(axes[axis])
        and all(isinstance(w, int | float) and w >= 0 for w in values.values())
        and sum(values.values()) > 0
        for axis, values in weights.items()
    )


WEIGHTS = {
    "rule": Rule(
        _valid_weights,
        "must map axes (track, season, light, vegetation) to {value: weight >= 0} with a positive weight on each axis",
    )
}


@dataclass
class AppearanceConfig:
    """Each world's look drawn from a stream of its own (offroad_path.world.appearance)."""

    enabled: bool = MISSING  # false: the single look of the worlds before issue 44, byte for byte
    # Looks no training drive shows; every other test world is drawn from them (the held-out-appearance test set).
    held_out: list[dict[str, str]] = setting(LOOKS)
    # The training distribution: per axis, each value's weight (absent or 0: no training drive shows it); an
    # axis not listed draws its values alike. The stress set `outside_look` draws from every value alike.
    weights: dict[str, Any] = setting(WEIGHTS)  # Any: OmegaConf cannot merge a typed dict of dicts


@dataclass
class WorldConfig:
    """One rendered sequence's generator settings; per-sequence variation is drawn around these."""

    rig: RigConfig = field(default_factory=RigConfig)
    vehicle: VehicleConfig = field(default_factory=VehicleConfig)
    frames: int = setting(at_least(2))
    fps: float = setting(positive())
    speed_min_mps: float = setting(positive())
    speed_max_mps: float = setting(positive())
    width: int = setting(IMAGE_SIZE)
    height: int = setting(IMAGE_SIZE)
    hfov_deg: float = setting(between(1, 179))
    max_distance_m: float = MISSING
    hill_height_m: float = MISSING
    bump_height_m: float = MISSING
    max_curvature: float = MISSING  # 1/m; the peak of a drive, reached once or twice per sequence
    track_width_m: float = MISSING
    trees_per_hectare: float = MISSING
    bushes_per_hectare: float = MISSING
    obstacles_per_100m: float = MISSING
    puddles_per_100m: float = MISSING
    forks_per_100m: float = MISSING
    offtrack_per_100m: float = MISSING
    paved_fraction: float = MISSING
    sun_elevation_deg: tuple[float, float] = MISSING
    density_jitter: float = MISSING  # per-sequence density factor drawn in [1 - j, 1 + j]
    slip: SlipConfig = field(default_factory=SlipConfig)
    appearance: AppearanceConfig = field(default_factory=AppearanceConfig)


@dataclass
class TestWorldsConfig:
    min_blocks: int = setting(at_least(0))  # the main test set's blocks; 0: no test worlds (the split takes test blocks from the drives)
    # Stress sets (offroad_path.world.held_out): condition groups (offroad_path.world.groups.GROUPS), each reported on its own.
    stress_sets: list[str] = setting(each(one_of(registry("world.groups", "GROUP_KEYS"))))
    per_stress: int = setting(at_least(0))  # worlds per stress set
    block_m: float = setting(positive())
    horizon_m: float = MISSING  # the last metres of a drive, which get no label (label.distance_m, whose rule checks it)
    max_candidates: int = setting(at_least(1))


@dataclass
class SynthesizeConfig:
    sequences: int = setting(at_least(1))
    seed: int = MISSING
    test_worlds: TestWorldsConfig = field(default_factory=TestWorldsConfig)
    workers: int = setting(at_least(0))  # 0: one per CPU core
    out_dir: str = MISSING


@dataclass
class PosesConfig:
    # vo: stereo visual odometry; file: a KITTI-format pose file per sequence
    source: str = setting(one_of(registry("labelling.labeller", "POSE_SOURCES")))
    # With source=file: a path pattern with {name} (the sequence folder's name), or None for
    # the sequence's own poses (poses.txt, or KITTI's poses/XX.txt).
    file: str | None = MISSING
    max_speed_mps: float = setting(positive())  # with source=file: a longer step between poses is refused


@dataclass
class OcclusionConfig:
    enabled: bool = MISSING  # beyond the paper: no path label on ground hidden behind a crest or obstacle
    # stereo: from the f0 disparity; ground_truth: the sequence's depth/ (synthetic)
    depth: str = setting(one_of(registry("labelling.labeller", "OCCLUSION_DEPTHS")))
    margin_m: float = setting(at_least(0))
    margin_rel: float = setting(at_least(0))


@dataclass
class FootprintConfig:
    """The vehicle's ground footprint relative to the camera; None: take it from meta.json."""

    width_m: float | None = MISSING
    front_m: float | None = MISSING
    rear_m: float | None = MISSING
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
    offset_frames: int | None = MISSING
    max_offset_frames: int = setting(at_least(1))


@dataclass
class IngestConfig:
    """A ROS bag or two videos to a rectified sequence (offroad_path.recordings)."""

    bag: str | None = MISSING
    list_topics: bool = MISSING
    mono: bool = MISSING  # one camera (topics.left) and poses from topics.odometry: a mono sequence
    tf_child_frame: str = MISSING  # with a TF topic as topics.odometry: the frame whose transforms are the poses
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
    uniqueness_ratio: int = MISSING
    speckle_window: int = MISSING
    speckle_range: int = MISSING


@dataclass
class OdometryConfig:
    """Stereo visual odometry (offroad_path.odometry): the front end's settings are shared; the
    window, fallback and depth-weighting settings are the windowed estimator's."""

    method: str = setting(one_of(registry("odometry.trajectory", "ESTIMATORS")))
    max_features: int = MISSING
    bucket_rows: int = MISSING
    bucket_cols: int = MISSING
    corner_quality: float = MISSING  # corners weaker than this fraction of the strongest are ignored
    lk_window: int = MISSING  # small windows: less perspective distortion of slanted ground between views
    lk_levels: int = MISSING
    max_row_error_px: float = MISSING  # stereo matches must stay on the same row (rectified)
    min_disparity_px: float = MISSING
    max_depth_m: float = MISSING
    forward_backward_px: float = MISSING
    ransac_reprojection_px: float = MISSING
    ransac_iterations: int = MISSING
    refine_iterations: int = MISSING
    huber_px: float = MISSING
    min_inliers: int = MISSING
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
    strategy: str = setting(one_of(registry("labelling.frame_selection", "STRATEGIES")))
    stride_m: float = setting(at_least(0.05))  # denser than the frames gives no more labels; the stage also wants it <= distance_m
    min_motion_m: float = setting(at_least(0))
    poses: PosesConfig = field(default_factory=PosesConfig)
    occlusion: OcclusionConfig = field(default_factory=OcclusionConfig)
    footprint: FootprintConfig = field(default_factory=FootprintConfig)
    odometry: OdometryConfig = field(default_factory=OdometryConfig)
    disparity: DisparityConfig = field(default_factory=DisparityConfig)
    workers: int = setting(at_least(0))
    shards: int = setting(at_least(1))  # label.shard of label.shards: this job labels every shards-th sequence (labelling/shards.py)
    shard: int = setting(at_least(0))
    merge_from: str | None = MISSING  # a folder of shard folders to merge into out_dir, instead of labelling


@dataclass
class SplitConfig:
    labels_dir: str = MISSING
    out_dir: str = MISSING
    # grouped: by blocks of driving, no leakage; stretch: each recording's last stretch; random: the paper's per-image split
    strategy: str = setting(one_of(registry("data.splitting", "STRATEGIES")))
    test_fraction: float = setting(between(0, 1, low_open=True, high_open=True))
    val_fraction: float = setting(between(0, 1, high_open=True))
    block_m: float = setting(positive())
    guard_m: float = setting(at_least(0))
    mirror: bool = MISSING
    seed: int = MISSING


@dataclass
class DataConfig:
    _target_: str = MISSING  # the LightningDataModule these keys are the arguments of (hydra.utils.instantiate)
    split_dir: str = MISSING
    width: int = setting(IMAGE_SIZE)  # network input size; labels and predictions stay at the recorded size
    height: int = setting(IMAGE_SIZE)
    batch_size: int = setting(at_least(1))
    num_workers: int = setting(at_least(0))
    pin_memory: bool = MISSING
    augment: bool = MISSING
    jitter: float = setting(between(0, 1))  # brightness, contrast and saturation jitter
    min_scale: float = setting(between(0, 1, low_open=True))  # random resized crop keeps at least this fraction of the image
    cache_mb: float = setting(at_least(0))  # decoded samples kept in memory per loader process (0: decode every epoch)


@dataclass
class PaperTrainingConfig:
    """How Holder & Breckon trained a network (conf/model/paper/<name>.yaml), which experiment=paper takes."""

    lr: float = setting(positive())
    lr_milestones: list[float] = setting(each(between(0, 1, low_open=True, high_open=True)))
    steps: int = setting(at_least(1))  # SGD iterations of batch 6


@dataclass
class ModelConfig:
    _target_: str = MISSING  # the task's builder (training.task.segmentation_task); the keys below are its arguments
    name: str = setting(one_of(_model_names))
    width: float = setting(positive())  # channel multiplier: 1 is the original network
    lr: float = setting(positive())
    # The rate times lr_gamma at each milestone, a fraction of the run's SGD iterations (training.task.sgd_with_milestones)
    lr_milestones: list[float] = setting(each(between(0, 1, low_open=True, high_open=True)))
    lr_gamma: float = setting(between(0, 1, low_open=True))
    lr_warmup: float = setting(between(0, 1, high_open=True))  # the rate ramps up from 0 over this fraction of the iterations
    momentum: float = setting(between(0, 1, high_open=True))
    weight_decay: float = setting(at_least(0))
    imagenet_weights: str = MISSING  # torchvision VGG16(-BN) file that pretraining=imagenet reads for this network
    channels_last: bool = MISSING  # the memory format train.channels_last takes by default (measured per network)
    paper: PaperTrainingConfig | None = None  # absent for a network the paper did not train


@dataclass
class PretrainingConfig:
    name: str = setting(one_of(PRETRAININGS))
    checkpoint: str | None = MISSING  # segmentation: the pretrain stage's checkpoint
    weights_path: str | None = MISSING  # imagenet: VGG16(-BN) weights in torchvision's state-dict layout


@dataclass
class TrainerConfig:
    """The arguments of lightning.pytorch.Trainer that conf/trainer sets (instantiated by the
    training loop, which adds callbacks, logger and plugins)."""

    _target_: str = MISSING
    max_epochs: int = setting(at_least(1))
    max_time: str | None = MISSING  # "DD:HH:MM:SS": stop after this wall time (null: no limit)
    accelerator: str = MISSING
    devices: str = MISSING
    strategy: str = MISSING  # ddp across GPUs (trainer=ddp)
    num_nodes: int = MISSING
    sync_batchnorm: bool = MISSING  # batch norm's statistics over the global batch (trainer=ddp)
    precision: str = MISSING
    deterministic: bool = MISSING
    log_every_n_steps: int = setting(at_least(1))
    fast_dev_run: bool = MISSING


@dataclass
class PretrainConfig:
    out_dir: str = MISSING
    max_epochs: int | None = setting(at_least(1))  # None: trainer.max_epochs
    max_steps: int = setting(MAX_STEPS)
    sample_images: int = setting(at_least(0))  # validation predictions logged to MLflow each epoch
    channels_last: bool = MISSING


@dataclass
class TrainConfig:
    out_dir: str = MISSING
    sample_images: int = setting(at_least(0))  # validation predictions logged to MLflow each epoch
    channels_last: bool = MISSING  # channels-last memory format (default: the model file's choice)
    max_steps: int = setting(MAX_STEPS)


@dataclass
class PostprocessConfig:
    predictions_dir: str = MISSING  # the train stage's test-set confidence maps
    out_dir: str = MISSING
    max_depth_m: float = setting(positive())  # D: confidence beyond this stereo depth is set to 0
    sigma: float = setting(between(0, 100, low_open=True))  # Gaussian blur, pixels of the label-sized map
    delta: float = setting(between(0, 1, high_open=True))  # confidence below this is set to 0
    use_depth: bool = MISSING
    # pixels without stereo depth: keep (the paper) or zero
    unknown_depth: str = setting(one_of(registry("postprocessing.filter", "UNKNOWN_DEPTH")))
    blur_scale: int = setting(between(1, 8))  # the blur runs at 1/blur_scale of the resolution (1: exact)


@dataclass
class SteeringFromPathsConfig:
    lookahead_m: float = setting(positive())  # pure pursuit's look-ahead distance from the rear axle
    steering_ratio: float = setting(positive())  # steering-wheel degrees per road-wheel degree
    pilotnet_predictions: str | None = MISSING  # train_steering's predictions.csv, {seed} for the seed; None: no PilotNet row


@dataclass
class TemporalConfig:
    enabled: bool = MISSING  # every frame of the test blocks, with and without the temporal filter (synthetic test sets)
    alpha: float = setting(between(0, 1, low_open=True))  # the current frame's weight in the fused confidence


@dataclass
class BootstrapConfig:
    """Intervals by resampling the test set's blocks of driving (offroad_path.statistics.bootstrap)."""

    resamples: int = setting(at_least(100))
    seed: int = MISSING
    level: float = setting(between(0, 1, low_open=True, high_open=True))


@dataclass
class PrimaryConfig:
    """One primary question, declared before the run (offroad_path.statistics.primaries)."""

    claim: str = MISSING  # the claim it tests, in words
    # Which comparison answers it: <section>/<key> of the report that owns it, e.g.
    # uncertainty/unet-none_vs_segnet-none (evaluate) or steering/unet-segmentation_vs_pilotnet (drive).
    compare: str = MISSING
    # drive only: the planning rates (interventions per km, a then b) its power is computed from
    planning_per_km: list[float] | None = None


@dataclass
class ConclusionsConfig:
    """The primary questions and their family-wise error (Holm)."""

    alpha: float = setting(between(0, 1, low_open=True, high_open=True))  # family-wise, two-sided
    power: float = setting(between(0, 1, low_open=True, high_open=True))  # the drive's target power per primary
    primaries: dict[str, PrimaryConfig] = MISSING


@dataclass
class EvaluateConfig:
    architectures: list[str] = setting(each(one_of(_model_names)))
    pretrainings: list[str] = setting(each(one_of(PRETRAININGS)))
    seeds: list[int] = setting(each(at_least(0)))  # training seeds of every run: data/runs/<run>/seed<k>
    drive_seeds: list[int] = setting(each(at_least(0)))  # the closed loop's (drive.seeds; the slip and curvature PilotNets')
    runs: list[str] = MISSING  # <architecture>-<pretraining>; conf/ takes the grid of the two lists
    runs_dir: str = MISSING  # <run>/predictions from train
    postprocessed_dir: str = MISSING  # <run>/ from postprocess
    labels_dir: str = MISSING  # the label run: steering, calibration and vehicle of each test frame
    steering_from_paths: SteeringFromPathsConfig = field(default_factory=SteeringFromPathsConfig)
    train_manifest: str = MISSING  # for the mean-path prior
    temporal: TemporalConfig = field(default_factory=TemporalConfig)
    bootstrap: BootstrapConfig = field(default_factory=BootstrapConfig)
    conclusions: ConclusionsConfig = field(default_factory=ConclusionsConfig)
    real_labels_dir: str | None = MISSING  # a label run of real footage: every network scored on it too (null: none)
    colour_baseline_pixels: int = setting(at_least(0))  # training pixels per frame of the colour baseline (0: none)
    threshold: float = setting(between(0, 1))  # path where C > threshold
    pr_thresholds: int = setting(at_least(2))
    out_dir: str = MISSING  # results table, figures
    metrics_path: str = MISSING
    plots_dir: str = MISSING  # one CSV per run, for `dvc plots`
    figure_scale: float = setting(between(0, 1, low_open=True))  # figures at half the label size keep the PNGs small
    figure_cases: int = setting(at_least(1))  # good and bad cases per network in Fig. 8, and raised and lowered in Fig. 5


@dataclass
class SteeringConfig:
    """The end-to-end baseline: PilotNet regressing normalised steering from one image."""

    out_dir: str = MISSING
    labels_dir: str = MISSING  # where each sequence's poses place its frames along the path
    split_dir: str = MISSING  # the path split, whose blocks of driving this split follows
    width: int = setting(IMAGE_SIZE)
    height: int = setting(IMAGE_SIZE)
    batch_size: int = setting(at_least(1))
    lr: float = setting(positive())  # CPU-sized default; experiment=paper sets the paper's 2e-4
    lr_step_epochs: int = MISSING  # step decay every N epochs
    lr_gamma: float = MISSING
    momentum: float = MISSING
    weight_decay: float = MISSING
    max_epochs: int = setting(at_least(1))
    patience: int = setting(at_least(1))  # early stopping on validation mean absolute error
    mirror: bool = MISSING  # add mirrored copies with negated steering
    jitter: float = MISSING  # photometric augmentation (no geometric: it would change the steering)
    cache_mb: float = setting(at_least(0))  # decoded images kept in memory (0: decode each epoch)
    # the straight-ahead bias's remedy: none | oversample | weighted
    balance: str = setting(one_of(registry("steering.balance", "BALANCES")))
    lock_deg: float = setting(positive())  # road-wheel angle of normalised steering 1, for errors in degrees
    steering_ratio: float = setting(positive())  # steering-wheel degrees per road-wheel degree
    slip: bool = MISSING  # train on the steering the same drives take on world.slip's ground (train_steering_slip)
    # angle: the normalised road-wheel angle (the thesis's PilotNet); curvature: the path's curvature
    # normalised by the vehicle's tightest, so that another vehicle steers atan(wheelbase x curvature)
    target: str = setting(one_of(["angle", "curvature"]))
    wheelbase_m: float = setting(positive())  # the recording vehicle's, to turn a curvature into an angle
    metrics_path: str = MISSING
    plots_path: str = MISSING  # true and predicted steering per test frame


@dataclass
class DriveConfig:
    """Closed-loop driving in the test worlds (offroad_path.driving)."""

    synthetic_dir: str = MISSING
    runs_dir: str = MISSING
    seeds: list[int] = setting(each(at_least(0)))  # every policy drives once with each training seed's networks
    pilotnets: dict[str, str] = MISSING  # end-to-end policy name -> train_steering checkpoint, {seed} for the seed
    out_dir: str = MISSING
    metrics_path: str = MISSING
    arguments: dict[str, list[str]] = MISSING  # steering | vehicle | traction -> policy names
    worlds: int | None = setting(at_least(1))
    starts_per_world: int = setting(at_least(1))
    length_m: float = setting(positive())
    width: int = setting(IMAGE_SIZE)
    height: int = setting(IMAGE_SIZE)
    rate_hz: float = setting(positive())
    speed_mps: float = setting(positive())
    steering_rate_deg_s: float = setting(positive())
    corridor_m: float = setting(positive())
    body_band_m: tuple[float, float] = MISSING
    foliage_is_obstacle: bool = MISSING
    water_intervenes: bool = MISSING
    respawn_m: float = setting(positive())
    intervention_s: float = setting(positive())
    timeout_factor: float = setting(at_least(1))
    lookahead_m: float = setting(positive())
    threshold: float = setting(between(0, 1))
    temporal_alpha: float = setting(between(0, 1, low_open=True))
    video: bool = MISSING
    other_vehicle: VehicleConfig = field(default_factory=VehicleConfig)
    bootstrap: BootstrapConfig = field(default_factory=BootstrapConfig)
    workers: int = setting(at_least(0))


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
    opset: int = MISSING
    tolerance: float = setting(positive())  # max abs difference of the path confidence against PyTorch


@dataclass
class MlflowConfig:
    enabled: bool = MISSING
    experiment: str = MISSING
    # None: $MLFLOW_TRACKING_URI if set, else sqlite:///mlflow.db at the project root.
    tracking_uri: str | None = MISSING
    log_models: bool = MISSING  # each training run's network with its signature, and a registered version (training/published.py)


@dataclass
class Config:
    paths: PathsConfig = field(default_factory=PathsConfig)
    world: WorldConfig = field(default_factory=WorldConfig)
    synthesize: SynthesizeConfig = field(default_factory=SynthesizeConfig)
    ingest: IngestConfig = field(default_factory=IngestConfig)
    label: LabelConfig = field(default_factory=LabelConfig)
    split: SplitConfig = field(default_factory=SplitConfig)
    data: DataConfig = field(default_factory=DataConfig)
    model: ModelConfig = field(default_factory=ModelConfig)
    pretraining: PretrainingConfig = field(default_factory=PretrainingConfig)
    trainer: TrainerConfig = field(default_factory=TrainerConfig)
    # Lightning callbacks and logger, instantiated as written (conf/callbacks, conf/logger): free-form,
    # so that a user can add any callback.
    callbacks: Any = MISSING
    logger: Any = MISSING
    train: TrainConfig = field(default_factory=TrainConfig)
    pretrain: PretrainConfig = field(default_factory=PretrainConfig)
    postprocess: PostprocessConfig = field(default_factory=PostprocessConfig)
    evaluate: EvaluateConfig = field(default_factory=EvaluateConfig)
    steering: SteeringConfig = field(default_factory=SteeringConfig)
    drive: DriveConfig = field(default_factory=DriveConfig)
    predict: PredictConfig = field(default_factory=PredictConfig)
    export: ExportConfig = field(default_factory=ExportConfig)
    mlflow: MlflowConfig = field(default_factory=MlflowConfig)
    experiment_name: str = MISSING
    seed: int = MISSING  # the training seed (pretrain, train, train_steering)
    resume: bool = MISSING  # continue an interrupted training run from its last.ckpt (in .resume/ beside out_dir); false: start afresh
    optimized_metric: str | None = MISSING  # the stage's metric a Hydra sweeper optimises (hparams_search)
    threads: str = setting(THREADS)  # torch, OpenCV and OpenMP threads of a stage's process: all, free or a number


def validate_config(cfg: DictConfig, groups: tuple[str, ...] | None = None) -> None:
    """Every value with a rule in these schemas (only those of `groups` and the top-level values,
    when given), checked before a stage works (ConfigValueError)."""
    validate(cfg, Config, only=groups)


def run_grid(architectures: list[str], pretrainings: list[str]) -> list[str]:
    """Every architecture with every pretraining: the runs the pipeline trains and scores."""
    return [f"{a}-{p}" for a in architectures for p in pretrainings]


def join_path(root: str, *parts: str) -> str:
    """`root`/`parts`, normalised (`./data` is `data`, `~` expanded): the paths group's resolver, so
    that the default root `.` gives the same paths, and so the same DVC outputs, as before it existed."""
    return os.path.normpath(os.path.join(os.path.expanduser(str(root)), *map(str, parts)))


def steering_folder(slip: bool, target: str = "angle") -> str:
    """The folder name of a PilotNet run: `steering`, `steering_slip` for the slip targets (the
    stage train_steering_slip), `steering_curvature` for the curvature target, so that none
    replaces another's outputs by default."""
    return "steering" + ("_curvature" if target == "curvature" else "") + ("_slip" if slip else "")


def steering_stage(slip: bool, target: str = "angle") -> str:
    """The stage a PilotNet run is (its outputs' markers, its MLflow tag): train_steering, train_steering_slip, ..."""
    return f"train_{steering_folder(slip, target)}"


def register_configs() -> None:
    OmegaConf.register_new_resolver("run_grid", run_grid, replace=True)
    OmegaConf.register_new_resolver("join", join_path, replace=True)
    OmegaConf.register_new_resolver("steering_folder", steering_folder, replace=True)
    cs = ConfigStore.instance()
    cs.store(name="config_schema", node=Config)
    cs.store(group="world/rig", name="rig_schema", node=RigConfig, package="world.rig")


def load_config(*overrides: str) -> DictConfig:
    """The project's config composed exactly as the stages compose it (for notebooks, scripts and
    tests), e.g. `load_config("experiment=paper").postprocess`."""
    register_configs()
    with initialize_config_dir(str(CONF_DIR), version_base="1.3"):
        return compose("config", overrides=list(overrides))
