"""Stage `train`: fit one architecture with one pretraining choice on the path labels, test it,
and write the test-set confidence maps for post-processing (see docs/design.md).

    python -m offroad_path.train model=segnet pretraining=segmentation
    python -m offroad_path.train -m model=segnet,fcn,unet pretraining=none,segmentation

Writes train.out_dir (data/runs/<model>-<pretraining>/seed<k>): checkpoints/best.ckpt, metrics.json,
predictions/ (float16 .npy per test sample and manifest.csv); logs to MLflow. Resumable state lives
beside it in data/runs/.resume/ (see offroad_path.training.run.fit).
"""

from __future__ import annotations

import logging
from pathlib import Path

from omegaconf import DictConfig

from offroad_path.stage import hydra_stage, reads
from offroad_path.training.stage_outputs import segmentation_outputs

log = logging.getLogger("offroad_path.train")


@reads("train", "data", "model", "pretraining", "trainer", "callbacks", "logger", "mlflow", writes=segmentation_outputs("train"))
def train(cfg: DictConfig) -> dict:
    from offroad_path.training.run import fit_segmentation, write_confidence_maps  # torch and Lightning: after the config is checked

    out_dir = Path(cfg.train.out_dir)

    def predictions(task, data, tmp: Path) -> dict:
        written = write_confidence_maps(task, data, tmp / "predictions", out_dir / "predictions")
        log.info("%d confidence maps in %s", written, out_dir / "predictions")
        return {}

    metrics = fit_segmentation(cfg, "train", target="path", pretraining=cfg.pretraining, write_more=predictions)
    log.info(
        "%s-%s: best validation IoU %s, test IoU %.4f", cfg.model.name, cfg.pretraining.name, metrics["best_val_iou"], metrics["test/iou"]
    )
    return metrics


main = hydra_stage(train)
