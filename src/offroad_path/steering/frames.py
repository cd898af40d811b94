"""Every frame of the labelled sequences with its steering angle, split by the path split's blocks.

The path split (offroad_path.data.splitting) holds out whole blocks of driving. Here each frame
goes to the part of its block when the path split held that block out; other frames train unless
they lie within the guard distance of a held-out frame. So the steering network is tested on the
same stretches of driving as the path networks, and never sees their neighbours in training.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from offroad_path.data.labels import read_label_run
from offroad_path.data.manifest import read_manifest
from offroad_path.sequence import meta

log = logging.getLogger(__name__)
PARTS = ("train", "val", "test")


@dataclass(frozen=True)
class SteeringFrame:
    sequence: str
    frame: int
    image: str
    steering: float  # normalised, in [-1, 1], positive turns right; negated when mirrored
    mirrored: bool = False


def steering_split(  # noqa: PLR0913
    labels_dir: Path,
    split_dir: Path,
    block_m: float,
    guard_m: float,
    mirror: bool,
    *,
    steering: dict[str, np.ndarray] | None = None,
) -> dict[str, list[SteeringFrame]]:
    """{'train', 'val', 'test'}: frames of every labelled sequence that has steering.txt (or, with
    `steering`, an angle per frame by sequence name in place of steering.txt's)."""
    held_out_part = {}  # (sequence, f0) -> 'val' | 'test'
    for part in ("val", "test"):
        for sample in read_manifest(split_dir / f"{part}.csv"):
            held_out_part[sample.sequence, sample.f0] = part
    # A held-out world the split does not test (a development world, settings are chosen on) is
    # neither trained nor tested on.
    tested = {sequence for sequence, _ in held_out_part}
    runs = [run for run in read_label_run(labels_dir) if run.name in tested or not meta.held_out(run.sequence.meta, run.sequence.root)]
    parts: dict[str, list[SteeringFrame]] = {p: [] for p in PARTS}
    skipped, guarded = [], 0
    for run in runs:
        name, seq = run.name, run.sequence
        angles = seq.steering if steering is None else steering.get(name)
        if angles is None:
            skipped.append(name)
            continue
        at = run.distance()
        blocks = (at // block_m).astype(int)
        block_part = {blocks[f0]: part for (s, f0), part in held_out_part.items() if s == name}
        part_of = [block_part.get(b, "train") for b in blocks]
        held = at[[p != "train" for p in part_of]]
        for i, part in enumerate(part_of):
            if part == "train" and len(held) and np.abs(held - at[i]).min() < guard_m:
                guarded += 1
                continue
            frame = SteeringFrame(name, i, str(seq.left[i]), float(angles[i]))
            parts[part].append(frame)
            if mirror:
                parts[part].append(SteeringFrame(name, i, frame.image, -frame.steering, mirrored=True))
    if skipped:
        log.warning("no steering.txt in %d sequence(s), left out of the steering baseline: %s", len(skipped), ", ".join(skipped))
    if not parts["train"] or not parts["test"]:
        raise ValueError(f"{labels_dir}: no sequence with steering.txt gives both training and test frames")
    log.info(
        "steering frames: %s (mirrored copies included: %s), %d training frames left out beside held-out ones",
        {p: len(f) for p, f in parts.items()},
        mirror,
        guarded,
    )
    return parts
