"""A trained path model as a function from RGB images to path confidence: PyTorch checkpoints
and exported ONNX files, with the training pipeline's own preprocessing."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import torch

from offroad_path.data.dataset import transforms
from offroad_path.errors import missing_extra


class PathModel:
    """Base: resize and normalise as in training, run, resize the confidence back to each image."""

    width: int
    height: int

    def __call__(self, images: list[np.ndarray]) -> list[np.ndarray]:
        """RGB (H, W, 3) uint8 images -> path confidence (H, W) float32 in [0, 1], one per image."""
        if getattr(self, "_prepare", None) is None:  # built once: predict calls this every frame
            self._prepare = transforms(self.width, self.height)
        batch = torch.stack([self._prepare(image=image)["image"] for image in images])  # (N, 3, h, w)
        confidence = self.run(batch)  # (N, h, w)
        return [cv2.resize(c, (im.shape[1], im.shape[0]), interpolation=cv2.INTER_LINEAR) for c, im in zip(confidence, images, strict=True)]

    def run(self, batch: torch.Tensor) -> np.ndarray:
        raise NotImplementedError

    def predict_all(self, images: list[np.ndarray], batch_size: int = 16) -> np.ndarray:
        """Path confidence (N, H, W) of same-sized images, `batch_size` at a time (evaluation's
        whole test blocks and real recordings: batches run several times faster than single frames)."""
        return np.stack([c for i in range(0, len(images), batch_size) for c in self(images[i : i + batch_size])])


class TorchModel(PathModel):
    def __init__(self, checkpoint: str | Path, device: str = "cpu"):
        from offroad_path.models import MODELS
        from offroad_path.training.checkpoints import CheckpointError, load_checkpoint, load_weights
        from offroad_path.training.task import SegmentationTask

        checkpoint = Path(checkpoint)
        saved = load_checkpoint(checkpoint)  # weights_only: a crafted file cannot run code
        hp, data = saved["hyper_parameters"], saved.get("datamodule_hyper_parameters") or {}
        if "width" not in data or "height" not in data or hp.get("num_classes") != 2 or hp.get("model") not in MODELS:
            raise CheckpointError(f"{checkpoint}: not a path model checkpoint of the train stage (no 2-class network or input size)")
        self.width, self.height = int(data["width"]), int(data["height"])
        try:
            self.task = SegmentationTask(**hp)
        except TypeError as e:
            raise CheckpointError(f"{checkpoint}: its hyper-parameters do not describe a path network ({e})") from e
        load_weights(self.task, checkpoint, saved)
        self.task = self.task.to(device).eval()
        self.device = device

    def run(self, batch: torch.Tensor) -> np.ndarray:
        with torch.no_grad():
            return self.task(batch.to(self.device)).softmax(1)[:, 1].float().cpu().numpy()


class OnnxModel(PathModel):
    def __init__(self, path: str | Path, threads: int | None = None):
        """threads: onnxruntime's intra-op threads (None: its default, one per core)."""
        try:
            import onnxruntime as ort
        except ImportError as e:
            raise missing_extra(f"predict of {path}", "onnx", e.name) from e

        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"{path}: no such ONNX file")
        options = ort.SessionOptions()
        if threads is not None:
            options.intra_op_num_threads = threads
            options.inter_op_num_threads = 1
        # Threads that spin while they wait took the core predict's writer thread (or another
        # process) needed: without spinning, 1.5x the frames/s idle, beside a busy process too.
        options.add_session_config_entry("session.intra_op.allow_spinning", "0")
        try:
            self.session = ort.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])
        except Exception as e:  # onnxruntime raises its own exception types
            raise ValueError(f"{path}: not a loadable ONNX model ({e})") from e
        shape = self.session.get_inputs()[0].shape  # [batch, 3, h, w]
        self.height, self.width = int(shape[2]), int(shape[3])

    def run(self, batch: torch.Tensor) -> np.ndarray:
        return self.session.run(None, {self.session.get_inputs()[0].name: batch.numpy()})[0]


def mlflow_checkpoint(run_id: str, tracking_uri: str) -> Path:
    """The best checkpoint a training run logged (artifact checkpoints/best.ckpt), downloaded."""
    import mlflow

    try:
        return Path(mlflow.artifacts.download_artifacts(run_id=run_id, artifact_path="checkpoints/best.ckpt", tracking_uri=tracking_uri))
    except Exception as e:  # MLflow raises its own exception types
        raise ValueError(f"MLflow run {run_id} at {tracking_uri}: no checkpoints/best.ckpt artifact ({e})") from e


def load_model(checkpoint: str | None, run_id: str | None, tracking_uri: str, device: str = "cpu", threads: int | None = None) -> PathModel:
    """A PyTorch checkpoint (a file, or an MLflow run's) or an ONNX file; `threads` for onnxruntime
    (PyTorch's are set process-wide: offroad_path.utils.threads)."""
    if run_id:
        return TorchModel(mlflow_checkpoint(run_id, tracking_uri), device)
    if not checkpoint:
        raise ValueError("give predict.checkpoint (a .ckpt or .onnx file) or predict.run_id (an MLflow training run)")
    return OnnxModel(checkpoint, threads) if str(checkpoint).endswith(".onnx") else TorchModel(checkpoint, device)
