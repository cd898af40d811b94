"""Held-out test worlds: whole drives through worlds of their own, never blocks of a training drive.

Three kinds, each from a seed stream of its own:

- The development set, on which every setting is chosen (benchmarks/recipe_search.py,
  benchmarks/learning_curve.py): worlds drawn exactly as the main test set's, from the stream that
  the first runs scored their main test set on, until it holds `development_blocks` blocks; and
  the retired main test set (`retired_blocks` blocks of the stream the next runs scored, named
  retired_NNN), whose results were looked at before its rules were last changed. No stage trains
  or scores on either; the split writes them to a manifest of their own.
- The main test set, which the headline figures (Table 5.1, the baselines, the primaries) score:
  worlds drawn exactly as the training drives are (world.appearance.weights) from the stream
  `main_stream` (the pre-registered design's, conf/evaluate/design/), kept in seed order until it
  holds `min_blocks` blocks of `block_m` labelled metres. It measures the claim on the
  distribution the networks were trained for, with every condition at its natural frequency.
- Stress sets, one per hard case of `stress_sets` (a condition group of
  offroad_path.world.groups.GROUPS): `per_stress` worlds each, drawn for the purpose and kept when
  they show the case on at least MIN_FRAMES labelled frames; each is reported against the mean-path
  prior on its own, never pooled into the main figures. A stress world's look is drawn by the
  training weights, so every look value it tests is one the training drives may show, except in
  `held_out_look` (world.appearance.held_out's combinations, which no training drive shows) and
  `outside_look` (every value alike, kept when one is of weight 0: the variety the default leaves out).

What a world shows is known before rendering (frame_conditions reads the world, not the images), so
only kept worlds are rendered.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np

from offroad_path.config.world_schema import TestWorldsConfig, WorldConfig
from offroad_path.sequence.meta import DEVELOPMENT, MAIN
from offroad_path.utils.parallel import map_processes
from offroad_path.utils.threads import usable_cores
from offroad_path.world.appearance import AXES, training_values
from offroad_path.world.conditions import frame_conditions
from offroad_path.world.groups import GROUPS
from offroad_path.world.scene import appearance_weights, build_world

log = logging.getLogger(__name__)
# Spawn keys: SeedSequence([master, i]) pads with zeros, so [master, 1, i] could repeat a drive's.
DEVELOPMENT_STREAM = 1  # the development set's: the first runs' main test set, which settings were tuned on
RETIRED_STREAM = 4  # the main test set's until its rules changed after a look: development worlds since
STRESS_STREAM = 3  # the spawn key of stress-world seeds (2 is the appearance's)
# The main test set's stream is the design's (synthesize.test_worlds.main_stream): above every one of these.
RESERVED_STREAMS = (DEVELOPMENT_STREAM, 2, STRESS_STREAM, RETIRED_STREAM)
RETIRED = "retired"  # the retired main test set's worlds: in the development set, named apart
MIN_FRAMES = 3  # labelled-range frames a world needs in a group to count as showing it
# How a stress set's worlds draw their look (offroad_path.world.appearance.DRAWS); every other set: "training".
STRESS_DRAWS = {"held_out_look": "held_out", "outside_look": "full_variety"}


@dataclass(frozen=True)
class HeldOutWorld:
    index: int  # in its set's seed stream
    seed: int
    blocks: int  # blocks of labelled driving
    groups: tuple[str, ...]  # condition groups it shows
    test_set: str = MAIN  # main, development, or the stress set it was drawn for
    retired: bool = False  # a development world of the retired main test set

    @property
    def name(self) -> str:
        if self.retired:
            return f"{PREFIXES[RETIRED]}_{self.index:03d}"
        if self.test_set in PREFIXES:
            return f"{PREFIXES[self.test_set]}_{self.index:03d}"
        return f"stress_{self.test_set}_{self.index:03d}"

    @property
    def draw(self) -> str:
        return STRESS_DRAWS.get(self.test_set, "training")


PREFIXES = {DEVELOPMENT: "dev", RETIRED: "retired", MAIN: "test"}  # the sets drawn as the training drives are


def held_out_seed(master_seed: int, index: int, stream: int) -> int:
    """World `index` of a set drawn as the training drives are (main, development, retired): a stream each."""
    return int(np.random.SeedSequence([master_seed, index], spawn_key=(stream,)).generate_state(1)[0])


def stress_seed(master_seed: int, stress_set: str, index: int) -> int:
    """Candidate `index` of a stress set: a stream per set, so adding a set leaves the others' worlds as they are."""
    key = [ord(c) for c in stress_set]
    return int(np.random.SeedSequence([master_seed, *key, index], spawn_key=(STRESS_STREAM,)).generate_state(1)[0])


def survey(cfg: WorldConfig, seed: int, c: TestWorldsConfig, draw: str = "training") -> tuple[int, tuple[str, ...]]:
    """(blocks of labelled driving, condition groups shown) of the world drawn from `seed`: frames
    with `horizon_m` of drive ahead get labels; blocks start every `block_m` along the drive."""
    world = build_world(cfg, seed, draw, textures=False)  # what a world shows does not depend on its textures
    s = np.asarray(world.frame_s) - world.frame_s[0]
    labelled = s <= s[-1] - c.horizon_m
    rows = [row for row, keep in zip(frame_conditions(world, cfg), labelled, strict=True) if keep]
    blocks = len(np.unique(s[labelled] // c.block_m))
    shown = tuple(key for key, _, test in GROUPS if sum(map(test, rows)) >= MIN_FRAMES)
    return blocks, shown


def _survey_job(args: tuple[WorldConfig, int, int, TestWorldsConfig, str, bool]) -> HeldOutWorld:
    cfg, index, seed, c, test_set, retired = args
    return HeldOutWorld(index, seed, *survey(cfg, seed, c, STRESS_DRAWS.get(test_set, "training")), test_set=test_set, retired=retired)


@dataclass
class _Search:
    """One set's walk through its candidate worlds, in seed order, and the worlds it has kept."""

    test_set: str
    wanted: int  # blocks (a set drawn as the training drives are) or worlds (a stress set)
    key: str  # the setting that asks for them, named when the candidates run out
    stream: int = 0  # a set drawn as the training drives are: its spawn key; 0: a stress set
    retired: bool = False
    next_index: int = 0
    kept: list[HeldOutWorld] = field(default_factory=list)

    @property
    def stress(self) -> bool:
        return not self.stream

    @property
    def label(self) -> str:
        return RETIRED if self.retired else self.test_set

    @property
    def done(self) -> bool:
        return (len(self.kept) if self.stress else sum(w.blocks for w in self.kept)) >= self.wanted

    def seed(self, master_seed: int, index: int) -> int:
        return stress_seed(master_seed, self.test_set, index) if self.stress else held_out_seed(master_seed, index, self.stream)

    def take(self, world: HeldOutWorld) -> None:
        """The next candidate in seed order: kept while the set is not made (a stress set's, if it shows the case)."""
        if not self.done and (not self.stress or self.test_set in world.groups):
            self.kept.append(world)


def choose_held_out_worlds(cfg: WorldConfig, c: TestWorldsConfig, master_seed: int, workers: int = 0) -> list[HeldOutWorld]:
    """The development and main test sets, then each stress set (module docstring); ValueError naming
    the set when `max_candidates` worlds do not make it. min_blocks 0: no test worlds at all.

    Every set's candidates are surveyed in rounds, one process map per round over every set not yet
    done, so that all cores work and worker processes start once a round, not once a set's batch.
    A set takes its candidates in seed order whatever the round size: which worlds are chosen does not
    depend on the cores (surplus candidates of a round are surveyed and dropped)."""
    if c.min_blocks == 0:
        return []
    searches = [
        _Search(DEVELOPMENT, c.development_blocks, "development_blocks", DEVELOPMENT_STREAM),
        _Search(DEVELOPMENT, c.retired_blocks, "retired_blocks", RETIRED_STREAM, retired=True),
        _Search(MAIN, c.min_blocks, "min_blocks", c.main_stream),
    ]
    for stress_set in c.stress_sets:
        if stress_set in STRESS_DRAWS and not _draws_differ(cfg, stress_set):
            log.warning("stress set %s: the training distribution already draws every such look; left out", stress_set)
        else:
            searches.append(_Search(stress_set, c.per_stress, "per_stress"))
    cores = workers or usable_cores()
    while open_searches := [s for s in searches if not s.done and s.next_index < c.max_candidates]:
        per_search = max(1, -(-cores // len(open_searches)))
        jobs = []
        for search in open_searches:
            indices = range(search.next_index, min(search.next_index + per_search, c.max_candidates))
            jobs += [(cfg, i, search.seed(master_seed, i), c, search.test_set, search.retired) for i in indices]
            search.next_index = indices.stop
        by_set = {s.label: s for s in open_searches}
        for world in map_processes(_survey_job, jobs, workers, [f"{job[4]} test world {job[1]}" for job in jobs]):
            by_set[RETIRED if world.retired else world.test_set].take(world)
        _check_shortfall(searches, c.max_candidates)
    for search in searches:
        name = f"stress set {search.test_set}" if search.stress else f"{search.label} set"
        log.info("%s: %d worlds, %d blocks", name, len(search.kept), sum(w.blocks for w in search.kept))
    return [world for search in searches for world in search.kept]


def _check_shortfall(searches: list[_Search], max_candidates: int) -> None:
    """ValueError naming the first set, in order, whose candidates ran out before it was made, as soon
    as every set before it is made (so the error is the one a set-by-set search would raise)."""
    for search in searches:
        if search.done:
            continue
        if search.next_index < max_candidates:
            return  # still searching: a later set's shortfall waits for it
        if search.stress:
            raise ValueError(
                f"synthesize.test_worlds: {max_candidates} candidate worlds give stress set {search.test_set} "
                f"{len(search.kept)} of {search.wanted} worlds; raise max_candidates or lower per_stress"
            )
        raise ValueError(
            f"synthesize.test_worlds.{search.key}: {max_candidates} candidate worlds hold fewer than {search.wanted} blocks; "
            "raise max_candidates"
        )


def _draws_differ(cfg: WorldConfig, stress_set: str) -> bool:
    """Whether a look-drawn stress set can hold anything: held-out looks need world.appearance.held_out,
    looks outside the training distribution need a weight of 0 somewhere."""
    if not cfg.appearance.enabled:
        return False
    if stress_set == "held_out_look":
        return bool(cfg.appearance.held_out)
    weights = appearance_weights(cfg)
    return any(len(training_values(weights, axis)) < len(training_values(None, axis)) for axis in AXES)
