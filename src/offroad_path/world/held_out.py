"""Held-out test worlds: whole drives through worlds of their own, never blocks of a training drive.

A test set cut from the training drives shares their trees, light and track, and a few blocks of it
make every by-condition figure one sequence against another. The test worlds are drawn from a seed
stream of their own and kept, in seed order, while they add what the test set still lacks: blocks
of labelled driving (`min_blocks` of `block_m` metres) and worlds that show each condition group
of the report (`per_condition`, offroad_path.world.conditions.GROUPS). What a world shows is
known before rendering (frame_conditions reads the world, not the images), so only kept worlds are
rendered. Choosing by condition favours worlds with rare conditions: the test set is built to
measure every group, not to mirror their frequency in the training drives.

Every other candidate (odd index) is drawn with a held-out look (world.appearance.held_out, which no
training drive shows): the report compares those worlds with the others, the in-distribution ones.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from offroad_path.config import TestWorldsConfig, WorldConfig
from offroad_path.utils.parallel import map_processes
from offroad_path.world.conditions import frame_conditions
from offroad_path.world.groups import GROUPS
from offroad_path.world.scene import build_world

log = logging.getLogger(__name__)
TEST_STREAM = 1  # the spawn key of test-world seeds: SeedSequence([master, i]) pads with zeros, so [master, 1, i] could repeat a drive's
MIN_FRAMES = 3  # labelled-range frames a world needs in a group to count as showing it


@dataclass(frozen=True)
class HeldOutWorld:
    index: int  # in the test seed stream
    seed: int
    blocks: int  # blocks of labelled driving
    groups: tuple[str, ...]  # condition groups it shows
    held_out_look: bool = False  # drawn with one of world.appearance.held_out's looks

    @property
    def name(self) -> str:
        return f"test_{self.index:03d}"


def held_out_seed(master_seed: int, index: int) -> int:
    return int(np.random.SeedSequence([master_seed, index], spawn_key=(TEST_STREAM,)).generate_state(1)[0])


def held_out_look(cfg: WorldConfig, index: int) -> bool:
    """Whether test candidate `index` is drawn with a held-out look: every other one, when there are such looks."""
    return bool(cfg.appearance.enabled and cfg.appearance.held_out and index % 2 == 1)


def required_groups(cfg: WorldConfig) -> list[str]:
    """The condition groups the test set must show: the looks' groups only where the world draws looks."""
    looks = {"shadow_water", "dappled", "grass_track", "no_track", "seen_look", "held_out_look"}
    skip = set() if cfg.appearance.enabled else looks
    if not (cfg.appearance.enabled and cfg.appearance.held_out):
        skip.add("held_out_look")
    return [key for key, _, _ in GROUPS if key not in skip]


def survey(cfg: WorldConfig, seed: int, c: TestWorldsConfig, look_held_out: bool = False) -> tuple[int, tuple[str, ...]]:
    """(blocks of labelled driving, condition groups shown) of the world drawn from `seed`: frames
    with `horizon_m` of drive ahead get labels; blocks start every `block_m` along the drive."""
    world = build_world(cfg, seed, look_held_out)
    s = np.asarray(world.frame_s) - world.frame_s[0]
    labelled = s <= s[-1] - c.horizon_m
    rows = [row for row, keep in zip(frame_conditions(world, cfg), labelled, strict=True) if keep]
    blocks = len(np.unique(s[labelled] // c.block_m))
    shown = tuple(key for key, _, test in GROUPS if sum(map(test, rows)) >= MIN_FRAMES)
    return blocks, shown


def _survey_job(args: tuple[WorldConfig, int, int, TestWorldsConfig]) -> HeldOutWorld:
    cfg, index, seed, c = args
    look = held_out_look(cfg, index)
    return HeldOutWorld(index, seed, *survey(cfg, seed, c, look), held_out_look=look)


def choose_held_out_worlds(cfg: WorldConfig, c: TestWorldsConfig, master_seed: int, workers: int = 0) -> list[HeldOutWorld]:
    """The test worlds of the module docstring, surveyed `workers` at a time; ValueError when
    `max_candidates` worlds do not make the set (naming what it lacks)."""
    if c.min_blocks == 0:
        return []
    chosen: list[HeldOutWorld] = []
    shown = dict.fromkeys(required_groups(cfg), 0)
    batch = max(1, workers or 2)
    for start in range(0, c.max_candidates, batch):
        indices = range(start, min(start + batch, c.max_candidates))
        jobs = [(cfg, i, held_out_seed(master_seed, i), c) for i in indices]
        for world in map_processes(_survey_job, jobs, workers, [f"test world {i}" for i in indices]):
            lacking = [k for k, n in shown.items() if n < c.per_condition]
            short = sum(w.blocks for w in chosen) < c.min_blocks
            if (lacking and set(world.groups) & set(lacking)) or (not lacking and short):
                chosen.append(world)
                for key in set(world.groups) & shown.keys():
                    shown[key] += 1
            if not _lacks(chosen, shown, c):
                log.info("test worlds: kept %d of %d drawn, %d blocks", len(chosen), world.index + 1, sum(w.blocks for w in chosen))
                return chosen
    missing = _lacks(chosen, shown, c)
    raise ValueError(
        f"synthesize.test_worlds: {c.max_candidates} candidate worlds do not make the test set ({missing}); "
        "raise max_candidates or lower min_blocks or per_condition"
    )


def _lacks(chosen: list[HeldOutWorld], shown: dict[str, int], c: TestWorldsConfig) -> str:
    """What the chosen worlds still lack, in words; '' when nothing."""
    blocks = sum(w.blocks for w in chosen)
    parts = [f"{blocks} of {c.min_blocks} blocks"] if blocks < c.min_blocks else []
    parts += [f"{k} in {n} of {c.per_condition} worlds" for k, n in shown.items() if n < c.per_condition]
    return ", ".join(parts)
