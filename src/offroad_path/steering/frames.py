"""Every frame of the labelled sequences with its steering angle, split by the path split's blocks.

The path split (offroad_path.data.splitting) holds out whole blocks of driving. Here each frame
goes to the part of its block when the path split held that block out. Other frames of a training
drive train unless they lie within the guard distance of a held-out frame; other frames of a
held-out world (its unlabelled last metres, a block without a test label) are left out, since no
network may learn from a held-out world (splitting.refuse_held_out_training, the rule the path split
obeys too). So the steering network is tested on the same stretches of driving as the path
networks, and never sees them, their worlds or their neighbours in training.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from offroad_path.data.labels import read_label_run
from offroad_path.data.manifest import Sample, read_manifest, write_manifest
from offroad_path.data.splitting import refuse_held_out_training
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
    fx: float = 0.0  # the sequence's calibration, for the manifests the stage writes (write_frames)
    baseline_m: float = 0.0


def write_frames(folder: Path, parts: dict[str, list[SteeringFrame]]) -> None:
    """<part>.csv for each part, in the split's manifest format (data.manifest), so anyone can check
    which frames a PilotNet learnt from and was tested on; label, disparity and semantic are empty
    (a steering frame is any frame of the drive, labelled or not)."""
    for part, frames in parts.items():
        rows = [Sample(f.sequence, f.frame, f.mirrored, f.image, "", "", "", f.fx, f.baseline_m) for f in frames]
        write_manifest(folder / f"{part}.csv", rows)


def _runs(labels_dir: Path, tested: set[str]) -> tuple[list, set[str]]:
    """The label runs PilotNet's split draws from, and the held-out worlds' names. A held-out world the
    split does not test (a development world, settings are chosen on) is neither trained nor tested
    on; of a tested one, only the frames of its tested blocks are used (steering_split)."""
    held_out_worlds, runs = set(), []
    for run in read_label_run(labels_dir):
        if meta.held_out(run.sequence.meta, run.sequence.root / "meta.json"):
            held_out_worlds.add(run.name)
            if run.name not in tested:
                continue
        runs.append(run)
    return runs, held_out_worlds


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
    runs, held_out_worlds = _runs(labels_dir, {sequence for sequence, _ in held_out_part})
    parts: dict[str, list[SteeringFrame]] = {p: [] for p in PARTS}
    skipped, guarded, unused = [], 0, 0
    for run in runs:
        name, seq = run.name, run.sequence
        angles = seq.steering if steering is None else steering.get(name)
        if angles is None:
            skipped.append(name)
            continue
        at = run.distance()
        blocks = (at // block_m).astype(int)
        block_part = {blocks[f0]: part for (s, f0), part in held_out_part.items() if s == name}
        # a held-out world's frames outside its tested blocks train nothing: they are left out
        part_of = [block_part.get(b, "" if name in held_out_worlds else "train") for b in blocks]
        unused += part_of.count("")
        held = at[[p not in ("train", "") for p in part_of]]
        calibration = seq.calibration
        for i, part in enumerate(part_of):
            if not part or (part == "train" and len(held) and np.abs(held - at[i]).min() < guard_m):
                guarded += bool(part)
                continue
            frame = SteeringFrame(name, i, str(seq.left[i]), float(angles[i]), False, calibration.fx, calibration.baseline_m)
            parts[part].append(frame)
            if mirror:
                parts[part].append(SteeringFrame(name, i, frame.image, -frame.steering, True, calibration.fx, calibration.baseline_m))
    refuse_held_out_training({p: (f.sequence for f in parts[p]) for p in PARTS}, held_out_worlds, f"{labels_dir}: the steering split")
    if skipped:
        log.warning("no steering.txt in %d sequence(s), left out of the steering baseline: %s", len(skipped), ", ".join(skipped))
    if not parts["train"] or not parts["test"]:
        raise ValueError(f"{labels_dir}: no sequence with steering.txt gives both training and test frames")
    log.info(
        "steering frames: %s (mirrored copies included: %s), %d training frames left out beside held-out ones, "
        "%d frames of held-out worlds outside their tested blocks left out",
        {p: len(f) for p, f in parts.items()},
        mirror,
        guarded,
        unused,
    )
    return parts
