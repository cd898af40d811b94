"""The report's condition groups over conditions.csv rows (offroad_path.world.conditions), in a
module of their own so that the evaluation reads them without importing the renderer."""

from __future__ import annotations

from collections.abc import Callable

SINGLE_LOOK = {"track": "dirt", "light": "clear", "look": "seen", "canopy": "open"}  # a world rendered without world.appearance
SHADOW_FRACTION = 0.1  # of the corridor, for "shadow on the path"
# The report's condition groups, (key, title, test on one frame's row): a frame may be in several.
GROUPS: list[tuple[str, str, Callable[[dict], bool]]] = [
    ("all", "all test frames", lambda r: True),
    ("shadow", f"shadow on the path (>= {SHADOW_FRACTION:.0%} of it)", lambda r: r["shadow"] >= SHADOW_FRACTION),
    ("no_shadow", "no shadow on the path", lambda r: r["shadow"] < SHADOW_FRACTION),
    ("water", "water on or near the path", lambda r: r["water"]),
    ("fork", "a fork in view", lambda r: r["fork"]),
    ("off_track", "off the track (mostly grass)", lambda r: r["surface"] == "grass"),
    ("paved", "paved road", lambda r: r["surface"] == "paved"),
    ("dirt", "dirt track", lambda r: r["surface"] == "dirt"),
    ("sharp_bend", "bend radius below 20 m", lambda r: r["bend_radius_m"] < 20),
    ("bend", "bend radius 20 to 30 m", lambda r: 20 <= r["bend_radius_m"] < 30),
    ("gentle", "bend radius 30 m or more", lambda r: r["bend_radius_m"] >= 30),
    # The looks of world.appearance: the paper's poor case (shadow and water together), and the tracks
    # real driving has that a colour tells nothing about.
    ("shadow_water", "shadow and water on the path", lambda r: r["shadow"] >= SHADOW_FRACTION and r["water"]),
    ("dappled", "dappled shade under trees along the track", lambda r: r["shadow"] >= SHADOW_FRACTION and r["canopy"] == "tree_lined"),
    ("grass_track", "a track of the grass's own colour (worn only)", lambda r: r["track"] == "grass_track"),
    ("no_track", "open ground, no visible track", lambda r: r["track"] == "none"),
    ("seen_look", "a look the training drives show", lambda r: r["look"] == "seen"),
    ("held_out_look", "a look no training drive shows (world.appearance.held_out)", lambda r: r["look"] == "held_out"),
    ("outside_look", "a track or light the training drives never show (world.appearance.weights 0)", lambda r: r["look"] == "outside"),
]
GROUP_KEYS = [key for key, _, _ in GROUPS]
