"""Schemas of training: the data module, the model, pretraining, the trainer, train and pretrain, post-processing, PilotNet."""

from __future__ import annotations

from dataclasses import dataclass

from omegaconf import MISSING

from offroad_path.config.common import IMAGE_SIZE, MAX_STEPS, PRETRAININGS, model_names
from offroad_path.utils.rules import ConfigValueError, accelerator, at_least, between, each, one_of, positive, setting

UNKNOWN_DEPTH = ("keep", "drop")  # postprocess.unknown_depth: inference.path_filter
BALANCES = ("none", "oversample", "weighted")  # steering.balance: steering.balance


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
    name: str = setting(one_of(model_names))
    width: float = setting(positive())  # channel multiplier: 1 is the original network
    lr: float = setting(positive())
    optimizer: str = setting(one_of(("sgd", "adamw")))  # sgd: the paper's (with momentum); adamw: the laptop recipe's
    lr_schedule: str = setting(one_of(("step", "cosine")))  # step: times lr_gamma at each milestone; cosine: annealed to 0
    # Milestones: fractions of the run's iterations (training.task.optimizer_with_schedule)
    lr_milestones: list[float] = setting(each(between(0, 1, low_open=True, high_open=True)))
    lr_gamma: float = setting(between(0, 1, low_open=True))
    lr_warmup: float = setting(between(0, 1, high_open=True))  # the rate ramps up from 0 over this fraction of the iterations
    momentum: float = setting(between(0, 1, high_open=True))  # SGD's
    weight_decay: float = setting(at_least(0))
    dice_weight: float = setting(at_least(0))  # a soft Dice loss term beside the cross-entropy (0: cross-entropy alone, the paper's)
    batch_norm: bool | None = MISSING  # a network whose normalisation is a choice (FCN-8s): after each convolution; null: its own
    imagenet_weights: str = MISSING  # torchvision VGG16(-BN) file that pretraining=imagenet reads for this network
    channels_last: bool = MISSING  # the memory format train.channels_last takes by default (measured per network)
    paper: PaperTrainingConfig | None = None  # absent for a network the paper did not train


# Networks whose normalisation is a choice (model.batch_norm): FCN-8s has none as published. SegNet
# and U-Net have batch norm after every convolution as published, which is theirs to keep.
BATCH_NORM_CHOICE = ("fcn",)


def check_batch_norm(name: str, batch_norm: bool | None) -> None:
    """model.batch_norm only for a network whose normalisation is a choice: one line, before any work."""
    if batch_norm is not None and name not in BATCH_NORM_CHOICE:
        raise ConfigValueError(
            f"model.batch_norm={batch_norm}: {name} has batch norm after every convolution as published, not a choice "
            f"(null; a choice of {', '.join(BATCH_NORM_CHOICE)} only)"
        )


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
    accelerator: str = setting(accelerator())  # Lightning's: auto, cpu, gpu, ... (one this machine has)
    devices: str = MISSING
    strategy: str = MISSING  # ddp across GPUs (trainer=ddp)
    num_nodes: int = setting(at_least(1))
    sync_batchnorm: bool = MISSING  # batch norm's statistics over the global batch (trainer=ddp)
    precision: str = MISSING
    deterministic: bool = MISSING
    log_every_n_steps: int = setting(at_least(1))
    val_check_interval: float = setting(between(0, 1, low_open=True))  # validation every this fraction of an epoch
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
    unknown_depth: str = setting(one_of(UNKNOWN_DEPTH))
    blur_scale: int = setting(between(1, 8))  # the blur runs at 1/blur_scale of the resolution (1: exact)


@dataclass
class SteeringConfig:
    """The end-to-end baseline: PilotNet regressing normalised steering from one image."""

    _target_: str = MISSING  # the task's builder (steering.pilotnet_task.steering_task): SteeringTask's arguments are taken from these keys
    out_dir: str = MISSING
    labels_dir: str = MISSING  # where each sequence's poses place its frames along the path
    split_dir: str = MISSING  # the path split, whose blocks of driving this split follows
    width: int = setting(IMAGE_SIZE)
    height: int = setting(IMAGE_SIZE)
    batch_size: int = setting(at_least(1))
    lr: float = setting(positive())  # CPU-sized default; experiment=paper sets the paper's 2e-4
    optimizer: str = setting(one_of(("sgd", "adamw")))  # sgd: the thesis's, with step decay; adamw: cosine to 0 over the run
    lr_step_epochs: int = setting(at_least(1))  # sgd's step decay every N epochs
    lr_gamma: float = setting(between(0, 1, low_open=True))
    momentum: float = setting(between(0, 1, high_open=True))
    weight_decay: float = setting(at_least(0))
    max_epochs: int = setting(at_least(1))
    patience: int = setting(at_least(1))  # early stopping on validation mean absolute error
    mirror: bool = MISSING  # add mirrored copies with negated steering
    jitter: float = setting(between(0, 1))  # photometric augmentation (no geometric: it would change the steering)
    cache_mb: float = setting(at_least(0))  # decoded images kept in memory (0: decode each epoch)
    # the straight-ahead bias's remedy: none | oversample | weighted
    balance: str = setting(one_of(BALANCES))
    lock_deg: float = setting(positive())  # road-wheel angle of normalised steering 1, for errors in degrees
    steering_ratio: float = setting(positive())  # steering-wheel degrees per road-wheel degree
    slip: bool = MISSING  # train on the steering the same drives take on world.slip's ground (train_steering_slip)
    # angle: the normalised road-wheel angle (the thesis's PilotNet); curvature: the path's curvature
    # normalised by the vehicle's tightest, so that another vehicle steers atan(wheelbase x curvature)
    target: str = setting(one_of(["angle", "curvature"]))
    wheelbase_m: float = setting(positive())  # the recording vehicle's, to turn a curvature into an angle
    metrics_path: str = MISSING
    plots_path: str = MISSING  # true and predicted steering per test frame
