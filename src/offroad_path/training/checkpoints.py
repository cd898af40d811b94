"""Checkpoints that are safe to load and say nothing about where the project lives.

Every load is `torch.load(..., weights_only=True)`: a crafted file cannot run code. The checkpoints a
stage publishes (`best.ckpt`) hold only the weights and the plain values needed to rebuild the network,
so they hash the same in any checkout; Lightning's full checkpoints (optimizer, loops, callbacks with
absolute paths) stay in the resume folder, outside the stage's outputs.
"""

from __future__ import annotations

import hashlib
import os
import pickle
import re
import zipfile
from pathlib import Path
from typing import Any

import lightning as L
import torch
from lightning.fabric.plugins import TorchCheckpointIO

CONFIG_HASH = "offroad_path_config_hash"  # checkpoint key: the run's identity, see training.run.run_key


class CheckpointError(ValueError):
    """A checkpoint that is missing, corrupt, unsafe or of another network or task."""


def load_checkpoint(path: str | Path) -> dict[str, Any]:
    """A checkpoint as a dict of tensors and plain values; CheckpointError names the file otherwise."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such checkpoint")
    with open(path, "rb") as f:
        head = f.read(4)
    # torch.save writes a zip archive (a pickle, protocol 2 and up, before PyTorch 1.6): anything else
    # is not a checkpoint, and must not be reported as one whose objects the safe loader refused.
    if not (head.startswith(b"PK\x03\x04") or head.startswith(b"\x80")):
        raise CheckpointError(f"{path}: not a readable PyTorch checkpoint (neither a zip archive nor a pickle: it starts {head!r})")
    if head.startswith(b"PK\x03\x04"):
        check_archive(path)
    try:
        saved = torch.load(path, map_location="cpu", weights_only=True)
    except pickle.UnpicklingError as e:  # what weights_only raises on anything but tensors and plain values
        found = re.search(r"(?:unsupported|Unsupported global:) GLOBAL (\S+)", str(e))
        what = f"it would call {found.group(1)}" if found else _first_sentence(e)
        raise CheckpointError(f"{path}: refused, it holds objects that could run code when loaded ({what})") from e
    except Exception as e:  # truncated zip, not a torch file at all, ...
        raise CheckpointError(f"{path}: not a readable PyTorch checkpoint ({type(e).__name__}: {_first_sentence(e)})") from e
    if not isinstance(saved, dict) or not isinstance(saved.get("state_dict"), dict) or not isinstance(saved.get("hyper_parameters"), dict):
        raise CheckpointError(f"{path}: not a checkpoint of this project (no state_dict and hyper_parameters)")
    for name, tensor in saved["state_dict"].items():
        if torch.is_tensor(tensor) and tensor.is_floating_point() and not torch.isfinite(tensor).all():
            raise CheckpointError(f"{path}: weight {name} holds NaN or infinite values: a diverged run, not a model")
    return saved


def check_archive(path: Path) -> None:
    """The zip container's own CRC of every member: a checkpoint with flipped bytes loads as finite,
    wrong weights otherwise. CheckpointError naming the file and the damaged member."""
    try:
        with zipfile.ZipFile(path) as archive:
            damaged = archive.testzip()
    except (zipfile.BadZipFile, OSError, EOFError) as e:
        raise CheckpointError(f"{path}: not a readable PyTorch checkpoint (a damaged zip archive: {_first_sentence(e)})") from e
    if damaged is not None:
        raise CheckpointError(f"{path}: damaged, its member {damaged} fails the archive's CRC check (a corrupted copy?)")


def _first_sentence(error: Exception) -> str:
    text = str(error).strip().splitlines()[0] if str(error).strip() else type(error).__name__
    return text.split(". ")[0]


def save_weights(path: Path, task: L.LightningModule, **extra: Any) -> None:
    """The published checkpoint: weights, the task's hyper-parameters and `extra` plain values."""
    path.parent.mkdir(parents=True, exist_ok=True)
    torch.save({"state_dict": task.state_dict(), "hyper_parameters": dict(task.hparams), **extra}, path)


def load_weights(task: L.LightningModule, path: str | Path, saved: dict[str, Any] | None = None) -> None:
    """Load a checkpoint's weights into `task`; a checkpoint of another network is a CheckpointError."""
    saved = saved if saved is not None else load_checkpoint(path)
    try:
        task.load_state_dict(saved["state_dict"])
    except RuntimeError as e:  # torch lists the keys: name the count and the first
        state, ours = set(saved["state_dict"]), set(task.state_dict())
        missing, extra = sorted(ours - state), sorted(state - ours)
        problem = f"{len(missing)} weights missing, first {missing[0]}" if missing else ""
        problem += ("; " if problem else "") + (f"{len(extra)} unexpected, first {extra[0]}" if extra else "")
        raise CheckpointError(f"{path}: its weights do not fit this network ({problem or 'tensor shapes differ'})") from e


def file_digest(paths: list[Path], into: Any = None) -> Any:
    """sha256 over the bytes of `paths` in order (a missing path counts as empty)."""
    digest = into if into is not None else hashlib.sha256()
    for p in paths:
        digest.update(str(p.name).encode())
        if p.is_file():
            digest.update(p.read_bytes())
    return digest


class AtomicCheckpointIO(TorchCheckpointIO):
    """Lightning's checkpoint writer, but a kill during a save leaves the previous file whole."""

    def save_checkpoint(self, checkpoint: dict[str, Any], path: str | os.PathLike, storage_options: Any = None) -> None:
        path = Path(path)
        tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
        try:
            super().save_checkpoint(checkpoint, tmp, storage_options)
            os.replace(tmp, path)
        finally:
            tmp.unlink(missing_ok=True)
