"""The world's look axes and the names of their values: what `world.appearance.held_out` and
`world.appearance.weights` may name. The settings' rules check names against these (offroad_path/config/); the
renderer gives each name its colours (offroad_path.world.appearance, whose tables list exactly these,
in this order: a world's look is drawn by position). Kept apart from the renderer's tables so that a
stage that only validates its settings does not depend on them."""

from __future__ import annotations

AXIS_VALUES: dict[str, tuple[str, ...]] = {
    "track": ("dirt", "gravel", "mud", "ruts", "grass_track", "none"),
    "season": ("summer", "spring", "dry", "autumn"),
    "light": ("clear", "low_sun", "hazy", "overcast"),
    "vegetation": ("broadleaf", "conifer", "mixed", "scrub"),
}


def axis_values() -> dict[str, list[str]]:
    """Every value each axis may name, in drawing order."""
    return {axis: list(values) for axis, values in AXIS_VALUES.items()}
