"""ONNX export of every architecture, and what it says without the onnx extra."""

from __future__ import annotations

import sys

import pytest
import torch

from offroad_path.errors import InputError
from offroad_path.export.onnx_export import export_onnx
from offroad_path.models import MODELS, build_model


@pytest.mark.parametrize("model", sorted(MODELS))
@pytest.mark.slow(seconds=9)
def test_onnx_export_agrees_with_pytorch(model, tmp_path):
    torch.manual_seed(0)
    difference = export_onnx(build_model(model, 2, 0.125), 128, 72, tmp_path / f"{model}.onnx")
    assert difference < 1e-4


def test_export_without_the_onnx_extra_says_which_extra_to_install(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "onnxruntime", None)  # as if `pip install -e .` without [onnx]
    with pytest.raises(InputError, match=r"needs the \[onnx\] extra \(onnxruntime is not installed\)"):
        export_onnx(build_model("unet", 2, 0.125), 128, 72, tmp_path / "unet.onnx")
    assert not (tmp_path / "unet.onnx").exists()
