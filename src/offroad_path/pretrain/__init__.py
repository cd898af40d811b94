"""Stage `pretrain`: train an architecture on the world's 8-class semantic segmentation, for
`train pretraining=segmentation` to start from (Holder's thesis, chapter 5).

    python -m offroad_path.pretrain model=unet

Writes pretrain.out_dir (data/pretrain/<model>): checkpoints/best.ckpt and metrics.json.
"""

from __future__ import annotations

import logging

from omegaconf import DictConfig

from offroad_path.stage import hydra_stage, reads
from offroad_path.training.stage_outputs import segmentation_outputs
from offroad_path.world.classes import CLASS_NAMES

log = logging.getLogger("offroad_path.pretrain")


@reads("pretrain", "data", "model", "trainer", "callbacks", "logger", "mlflow", writes=segmentation_outputs("pretrain"))
def pretrain(cfg: DictConfig) -> dict:
    from offroad_path.training.run import fit_segmentation  # torch and Lightning: after the config is checked

    metrics = fit_segmentation(cfg, "pretrain", target="semantic")
    log.info("pretrained %s on %d classes: best validation mIoU %s", cfg.model.name, len(CLASS_NAMES), metrics["best_val_iou"])
    return metrics


main = hydra_stage(pretrain)
