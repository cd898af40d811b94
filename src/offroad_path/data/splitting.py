"""Train / validation / test splits of labelled frames that do not leak.

Labels a few metres apart show nearly the same scene, so a per-image random split (the paper's)
puts near-duplicates on both sides. Here frames are grouped into blocks of `block_m` metres of
driving within each sequence; whole blocks go to validation (and to test), and training frames
within `guard_m` of a held-out frame are left out, so no held-out frame has a neighbour in training.

Frames of held-out test worlds (a recording whose meta.json says "split": "test", as the
synthesize stage's test_NNN drives do) are the whole test set when there are any; test_fraction
then takes no blocks from the other drives.

The `stretch` strategy holds out one stretch per recording instead (your own driving): the last
test_fraction of each sequence's labelled driving is test, the val_fraction before it validation,
with the same guard.
"""

from __future__ import annotations

import logging
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from offroad_path.config.label_schema import SPLIT_STRATEGIES

if TYPE_CHECKING:
    from offroad_path.config.label_schema import SplitConfig

log = logging.getLogger(__name__)
STRATEGIES = SPLIT_STRATEGIES


@dataclass(frozen=True)
class Frame:
    sequence: str
    f0: int
    travelled_m: float  # position along the sequence's driven path at f0
    held_out: bool = False  # from a held-out test world
    development: bool = False  # from a development world (held out too): its own manifest, development.csv


TRAINING_PARTS = ("train", "val")  # what a network learns from or is selected on


def refuse_held_out_training(parts: Mapping[str, Iterable[str]], held_out: Iterable[str], where: str) -> None:
    """The rule every task's split obeys (the path split and PilotNet's): no frame of a held-out world
    (main test, development, stress) in a training or validation part. parts: part -> the sequence
    of each of its frames; held_out: the held-out worlds' sequences. ValueError naming them otherwise."""
    held = set(held_out)
    leaked = {part: sorted(held.intersection(parts.get(part, ()))) for part in TRAINING_PARTS}
    if any(leaked.values()):
        shown = "; ".join(f"{part}: {', '.join(names)}" for part, names in leaked.items() if names)
        raise ValueError(f"{where}: frames of held-out worlds would train a network ({shown})")


def block_of(sequence: str, travelled_m: float, block_m: float) -> tuple[str, int]:
    """The block of driving a frame belongs to: its sequence and the block_m-long stretch of it."""
    return sequence, int(travelled_m // block_m)


def split_frames(frames: list[Frame], c: SplitConfig) -> tuple[dict[str, list[Frame]], int]:
    """({'train': [...], 'val': [...], 'test': [...], 'development': [...]}, number of training frames left out as guard),
    by the `split` settings (strategy, test_fraction, val_fraction, block_m, guard_m, seed)."""
    if c.strategy not in STRATEGIES:
        raise ValueError(f"unknown split strategy {c.strategy!r}; valid: {', '.join(STRATEGIES)}")
    rng = np.random.default_rng(c.seed)
    development = [f for f in frames if f.development]
    worlds = [f for f in frames if f.held_out and not f.development]
    frames = [f for f in frames if not f.held_out]
    test_fraction = 0.0 if worlds else c.test_fraction
    if c.strategy == "random":
        log.warning("split strategy 'random' (the paper's per-image split) puts near-duplicate neighbours in train and test")
        order = rng.permutation(len(frames))
        n_test, n_val = round(test_fraction * len(frames)), round(c.val_fraction * len(frames))
        picked = [frames[i] for i in order]
        split = {"test": worlds + picked[:n_test], "val": picked[n_test : n_test + n_val], "train": picked[n_test + n_val :]}
        return split | {"development": development}, 0

    split = _stretches(frames, test_fraction, c.val_fraction) if c.strategy == "stretch" else _blocks(frames, test_fraction, c, rng)
    held_out: dict[str, np.ndarray] = {}
    for frame in split["test"] + split["val"]:
        held_out.setdefault(frame.sequence, []).append(frame.travelled_m)
    train = [f for f in split["train"] if not _near(f, held_out, c.guard_m)]
    guarded = len(split["train"]) - len(train)
    split["train"] = train
    split["test"] += worlds
    split["development"] = development
    for name in split:
        split[name].sort(key=lambda f: (f.sequence, f.f0))
    refuse_held_out_training(
        {p: (f.sequence for f in split[p]) for p in TRAINING_PARTS}, (f.sequence for f in worlds + development), "split"
    )
    return split, guarded


def _blocks(frames: list[Frame], test_fraction: float, c: SplitConfig, rng: np.random.Generator) -> dict[str, list[Frame]]:
    """Whole blocks of driving, in random order, to test and validation until each has its share."""
    groups: dict[tuple[str, int], list[Frame]] = {}
    for frame in frames:
        groups.setdefault(block_of(frame.sequence, frame.travelled_m, c.block_m), []).append(frame)
    keys = sorted(groups)
    order = [keys[i] for i in rng.permutation(len(keys))]
    split: dict[str, list[Frame]] = {"test": [], "val": [], "train": []}
    targets = {"test": test_fraction * len(frames), "val": c.val_fraction * len(frames)}
    for key in order:
        for name in ("test", "val"):
            if len(split[name]) < targets[name]:
                split[name].extend(groups[key])
                break
        else:
            split["train"].extend(groups[key])
    return split


def _stretches(frames: list[Frame], test_fraction: float, val_fraction: float) -> dict[str, list[Frame]]:
    """Per sequence, by distance along its labelled driving: the last test_fraction to test, the
    val_fraction before it to validation, the rest to training."""
    split: dict[str, list[Frame]] = {"test": [], "val": [], "train": []}
    for sequence in sorted({f.sequence for f in frames}):
        own = [f for f in frames if f.sequence == sequence]
        first, last = min(f.travelled_m for f in own), max(f.travelled_m for f in own)
        test_from = last - test_fraction * (last - first)
        val_from = test_from - val_fraction * (last - first)
        for f in own:
            split["test" if f.travelled_m >= test_from else "val" if f.travelled_m >= val_from and val_fraction else "train"].append(f)
    return split


def _near(frame: Frame, held_out: dict[str, list[float]], guard_m: float) -> bool:
    positions = held_out.get(frame.sequence)
    return positions is not None and bool(np.min(np.abs(np.asarray(positions) - frame.travelled_m)) < guard_m)
