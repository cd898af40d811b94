"""Stage `pretrain`: train an architecture on the world's 8-class semantic segmentation, for
`train pretraining=segmentation` to start from (Holder's thesis, chapter 5).

    python -m offroad_path.pretrain model=unet

Writes pretrain.out_dir (data/pretrain/<model>): checkpoints/best.ckpt and metrics.json.
"""

from __future__ import annotations

import logging

from omegaconf import DictConfig

from offroad_path.training.run import fit_segmentation
from offroad_path.utils.cli import hydra_stage
from offroad_path.world.classes import CLASS_NAMES

log = logging.getLogger("offroad_path.pretrain")


def pretrain(cfg: DictConfig) -> dict:
    cfg = cfg.copy()
    if cfg.pretrain.max_epochs is not None:
        cfg.trainer.max_epochs = cfg.pretrain.max_epochs
    if cfg.pretrain.max_steps is not None:
        cfg.train.max_steps = cfg.pretrain.max_steps
    metrics = fit_segmentation(cfg, "pretrain", "semantic", len(CLASS_NAMES))
    log.info("pretrained %s on %d classes: best validation mIoU %s", cfg.model.name, len(CLASS_NAMES), metrics["best_val_iou"])
    return metrics


main = hydra_stage(pretrain)


if __name__ == "__main__":
    main()
