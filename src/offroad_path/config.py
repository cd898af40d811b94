"""Typed schemas of the Hydra configuration, registered in Hydra's ConfigStore.

The YAML files under `conf/` fill these schemas; a misspelt key or a value of the wrong type
fails at composition, before any stage does work, with an error naming the key.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from hydra.core.config_store import ConfigStore
from omegaconf import MISSING

from offroad_path.odometry.stereo_vo import OdometryConfig
from offroad_path.utils.rules import at_least, between, one_of, positive, rule, validate

IMAGE_SIZE = between(16, 8192)  # pixels of an image side


def _model_names() -> list[str]:
    from offroad_path.models import MODELS  # the registry, read only when checking

    return list(MODELS)


@dataclass
class RigConfig:
    name: str = MISSING
    baseline_m: float = MISSING


@dataclass
class VehicleConfig:
    width_m: float = 1.9
    length_m: float = 4.2
    wheelbase_m: float = 2.8
    track_m: float = 1.6
    camera_height_m: float = 1.8
    camera_forward_m: float = 0.4  # camera ahead of the body centre
    camera_pitch_deg: float = 7.0  # optical axis tilted down
    max_steering_deg: float = 30.0


@dataclass
class WorldConfig:
    """One rendered sequence's generator settings; per-sequence variation is drawn around these."""

    rig: RigConfig = field(default_factory=RigConfig)
    vehicle: VehicleConfig = field(default_factory=VehicleConfig)
    frames: int = field(default=200, metadata=at_least(2))
    fps: float = field(default=10.0, metadata=positive())
    speed_min_mps: float = field(default=2.0, metadata=positive())
    speed_max_mps: float = field(default=8.0, metadata=positive())
    width: int = field(default=512, metadata=IMAGE_SIZE)
    height: int = field(default=288, metadata=IMAGE_SIZE)
    hfov_deg: float = field(default=80.0, metadata=between(1, 179))
    max_distance_m: float = 90.0
    hill_height_m: float = 4.0
    bump_height_m: float = 0.12
    max_curvature: float = 0.09  # 1/m; the peak of a drive, reached once or twice per sequence
    track_width_m: float = 3.4
    trees_per_hectare: float = 30.0
    bushes_per_hectare: float = 80.0
    obstacles_per_100m: float = 4.0
    puddles_per_100m: float = 2.0
    forks_per_100m: float = 0.7
    offtrack_per_100m: float = 0.5
    paved_fraction: float = 0.15
    sun_elevation_deg: tuple[float, float] = (25.0, 65.0)
    density_jitter: float = 0.5  # per-sequence density factor drawn in [1 - j, 1 + j]


@dataclass
class SynthesizeConfig:
    sequences: int = field(default=8, metadata=at_least(1))
    seed: int = 0
    workers: int = field(default=0, metadata=at_least(0))  # 0: one per CPU core
    out_dir: str = "data/synthetic"


@dataclass
class PosesConfig:
    source: str = field(
        default="vo", metadata=one_of(("vo", "file"))
    )  # vo: stereo visual odometry; file: a KITTI-format pose file per sequence
    # With source=file: a path pattern with {name} (the sequence folder's name), or None for
    # the sequence's own poses (poses.txt, or KITTI's poses/XX.txt).
    file: str | None = None


@dataclass
class OcclusionConfig:
    enabled: bool = True  # beyond the paper: no path label on ground hidden behind a crest or obstacle
    depth: str = field(
        default="stereo", metadata=one_of(("stereo", "ground_truth"))
    )  # stereo: from the f0 disparity; ground_truth: the sequence's depth/ (synthetic)
    margin_m: float = field(default=1.0, metadata=at_least(0))
    margin_rel: float = field(default=0.1, metadata=at_least(0))


@dataclass
class FootprintConfig:
    """The vehicle's ground footprint relative to the camera; None: take it from meta.json."""

    width_m: float | None = None
    front_m: float | None = None
    rear_m: float | None = None
    camera_height_m: float | None = None
    camera_pitch_deg: float | None = None


@dataclass
class DisparityConfig:
    """OpenCV StereoSGBM on the f0 pair; the disparity is written beside each label."""

    num_disparities: int = field(default=64, metadata=rule(lambda v: v > 0 and v % 16 == 0, "must be a positive multiple of 16"))
    block_size: int = field(default=5, metadata=rule(lambda v: v >= 1 and v % 2 == 1, "must be an odd number >= 1"))
    uniqueness_ratio: int = 10
    speckle_window: int = 100
    speckle_range: int = 2


@dataclass
class LabelConfig:
    in_dir: str = "data/synthetic"
    out_dir: str = "data/labels"
    metrics_path: str = "metrics/label.json"
    distance_m: float = field(default=20.0, metadata=positive())
    strategy: str = field(default="midway", metadata=one_of(("midway", "stride")))
    stride_m: float = field(default=5.0, metadata=positive())
    min_motion_m: float = field(default=0.01, metadata=at_least(0))
    poses: PosesConfig = field(default_factory=PosesConfig)
    occlusion: OcclusionConfig = field(default_factory=OcclusionConfig)
    footprint: FootprintConfig = field(default_factory=FootprintConfig)
    odometry: OdometryConfig = field(default_factory=OdometryConfig)
    disparity: DisparityConfig = field(default_factory=DisparityConfig)
    workers: int = field(default=0, metadata=at_least(0))


@dataclass
class SplitConfig:
    labels_dir: str = "data/labels"
    out_dir: str = "data/split"
    strategy: str = field(
        default="grouped", metadata=one_of(("grouped", "random"))
    )  # grouped: by blocks of driving, no leakage; random: the paper's per-image split
    test_fraction: float = field(default=0.1, metadata=between(0, 1, low_open=True, high_open=True))
    val_fraction: float = field(default=0.1, metadata=between(0, 1, high_open=True))
    block_m: float = field(default=20.0, metadata=positive())
    guard_m: float = field(default=10.0, metadata=at_least(0))
    mirror: bool = True
    seed: int = 0


@dataclass
class DataConfig:
    split_dir: str = "data/split"
    width: int = field(default=512, metadata=IMAGE_SIZE)  # network input size; labels and predictions stay at the recorded size
    height: int = field(default=288, metadata=IMAGE_SIZE)
    batch_size: int = field(default=6, metadata=at_least(1))
    num_workers: int = field(default=0, metadata=at_least(0))
    pin_memory: bool = False
    augment: bool = True
    jitter: float = field(default=0.2, metadata=between(0, 1))  # brightness, contrast and saturation jitter
    min_scale: float = field(
        default=0.8, metadata=between(0, 1, low_open=True)
    )  # random resized crop keeps at least this fraction of the image


@dataclass
class ModelConfig:
    name: str = field(default=MISSING, metadata=one_of(_model_names))
    width: float = field(default=1.0, metadata=positive())  # channel multiplier: 1 is the original network
    lr: float = field(default=1e-3, metadata=positive())
    # The learning rate experiment=laptop uses: narrow networks on small inputs for a few epochs
    # learn nothing in that time at the paper's rates.
    laptop_lr: float = field(default=1e-2, metadata=positive())
    lr_step_epochs: int = field(default=0, metadata=at_least(0))  # step decay every N epochs (0: fixed learning rate)
    lr_gamma: float = field(default=0.1, metadata=between(0, 1, low_open=True))
    momentum: float = field(default=0.9, metadata=between(0, 1, high_open=True))
    weight_decay: float = field(default=5e-4, metadata=at_least(0))


@dataclass
class PretrainingConfig:
    name: str = field(default="none", metadata=one_of(("none", "segmentation", "imagenet")))
    checkpoint: str | None = None  # segmentation: the pretrain stage's checkpoint
    weights_path: str | None = None  # imagenet: VGG16(-BN) weights in torchvision's state-dict layout


@dataclass
class TrainerConfig:
    max_epochs: int = field(default=100, metadata=at_least(1))
    accelerator: str = "auto"
    devices: str = "auto"
    strategy: str = "auto"  # ddp across GPUs (trainer=ddp)
    num_nodes: int = 1
    precision: str = "32-true"
    channels_last: bool = False
    deterministic: bool = False
    log_every_n_steps: int = field(default=10, metadata=at_least(1))
    patience: int = field(default=5, metadata=at_least(1))  # early stopping: epochs without a better validation IoU
    fast_dev_run: bool = False


@dataclass
class PretrainConfig:
    out_dir: str = "data/pretrain/${model.name}"
    max_epochs: int | None = field(default=None, metadata=at_least(1))  # None: trainer.max_epochs


@dataclass
class TrainConfig:
    out_dir: str = "data/runs/${model.name}-${pretraining.name}"
    seed: int = 0
    resume: bool = True  # continue an interrupted run from its last.ckpt (in .resume/ beside out_dir); false: start afresh
    sample_images: int = field(default=4, metadata=at_least(0))  # validation predictions logged to MLflow each epoch


@dataclass
class PostprocessConfig:
    predictions_dir: str = "${train.out_dir}/predictions"  # the train stage's test-set confidence maps
    out_dir: str = "data/postprocessed/${model.name}-${pretraining.name}"
    max_depth_m: float = field(
        default=20.0, metadata=positive()
    )  # D: confidence beyond this stereo depth (or of unknown depth) is set to 0
    sigma: float = field(default=6.0, metadata=between(0, 100, low_open=True))  # Gaussian blur, pixels of the label-sized map
    delta: float = field(default=0.025, metadata=between(0, 1, high_open=True))  # confidence below this is set to 0
    use_depth: bool = True


@dataclass
class EvaluateConfig:
    runs: list[str] = field(default_factory=lambda: [f"{m}-{p}" for m in ("segnet", "fcn", "unet") for p in ("none", "segmentation")])
    runs_dir: str = "data/runs"  # <run>/predictions from train
    postprocessed_dir: str = "data/postprocessed"  # <run>/ from postprocess
    train_manifest: str = "${split.out_dir}/train.csv"  # for the mean-path prior
    threshold: float = field(default=0.5, metadata=between(0, 1))  # path where C > threshold
    pr_thresholds: int = field(default=101, metadata=at_least(2))
    out_dir: str = "data/evaluation"  # results table, figures
    metrics_path: str = "metrics/evaluation.json"
    plots_dir: str = "metrics/precision_recall"  # one CSV per run, for `dvc plots`
    figure_scale: float = field(default=0.5, metadata=between(0, 1, low_open=True))  # figures at half the label size keep the PNGs small
    figure_cases: int = field(default=1, metadata=at_least(1))  # good and bad cases per network in Fig. 8, and raised and lowered in Fig. 5


@dataclass
class SteeringConfig:
    """The end-to-end baseline: PilotNet regressing normalised steering from one image."""

    out_dir: str = "data/steering"
    labels_dir: str = "${split.labels_dir}"  # where each sequence's poses place its frames along the path
    split_dir: str = "${split.out_dir}"  # the path split, whose blocks of driving this split follows
    width: int = field(default=256, metadata=IMAGE_SIZE)
    height: int = field(default=136, metadata=IMAGE_SIZE)
    batch_size: int = field(default=6, metadata=at_least(1))
    lr: float = field(default=0.002, metadata=positive())  # CPU-sized default; experiment=paper sets the paper's 2e-4
    lr_step_epochs: int = 5  # step decay every N epochs
    lr_gamma: float = 0.5
    momentum: float = 0.9
    weight_decay: float = 0.0
    max_epochs: int = field(default=12, metadata=at_least(1))
    patience: int = field(default=4, metadata=at_least(1))  # early stopping on validation mean absolute error
    mirror: bool = True  # add mirrored copies with negated steering
    jitter: float = 0.2  # photometric augmentation (no geometric: it would change the steering)
    seed: int = 0
    metrics_path: str = "metrics/steering.json"
    plots_path: str = "metrics/steering_scatter.csv"  # true and predicted steering per test frame


@dataclass
class PredictConfig:
    """Run a trained path model on new footage."""

    checkpoint: str | None = None  # a train checkpoint (.ckpt) or an exported model (.onnx)
    run_id: str | None = None  # or an MLflow training run: its best checkpoint
    input: str = MISSING  # a folder of images, a sequence folder (stereo, with calib.txt) or a video file
    out_dir: str = "predictions"
    threshold: float = field(default=0.5, metadata=between(0, 1))  # path where confidence > threshold, for the overlay
    postprocess: bool = False  # the paper's post-processing (depth mask only for stereo sequences)
    video_fps: float | None = field(
        default=None, metadata=positive()
    )  # MP4 frame rate; None: the video's own, or the sequence's times, or 10
    max_frames: int | None = field(default=None, metadata=at_least(1))
    # Images larger than this are refused from their header, before decoding (8K is 33 million).
    max_image_pixels: int = field(default=50_000_000, metadata=at_least(1))
    device: str = "cpu"


@dataclass
class ExportConfig:
    """ONNX export of a trained path model, checked against PyTorch."""

    checkpoint: str = "${train.out_dir}/checkpoints/best.ckpt"
    out: str = "exports/${model.name}-${pretraining.name}.onnx"  # outside DVC's outputs
    opset: int = 18
    tolerance: float = field(default=1e-4, metadata=positive())  # max abs difference of the path confidence against PyTorch


@dataclass
class MlflowConfig:
    enabled: bool = True
    experiment: str = "offroad-path"
    # None: $MLFLOW_TRACKING_URI if set, else sqlite:///mlflow.db at the project root.
    tracking_uri: str | None = None


@dataclass
class Config:
    world: WorldConfig = field(default_factory=WorldConfig)
    synthesize: SynthesizeConfig = field(default_factory=SynthesizeConfig)
    label: LabelConfig = field(default_factory=LabelConfig)
    split: SplitConfig = field(default_factory=SplitConfig)
    data: DataConfig = field(default_factory=DataConfig)
    model: ModelConfig = field(default_factory=ModelConfig)
    pretraining: PretrainingConfig = field(default_factory=PretrainingConfig)
    trainer: TrainerConfig = field(default_factory=TrainerConfig)
    train: TrainConfig = field(default_factory=TrainConfig)
    pretrain: PretrainConfig = field(default_factory=PretrainConfig)
    postprocess: PostprocessConfig = field(default_factory=PostprocessConfig)
    evaluate: EvaluateConfig = field(default_factory=EvaluateConfig)
    steering: SteeringConfig = field(default_factory=SteeringConfig)
    predict: PredictConfig = field(default_factory=PredictConfig)
    export: ExportConfig = field(default_factory=ExportConfig)
    mlflow: MlflowConfig = field(default_factory=MlflowConfig)
    experiment_name: str = "laptop"


def validate_config(cfg) -> None:
    """Every value with a rule in these schemas, checked before a stage works (ConfigValueError)."""
    validate(cfg, Config)


def register_configs() -> None:
    cs = ConfigStore.instance()
    cs.store(name="config_schema", node=Config)
    cs.store(group="world/rig", name="rig_schema", node=RigConfig, package="world.rig")
