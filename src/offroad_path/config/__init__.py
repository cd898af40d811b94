"""Typed schemas of the Hydra configuration, registered in Hydra's ConfigStore.

The values live in the YAML files under `conf/`, once; these schemas hold only types and rules
(`setting(positive())`: checked by `validate_config` before a stage works). A misspelt key or a
value of the wrong type fails at composition, a value a rule refuses before any work, each with
an error naming the key. Library code reads its settings from a composed config
(`load_config()`), never from defaults of its own.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

from hydra import compose, initialize_config_dir
from hydra.core.config_store import ConfigStore
from omegaconf import MISSING, BooleanNode, DictConfig, OmegaConf

from offroad_path.config.common import CONF_DIR, THREADS, model_names
from offroad_path.config.evaluate_schema import DriveConfig, EvaluateConfig
from offroad_path.config.label_schema import IngestConfig, LabelConfig, SplitConfig
from offroad_path.config.serving import ExportConfig, MlflowConfig, PredictConfig
from offroad_path.config.training_schema import (
    DataConfig,
    ModelConfig,
    PostprocessConfig,
    PretrainConfig,
    PretrainingConfig,
    SteeringConfig,
    TrainConfig,
    TrainerConfig,
    check_batch_norm,
)
from offroad_path.config.world_schema import PathsConfig, RenderConfig, RigConfig, SynthesizeConfig, WorldConfig, check_looks_drawable
from offroad_path.errors import InputError
from offroad_path.utils.rules import SEED, setting, validate


@dataclass
class Config:
    paths: PathsConfig = field(default_factory=PathsConfig)
    world: WorldConfig = field(default_factory=WorldConfig)
    render: RenderConfig = field(default_factory=RenderConfig)
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
    seed: int = setting(SEED)  # the training seed (pretrain, train, train_steering)
    resume: bool = MISSING  # continue an interrupted training run from its last.ckpt (in .resume/ beside out_dir); false: start afresh
    optimized_metric: str | None = MISSING  # the stage's metric a Hydra sweeper optimises (hparams_search)
    threads: str = setting(THREADS)  # torch, OpenCV and OpenMP threads of a stage's process: all, free or a number


def validate_config(cfg: DictConfig, groups: tuple[str, ...] | None = None) -> None:
    """Every value with a rule in these schemas (only those of `groups` and the top-level values,
    when given), checked before a stage works (ConfigValueError)."""
    validate(cfg, Config, only=groups)
    if (groups is None or "world" in groups) and OmegaConf.select(cfg, "world.appearance") is not None:
        check_looks_drawable(cfg.world.appearance)
    if (groups is None or "model" in groups) and OmegaConf.select(cfg, "model") is not None:
        check_batch_norm(cfg.model.get("name"), cfg.model.get("batch_norm"))


def run_grid(architectures: list[str], pretrainings: list[str]) -> list[str]:
    """Every architecture with every pretraining: the runs the pipeline trains and scores."""
    return [f"{a}-{p}" for a in architectures for p in pretrainings]


def join_path(root: str, *parts: str) -> str:
    """`root`/`parts`, normalised (`./data` is `data`, `~` expanded): the paths group's resolver, so
    that the default root `.` gives exactly the paths dvc.yaml names as the stages' outputs."""
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
    OmegaConf.register_new_resolver("model_names", lambda: list(model_names()), replace=True)  # every network of conf/model
    cs = ConfigStore.instance()
    cs.store(name="config_schema", node=Config)
    cs.store(group="world/rig", name="rig_schema", node=RigConfig, package="world.rig")


def load_config(*overrides: str) -> DictConfig:
    """The project's config composed exactly as the stages compose it (for notebooks, scripts and
    tests), e.g. `load_config("experiment=paper").postprocess`."""
    register_configs()
    with initialize_config_dir(str(CONF_DIR), version_base="1.3"):
        cfg = compose("config", overrides=list(overrides))
    check_overrides(cfg, overrides)
    return cfg


def check_overrides(cfg: DictConfig, overrides: Iterable[str]) -> None:
    """The command line's overrides that Hydra would take but that mean something else: an empty
    mapping (check_empty_mapping), a number given to a true/false setting (check_boolean)."""
    for override in overrides:
        if override.startswith("~"):  # a deletion: no value to check
            continue
        key, _, value = override.partition("=")
        key = key.lstrip("+")
        check_empty_mapping(cfg, key, value)
        check_boolean(cfg, key, value)


def check_empty_mapping(cfg: DictConfig, key: str, value: str) -> None:
    """`key={}` on a mapping that is not empty: Hydra merges an override into a mapping, so an empty
    one changes nothing (`world.appearance.weights={}` would still draw the default weights, `--cfg job`
    shows the merged result). Refused naming the key, with what to write instead."""
    if value.strip() == "{}" and isinstance(found := OmegaConf.select(cfg, key, default=None), DictConfig) and len(found):
        raise InputError(
            key,
            "={} changes nothing: an override merges into the mapping (--cfg job shows the result); "
            f"to leave an entry out, delete it (~{key}.<entry>) or give it weight 0",
        )


def check_boolean(cfg: DictConfig, key: str, value: str) -> None:
    """`model.batch_norm=2`: OmegaConf reads any number as a boolean (2 as true, 0 as false), so a
    true/false setting takes only true, false or null from the command line."""
    parent_key, _, name = key.rpartition(".")
    parent = OmegaConf.select(cfg, parent_key, default=None) if parent_key else cfg
    if not isinstance(parent, DictConfig) or name not in parent or not isinstance(parent._get_node(name), BooleanNode):
        return
    if value.strip().lower() not in ("true", "false", "null"):
        raise InputError(key, f"takes true or false, not {value.strip()}")
