"""The meta.json keys that several modules write or read, spelt once (the sequence's contract:
docs/design.md, "Data contracts")."""

from __future__ import annotations

from pathlib import Path

SPLIT, HELD_OUT = "split", "test"  # a held-out test world says "split": "test"; other recordings say nothing
# A held-out test world's test set: "main" (drawn from the training drives' distribution, the headline
# figures) or the stress set it was drawn for (offroad_path.world.held_out.STRESS_SETS); absent: main.
TEST_SET, MAIN = "test_set", "main"
DEVELOPMENT = "development"  # held-out worlds settings are chosen on; never scored by evaluate
GENERATOR = "generator"
RENDERED = "offroad_path.world"  # the generator of the synthesize stage's sequences
INGESTED = "offroad_path.ingest"  # the generator of the ingest stage's sequences
# Config key (label.footprint, ingest.footprint) -> meta.json key of the vehicle's footprint.
FOOTPRINT = {
    "width_m": "vehicle_width_m",
    "front_m": "footprint_front_m",
    "rear_m": "footprint_rear_m",
    "camera_height_m": "camera_height_m",
    "camera_pitch_deg": "camera_pitch_deg",
}


def held_out(meta: dict, path: Path | str) -> bool:
    """Whether a recording is a held-out test world: meta.json's "split" is "test" (absent: no);
    any other value is a ValueError naming the file."""
    if meta.get(SPLIT, HELD_OUT) != HELD_OUT:
        raise ValueError(f'{path}: "{SPLIT}" is {meta[SPLIT]!r}; the only value it may take is "{HELD_OUT}" (a held-out test world)')
    return SPLIT in meta


def test_set(meta: dict) -> str:
    """The test set a held-out test world belongs to (main when meta.json does not say)."""
    return str(meta.get(TEST_SET, MAIN))


def rendered(meta: dict) -> bool:
    """Whether the synthesize stage rendered the sequence (its world can be rebuilt from its seed)."""
    return meta.get(GENERATOR) == RENDERED
