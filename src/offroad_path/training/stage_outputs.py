"""What the pretrain and train stages write and read, for the output rule (utils.outputs): light, so
that a stage's command checks its config and outputs before it imports torch and Lightning."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from omegaconf import DictConfig

from offroad_path.data.manifest import manifest_folders
from offroad_path.utils.outputs import Outputs


def logger_folder(cfg: DictConfig) -> dict[str, str]:
    """A file logger's folder (logger=csv, wandb: logger.save_dir), for the output rule."""
    logger = cfg.get("logger")
    return {"logger.save_dir": logger.save_dir} if logger is not None and logger.get("save_dir") else {}


def segmentation_outputs(stage: str) -> Callable[[DictConfig], Outputs]:
    """The outputs rule of the pretrain and train stages: `<stage>.out_dir`, against the split, the
    label runs and recordings its manifests point into, and the pretraining's checkpoint or weights."""

    def outputs(cfg: DictConfig) -> Outputs:
        split_dir = Path(cfg.data.split_dir)
        inputs = [split_dir, *(f for part in ("train", "val", "test") for f in manifest_folders(split_dir / f"{part}.csv"))]
        if "pretraining" in cfg:
            inputs += [cfg.pretraining.checkpoint, cfg.pretraining.weights_path]
        return Outputs(stage, folders={f"{stage}.out_dir": cfg[stage].out_dir}, inputs=inputs, shared=logger_folder(cfg))

    return outputs
