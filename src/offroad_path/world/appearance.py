"""What a world looks like, drawn per world: the track's surface, the season, the light, the
vegetation and the camera (domain randomisation, Tobin et al., IROS 2017).

A world's appearance comes from a seed stream of its own (APPEARANCE_STREAM), so the geometry a seed
draws (terrain, drive, track, objects) is the same with or without it. Some combinations are held
out (`world.appearance.held_out`): no training drive shows them, and every other test world is drawn
from them, so that the report can say what a network loses on a look it never saw.

Holder & Breckon name shadow across the path, water and forks as their failure cases; the looks
here add the ones real tracks have and the old world did not: a track of the surroundings' own
colour (worn ruts only), open ground with no track at all, dappled shade, overcast and low sun,
greyscale and noisy cameras.

The training drives draw each axis with `world.appearance.weights` (a value of weight 0 is never
drawn: the laptop default leaves out the looks its networks cannot learn in its budget); a world
drawn with `full_variety` draws every value alike, so the stress set of looks outside the training
distribution can be drawn beside it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from offroad_path.looks import AXIS_VALUES, axis_values
from offroad_path.world.classes import BASE_COLORS, DIRT, FOLIAGE, GRASS, TREE

APPEARANCE_STREAM = 2  # spawn key: held-out worlds use others (world.held_out's *_STREAM)

# Track surfaces: the DIRT class's albedo and texture contrast, and its ruts' colour and strength
# (None: the surroundings' own ground cover, so the track is its wear or nothing).
TRACKS: dict[str, dict] = {
    "dirt": {"albedo": (0.50, 0.38, 0.26), "contrast": 0.45, "ruts": None},
    "gravel": {"albedo": (0.46, 0.44, 0.41), "contrast": 0.85, "ruts": None},
    "mud": {"albedo": (0.23, 0.17, 0.11), "contrast": 0.3, "ruts": ((0.15, 0.11, 0.07), 0.6)},
    "ruts": {"albedo": None, "contrast": None, "ruts": ((0.45, 0.34, 0.23), 0.95)},  # two dirt ruts in grass
    "grass_track": {"albedo": None, "contrast": 0.3, "ruts": ("grass", 0.45)},  # flattened, darker grass only
    "none": {"albedo": None, "contrast": None, "ruts": None},  # open ground: the path is where the driver went
}
# Ground cover, bushes and tree crowns per season (linear RGB).
SEASONS: dict[str, dict[int, tuple[float, float, float]]] = {
    "summer": {GRASS: BASE_COLORS[GRASS], FOLIAGE: BASE_COLORS[FOLIAGE], TREE: BASE_COLORS[TREE]},
    "spring": {GRASS: (0.22, 0.50, 0.12), FOLIAGE: (0.18, 0.40, 0.10), TREE: (0.14, 0.34, 0.08)},
    "dry": {GRASS: (0.48, 0.42, 0.22), FOLIAGE: (0.26, 0.30, 0.12), TREE: (0.15, 0.22, 0.08)},
    "autumn": {GRASS: (0.32, 0.32, 0.13), FOLIAGE: (0.42, 0.22, 0.07), TREE: (0.46, 0.23, 0.06)},
}
# Light: (sun elevation range in degrees, sun strength, sky light, sun colour, fog distance range in m, cloud cover range).
LIGHTS: dict[str, tuple] = {
    "clear": ((25.0, 70.0), 0.9, 0.35, (1.0, 1.0, 1.0), (200.0, 300.0), (0.1, 0.5)),
    "low_sun": ((6.0, 16.0), 1.0, 0.3, (1.0, 0.78, 0.55), (150.0, 250.0), (0.1, 0.4)),
    "hazy": ((20.0, 60.0), 0.55, 0.5, (1.0, 0.95, 0.88), (55.0, 110.0), (0.3, 0.6)),
    "overcast": ((30.0, 60.0), 0.0, 0.85, (1.0, 1.0, 1.0), (110.0, 200.0), (0.97, 1.0)),
}
VEGETATION = AXIS_VALUES["vegetation"]
AXES = tuple(AXIS_VALUES)
DRAWS = ("training", "full_variety", "held_out")  # how a world's look is drawn (draw_appearance's `draw`)


@dataclass(frozen=True)
class Sensor:
    """The camera's response: what turns linear light into the recorded bytes (world.sensor)."""

    greyscale: bool
    exposure: float  # a fixed gain on linear light, times the auto-gain when auto_gain
    auto_gain: bool  # scale each frame's mean luminance to `target`
    target: float
    white_balance: tuple[float, float, float]  # per-channel gains, green 1
    noise_dn: float  # standard deviation of the sensor noise, in 8-bit steps
    vignetting: float  # brightness lost at the image's corners
    shutter_s: float  # exposure time: the blur of the vehicle's own motion
    jpeg_quality: int  # 0: none


@dataclass(frozen=True)
class Appearance:
    track: str
    season: str
    light: str
    vegetation: str
    tree_lined: bool  # trees along the track: dappled shade across it
    wet: bool  # more puddles
    held_out: bool  # a combination `world.appearance.held_out` keeps out of training
    sensor: Sensor
    outside: bool = False  # a value of weight 0 in `world.appearance.weights`: no training drive shows it
    full_variety: bool = False  # drawn with every value alike (a stress world), not with the weights

    def tags(self) -> dict[str, str]:
        """The world's look, as conditions.csv records it on every frame: seen, held_out or outside."""
        return {"track": self.track, "light": self.light, "look": "held_out" if self.held_out else "outside" if self.outside else "seen"}


def _matches(look: dict[str, str], combination: dict[str, str]) -> bool:
    return all(look[k] == v for k, v in combination.items())


def draw_appearance(
    seed: int, held_out: list[dict[str, str]], draw: str = "training", weights: dict[str, dict[str, float]] | None = None
) -> Appearance:
    """The look of the world drawn from `seed`: any combination but the held-out ones, each axis by
    `weights` (draw "training"; None or an axis it omits: every value alike) or with every value
    alike (draw "full_variety"), or (draw "held_out") one of the held-out combinations, its other
    axes drawn by the weights."""
    if draw not in DRAWS:
        raise ValueError(f"unknown look draw {draw!r}; valid: {', '.join(DRAWS)}")
    rng = np.random.default_rng(np.random.SeedSequence([seed], spawn_key=(APPEARANCE_STREAM,)))
    choices = axis_values()
    chances = {axis: None if draw == "full_variety" else axis_chances(weights, axis) for axis in AXES}
    fixed = dict(held_out[int(rng.integers(len(held_out)))]) if draw == "held_out" and held_out else {}
    for _ in range(1000):
        look = {axis: fixed.get(axis) or str(rng.choice(choices[axis], p=chances[axis])) for axis in AXES}
        if fixed or not any(_matches(look, c) for c in held_out):
            break
    else:  # never a held-out look in a world drawn as training is: the config check refuses what cannot be drawn
        raise ValueError(f"world.appearance.weights and world.appearance.held_out: 1000 draws for seed {seed} all fell on held-out looks")
    sensor = Sensor(
        greyscale=bool(rng.uniform() < 0.25),
        exposure=float(rng.uniform(0.7, 1.4)),
        auto_gain=bool(rng.uniform() < 0.7),
        target=float(rng.uniform(0.12, 0.24)),
        white_balance=(float(rng.uniform(0.85, 1.15)), 1.0, float(rng.uniform(0.85, 1.15))),
        noise_dn=float(rng.uniform(0.0, 2.5)),
        vignetting=float(rng.uniform(0.0, 0.35)),
        shutter_s=float(rng.uniform(0.0, 1 / 60)),
        jpeg_quality=int(rng.integers(55, 96)) if rng.uniform() < 0.5 else 0,
    )
    return Appearance(
        **look,
        tree_lined=bool(rng.uniform() < 0.35),
        wet=look["track"] == "mud" or bool(rng.uniform() < 0.2),
        held_out=bool(fixed),
        sensor=sensor,
        outside=any(look[axis] not in training_values(weights, axis) for axis in AXES),
        full_variety=draw == "full_variety",
    )


def axis_chances(weights: dict[str, dict[str, float]] | None, axis: str) -> np.ndarray | None:
    """The probability of each of the axis's values (axis_values order) under `weights`; None: all alike."""
    if not weights or axis not in weights:
        return None
    w = np.array([float(weights[axis].get(value, 0.0)) for value in axis_values()[axis]])
    return w / w.sum()


def training_values(weights: dict[str, dict[str, float]] | None, axis: str) -> list[str]:
    """The axis's values the training drives may show (weight above 0)."""
    values = axis_values()[axis]
    return values if not weights or axis not in weights else [v for v in values if weights[axis].get(v, 0.0) > 0]


def appearance_rng(seed: int) -> np.random.Generator:
    """The generator the dressing draws from (after draw_appearance's own draws: a stream of its own)."""
    return np.random.default_rng(np.random.SeedSequence([seed, 1], spawn_key=(APPEARANCE_STREAM,)))


def palette(look: Appearance, rng: np.random.Generator, base: np.ndarray) -> np.ndarray:
    """The world's albedo per class (8, 3): `base` (the jittered default) recoloured by season and track."""
    out = base.copy()
    for cls, rgb in SEASONS[look.season].items():
        out[cls] = np.clip(np.asarray(rgb) * rng.uniform(0.85, 1.15) * rng.uniform(0.92, 1.08, 3), 0.02, 1.0)
    track = TRACKS[look.track]
    out[DIRT] = out[GRASS] if track["albedo"] is None else np.clip(np.asarray(track["albedo"]) * rng.uniform(0.85, 1.15), 0.02, 1.0)
    return out


def rut_colour(look: Appearance, albedo: np.ndarray) -> tuple[np.ndarray, float] | None:
    """(colour, strength) of the track's ruts, or None where it has none."""
    ruts = TRACKS[look.track]["ruts"]
    if ruts is None:
        return None
    colour, strength = ruts
    return (albedo[GRASS] * 0.7 if colour == "grass" else np.asarray(colour)), strength
