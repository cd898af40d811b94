"""Export a trained path model to ONNX, and check it against PyTorch (see offroad_path.export.onnx_export).

    python -m offroad_path.export model=segnet pretraining=none
    python -m offroad_path.export export.checkpoint=path/to/best.ckpt export.out=segnet.onnx

The ONNX graph takes a normalised RGB batch (N, 3, h, w) at the network's training input size
and returns the path confidence (N, h, w); `predict` runs it with onnxruntime.
"""

from __future__ import annotations

import logging
import os
import tempfile
from pathlib import Path

from omegaconf import DictConfig

from offroad_path.stage import hydra_stage, reads
from offroad_path.utils.atomic import UnsafeOutputError, current_umask, sidecar, write_text_atomic
from offroad_path.utils.outputs import Outputs

log = logging.getLogger("offroad_path.export")


def outputs(cfg: DictConfig) -> Outputs:
    return Outputs("export", files={"export.out": cfg.export.out}, inputs=[cfg.export.checkpoint])


@reads("export", writes=outputs)
def run_export(cfg: DictConfig) -> float:
    from offroad_path.export.onnx_export import export_onnx  # torch: after the config is checked
    from offroad_path.inference.runners import TorchModel

    export = cfg.export
    out = Path(export.out)
    if out.suffix != ".onnx":
        raise UnsafeOutputError(f"export.out={out}: must be a .onnx file path; nothing is written")
    model = TorchModel(export.checkpoint)
    out.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{out.name}.tmp-", suffix=".onnx", dir=out.parent)
    os.close(fd)
    try:
        difference = export_onnx(model.task.model, model.width, model.height, Path(tmp), export.opset)
        if not difference <= export.tolerance:  # NaN compares false either way: it fails here
            raise ValueError(f"{export.checkpoint}: the ONNX export differs from PyTorch by {difference:.2e} (> {export.tolerance:g})")
        write_text_atomic(sidecar(out), "export\n")
        os.chmod(tmp, 0o666 & ~current_umask())
        os.replace(tmp, out)
    finally:
        Path(tmp).unlink(missing_ok=True)
    log.info(
        "exported %s to %s (%d x %d input, dynamic batch); largest difference from PyTorch %.2e",
        export.checkpoint,
        out,
        model.width,
        model.height,
        difference,
    )
    return difference


main = hydra_stage(run_export)
