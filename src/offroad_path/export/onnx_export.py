"""ONNX export of a path model, checked against PyTorch with onnxruntime.

SegNet's max-unpooling: the legacy TorchScript exporter (`dynamo=False`) has no translation for
`max_unpool2d` and fails on SegNet; the torch.export-based exporter (PyTorch's default since 2.9,
used here) decomposes it into ScatterND, which gives the same numbers (the export checks it).
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import torch
from torch import nn

from offroad_path.errors import missing_extra
from offroad_path.models.base import SegmentationNet


class PathConfidence(nn.Module):
    """What the exported graph computes: a normalised RGB batch (N, 3, H, W) -> path confidence (N, H, W)."""

    def __init__(self, model: SegmentationNet):
        super().__init__()
        self.model = model

    def forward(self, image: torch.Tensor) -> torch.Tensor:
        return self.model(image).softmax(1)[:, 1]


def export_onnx(model: SegmentationNet, width: int, height: int, out: Path, opset: int = 18) -> float:
    """Write `out` for inputs of (batch, 3, height, width) with a dynamic batch, and return the largest
    absolute difference of its path confidence from PyTorch's on a random input of two images."""
    try:
        import onnxruntime as ort
        import onnxscript  # noqa: F401  (torch.onnx.export's exporter)
    except ImportError as e:
        raise missing_extra("export", "onnx", e.name) from e

    wrapped = PathConfidence(model).eval()
    example = torch.randn(2, 3, height, width, generator=torch.Generator().manual_seed(0))
    out.parent.mkdir(parents=True, exist_ok=True)
    logging.getLogger("onnxscript").setLevel(logging.WARNING)
    with torch.no_grad():
        reference = wrapped(example).numpy()
        batch = torch.export.Dim("batch", min=1, max=1024)
        torch.onnx.export(
            wrapped,
            (example,),
            str(out),
            input_names=["image"],
            output_names=["confidence"],
            opset_version=opset,
            dynamic_shapes={"image": {0: batch}},
            dynamo=True,
            external_data=False,
            verbose=False,
        )
    session = ort.InferenceSession(str(out), providers=["CPUExecutionProvider"])
    exported = session.run(["confidence"], {"image": example.numpy()})[0]
    return float(np.abs(exported - reference).max())
