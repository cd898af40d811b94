"""Every frame of the labelled sequences with its steering angle, split by the path split's blocks.

The path split (offroad_path.data.splitting) holds out whole blocks of driving. Here each frame
goes to the part of its block when the path split held that block out; other frames train unless
they lie within the guard distance of a held-out frame. So the steering network is tested on the
same stretches of driving as the path networks, and never sees their neighbours in training.
"""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from offroad_path.data.manifest import read_manifest
from offroad_path.sequence.poses import read_poses
from offroad_path.sequence.reader import open_sequence

log = logging.getLogger(__name__)
PARTS = ("train", "val", "test")


@dataclass(frozen=True)
class SteeringFrame:
    sequence: str
    frame: int
    image: str
    steering: float  # normalised, in [-1, 1], positive turns right; negated when mirrored
    mirrored: bool = False


def travelled(poses: np.ndarray) -> np.ndarray:
    """Distance driven (m) at each frame of (N, 4, 4) camera poses."""
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(poses[:, :3, 3], axis=0), axis=1))])


def steering_split(labels_dir: Path, split_dir: Path, block_m: float, guard_m: float, mirror: bool) -> dict[str, list[SteeringFrame]]:
    """{'train', 'val', 'test'}: frames of every labelled sequence that has steering.txt."""
    summary_path = labels_dir / "summary.json"
    if not summary_path.is_file():
        raise FileNotFoundError(f"{summary_path}: missing (run the label stage first)")
    held_out_part = {}  # (sequence, f0) -> 'val' | 'test'
    for part in ("val", "test"):
        for sample in read_manifest(split_dir / f"{part}.csv"):
            held_out_part[sample.sequence, sample.f0] = part
    parts: dict[str, list[SteeringFrame]] = {p: [] for p in PARTS}
    skipped, guarded = [], 0
    for entry in json.loads(summary_path.read_text())["sequences"]:
        name, seq = entry["name"], open_sequence(entry["root"])
        if seq.steering is None:
            skipped.append(name)
            continue
        poses_path = labels_dir / name / "poses_vo.txt"
        at = travelled(read_poses(poses_path, len(seq)) if poses_path.is_file() else seq.poses)
        blocks = (at // block_m).astype(int)
        block_part = {blocks[f0]: part for (s, f0), part in held_out_part.items() if s == name}
        part_of = [block_part.get(b, "train") for b in blocks]
        held = at[[p != "train" for p in part_of]]
        for i, part in enumerate(part_of):
            if part == "train" and len(held) and np.abs(held - at[i]).min() < guard_m:
                guarded += 1
                continue
            frame = SteeringFrame(name, i, str(seq.left[i]), float(seq.steering[i]))
            parts[part].append(frame)
            if mirror:
                parts[part].append(SteeringFrame(name, i, frame.image, -frame.steering, mirrored=True))
    if skipped:
        log.warning("no steering.txt in %d sequence(s), left out of the steering baseline: %s", len(skipped), ", ".join(skipped))
    if not parts["train"] or not parts["test"]:
        raise ValueError(f"{labels_dir}: no sequence with steering.txt gives both training and test frames")
    log.info("steering frames: %s (mirrored copies included: %s), %d training frames left out beside held-out ones",
             {p: len(f) for p, f in parts.items()}, mirror, guarded)  # fmt: skip
    return parts
