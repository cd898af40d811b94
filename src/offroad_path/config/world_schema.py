"""Schemas of the world and its rendering: paths, the rig, the vehicle, slip, appearance, test worlds (synthesize)."""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from typing import Any

from omegaconf import MISSING

from offroad_path.config.common import FINITE, IMAGE_SIZE, PITCH
from offroad_path.looks import axis_values
from offroad_path.utils.rules import (
    SEED,
    ConfigValueError,
    Rule,
    at_least,
    between,
    distinct,
    each,
    one_of,
    ordered_pair,
    positive,
    rule,
    setting,
    torch_device,
)

# The report's condition groups, which synthesize.test_worlds.stress_sets name: world.groups.GROUPS's
# keys, in order (tests/config/test_config.py checks that they agree).
GROUP_KEYS = ("all", "shadow", "no_shadow", "water", "fork", "off_track", "paved", "dirt", "sharp_bend", "bend", "gentle",
              "shadow_water", "dappled", "grass_track", "no_track", "seen_look", "held_out_look", "outside_look")  # fmt: skip


@dataclass
class PathsConfig:
    """Where the stages read and write (conf/paths): every stage's *_dir and *_path is made from these."""

    root: str = MISSING
    data_dir: str = MISSING
    metrics_dir: str = MISSING
    recordings_dir: str = MISSING
    logs_dir: str = MISSING
    exports_dir: str = MISSING
    predictions_dir: str = MISSING


@dataclass
class RigConfig:
    name: str = MISSING
    baseline_m: float = setting(positive())


@dataclass
class VehicleConfig:
    width_m: float = setting(positive())
    length_m: float = setting(positive())
    wheelbase_m: float = setting(positive())
    track_m: float = setting(positive())
    camera_height_m: float = setting(positive())
    camera_forward_m: float = setting(FINITE)  # camera ahead of the body centre
    camera_pitch_deg: float = setting(PITCH)  # optical axis tilted down
    max_steering_deg: float = setting(between(0, 90, low_open=True, high_open=True))


@dataclass
class SlipConfig:
    """Traction below the kinematic bicycle model's (offroad_path.world.slip): off by default."""

    enabled: bool = MISSING  # synthesize: the recorded steering is the input that made the motion under slip
    factors: dict[str, float] = setting(each(positive()))  # yaw-rate factor per surface class name; 1 where absent
    # The factor's jitter is drawn once per square patch this wide (a grid over the whole world: smaller ones do not fit memory).
    patch_m: float = setting(at_least(0.5))
    jitter: float = setting(between(0, 1, high_open=True))  # patch factors in [1 - jitter, 1 + jitter] times the surface's
    noise: float = setting(at_least(0))  # per-step (per-frame) noise of the factor, a standard deviation


def _valid_looks(combinations: Any) -> bool:
    axes = axis_values()
    return all(c and all(axes.get(k) and v in axes[k] for k, v in c.items()) for c in combinations)


LOOKS = {
    "rule": Rule(
        _valid_looks,
        "must list combinations such as {track: mud, season: autumn} of the axes track, season, light, vegetation",
    )
}


def _valid_weights(weights: Any) -> bool:
    axes = axis_values()
    return all(
        axis in axes
        and set(values) <= set(axes[axis])
        and all(isinstance(w, int | float) and math.isfinite(w) and w >= 0 for w in values.values())
        and sum(values.values()) > 0
        for axis, values in weights.items()
    )


WEIGHTS = {
    "rule": Rule(
        _valid_weights,
        "must map axes (track, season, light, vegetation) to {value: weight >= 0} with a positive weight on each axis",
    )
}


@dataclass
class AppearanceConfig:
    """Each world's look drawn from a stream of its own (offroad_path.world.appearance)."""

    enabled: bool = MISSING  # false: one look for every world (the simplest world, for tests and tours)
    # Looks no training drive shows; every other test world is drawn from them (the held-out-appearance test set).
    held_out: list[dict[str, str]] = setting(LOOKS)
    # The training distribution: per axis, each value's weight (absent or 0: no training drive shows it); an
    # axis not listed draws its values alike. The stress set `outside_look` draws from every value alike.
    weights: dict[str, Any] = setting(WEIGHTS)  # Any: OmegaConf cannot merge a typed dict of dicts


@dataclass
class WorldConfig:
    """One rendered sequence's generator settings; per-sequence variation is drawn around these."""

    rig: RigConfig = field(default_factory=RigConfig)
    vehicle: VehicleConfig = field(default_factory=VehicleConfig)
    frames: int = setting(at_least(2))
    fps: float = setting(positive())
    speed_min_mps: float = setting(positive())
    speed_max_mps: float = setting(positive())
    width: int = setting(IMAGE_SIZE)
    height: int = setting(IMAGE_SIZE)
    hfov_deg: float = setting(between(1, 179))
    max_distance_m: float = setting(positive())
    hill_height_m: float = setting(at_least(0))
    bump_height_m: float = setting(at_least(0))
    max_curvature: float = setting(positive())  # 1/m; the peak of a drive, reached once or twice per sequence
    track_width_m: float = setting(positive())
    trees_per_hectare: float = setting(at_least(0))
    bushes_per_hectare: float = setting(at_least(0))
    obstacles_per_100m: float = setting(at_least(0))
    puddles_per_100m: float = setting(at_least(0))
    forks_per_100m: float = setting(at_least(0))
    offtrack_per_100m: float = setting(at_least(0))
    paved_fraction: float = setting(between(0, 1))
    sun_elevation_deg: tuple[float, float] = setting(ordered_pair(0, 90, low_open=True))
    density_jitter: float = setting(between(0, 1, high_open=True))  # per-sequence density factor drawn in [1 - j, 1 + j]
    slip: SlipConfig = field(default_factory=SlipConfig)
    appearance: AppearanceConfig = field(default_factory=AppearanceConfig)


@dataclass
class TestWorldsConfig:
    min_blocks: int = setting(at_least(0))  # the main test set's blocks; 0: no test worlds (the split takes test blocks from the drives)
    # The main test set's spawn key: 1-4 are the development set's, the appearance's, the stress sets' and
    # the retired main test set's (offroad_path.world.held_out), so a fresh test set takes 5 or above.
    main_stream: int = setting(at_least(5))
    development_blocks: int = setting(at_least(0))  # the development set's blocks (settings are chosen there); 0: none
    retired_blocks: int = setting(at_least(0))  # the retired main test set's, in the development set; 0: none
    # Stress sets (offroad_path.world.held_out): condition groups (offroad_path.world.groups.GROUPS), each reported on its own.
    stress_sets: list[str] = setting(distinct(one_of(GROUP_KEYS)))
    per_stress: int = setting(at_least(0))  # worlds per stress set
    block_m: float = setting(positive())
    # The last metres of a drive, which get no label (label.distance_m): checked here too, since the
    # synthesize stage reads it without the label group's rules.
    horizon_m: float = setting(rule(lambda v: v > 0, "must be a number > 0 (it is label.distance_m unless set apart)"))
    max_candidates: int = setting(at_least(1))


@dataclass
class RenderConfig:
    backend: str = setting(one_of(("numpy", "torch")))
    device: str = setting(torch_device())  # torch's device name, or auto
    views_per_batch: int = setting(at_least(2))


@dataclass
class SynthesizeConfig:
    sequences: int = setting(at_least(1))
    seed: int = setting(SEED)
    test_worlds: TestWorldsConfig = field(default_factory=TestWorldsConfig)
    workers: int = setting(at_least(0))  # 0: one per CPU core
    out_dir: str = MISSING


def check_looks_drawable(appearance: Any) -> None:
    """Some look of the training distribution (world.appearance.weights) is not held out
    (world.appearance.held_out): else every training drive would be drawn in a held-out look, which
    the held-out-look stress set promises none shows. ConfigValueError naming both keys."""
    if not appearance.enabled:
        return
    axes, weights = axis_values(), appearance.weights or {}
    support = [
        [value for value in values if axis not in weights or float(weights[axis].get(value, 0)) > 0] for axis, values in axes.items()
    ]
    held_out = [dict(c) for c in appearance.held_out or []]
    for look in itertools.product(*support):
        named = dict(zip(axes, look, strict=True))
        if not any(all(named.get(k) == v for k, v in c.items()) for c in held_out):
            return
    raise ConfigValueError(
        "world.appearance.weights and world.appearance.held_out: every look the weights can draw is held out, so no training "
        "drive could be drawn; give a value outside the held-out looks a weight above 0, or hold out fewer looks"
    )
