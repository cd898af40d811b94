"""Each world's look drawn from a stream of its own, and the sensor between light and bytes."""

from __future__ import annotations

import numpy as np
import pytest

from offroad_path.world.appearance import TRACKS, Sensor, draw_appearance
from offroad_path.world.classes import DIRT, GRASS
from offroad_path.world.conditions import frame_conditions
from offroad_path.world.groups import GROUPS
from offroad_path.world.held_out import STRESS_DRAWS
from offroad_path.world.record import camera_for
from offroad_path.world.render import render_view
from offroad_path.world.scene import build_world
from offroad_path.world.sensor import expose, jpeg_like, record

SMALL = ("world.width=64", "world.height=36", "world.frames=20", "world.max_distance_m=40")
HELD_OUT = [{"track": "ruts", "season": "autumn"}, {"track": "gravel", "light": "low_sun"}]


def plain_sensor(**changes) -> Sensor:
    base = dict(greyscale=False, exposure=1.0, auto_gain=False, target=0.18, white_balance=(1.0, 1.0, 1.0), noise_dn=0.0)
    return Sensor(**(base | dict(vignetting=0.0, shutter_s=0.0, jpeg_quality=0) | changes))


def test_no_training_world_shows_a_held_out_look_and_every_held_out_world_shows_one():
    seen = [draw_appearance(seed, HELD_OUT) for seed in range(300)]
    held = [draw_appearance(seed, HELD_OUT, "held_out") for seed in range(60)]

    def matches(look) -> bool:
        return any(all(getattr(look, k) == v for k, v in c.items()) for c in HELD_OUT)

    assert not any(matches(look) for look in seen)
    assert all(matches(look) and look.held_out for look in held)
    assert {look.track for look in seen} == set(TRACKS)  # every surface occurs (ruts with other seasons)
    assert {look.sensor.greyscale for look in seen} == {True, False}


def test_the_training_weights_leave_out_the_values_of_weight_zero_and_full_variety_draws_them():
    weights = {"track": {"dirt": 1.0, "gravel": 3.0, "none": 0.0}, "light": {"clear": 1.0, "hazy": 0.0}}
    training = [draw_appearance(seed, HELD_OUT, "training", weights) for seed in range(400)]
    assert {look.track for look in training} == {"dirt", "gravel"} and {look.light for look in training} == {"clear"}
    gravel = sum(look.track == "gravel" for look in training) / len(training)
    assert 0.68 < gravel < 0.82  # 3 to 1, within sampling error (sd 0.02)
    assert not any(look.outside or look.full_variety for look in training)
    assert {look.season for look in training} == {"summer", "spring", "dry", "autumn"}  # an axis not listed: every value
    every = [draw_appearance(seed, HELD_OUT, "full_variety", weights) for seed in range(200)]
    assert {look.track for look in every} == set(TRACKS) and all(look.full_variety for look in every)
    outside = [look for look in every if look.outside]
    assert outside and all(look.track not in ("dirt", "gravel") or look.light != "clear" for look in outside)
    assert {look.tags()["look"] for look in every} == {"seen", "outside"}
    # held-out looks draw their free axes by the weights
    held = [draw_appearance(seed, HELD_OUT, "held_out", {"season": {"spring": 1.0}, "light": {"overcast": 1.0}}) for seed in range(30)]
    assert {look.season for look in held} <= {"spring", "autumn"} and {look.light for look in held} <= {"overcast", "low_sun"}
    with pytest.raises(ValueError, match="unknown look draw 'odd'; valid: training, full_variety, held_out"):
        draw_appearance(0, HELD_OUT, "odd")


@pytest.mark.slow(seconds=7)
def test_a_look_changes_the_appearance_not_the_drive(compose_config):
    plain = build_world(compose_config(*SMALL, "world.appearance.enabled=false").world, 5)
    dressed = build_world(compose_config(*SMALL).world, 5)
    assert plain.look is None and dressed.look is not None
    np.testing.assert_array_equal(plain.drive.xz, dressed.drive.xz)
    np.testing.assert_array_equal(plain.frame_s, dressed.frame_s)
    np.testing.assert_array_equal(plain.materials, dressed.materials)
    assert len(dressed.objects.kind) > len(plain.objects.kind)  # crowns of several lumps, grass, logs


@pytest.mark.parametrize("track", ["grass_track", "none", "ruts"])
def test_a_track_of_the_grass_colour_differs_from_it_only_by_wear(compose_config, track):
    cfg = compose_config(*SMALL).world
    seed = next(s for s in range(500) if draw_appearance(s, [dict(c) for c in cfg.appearance.held_out], "full_variety").track == track)
    world = build_world(cfg, seed, "full_variety")
    np.testing.assert_array_equal(world.palette[DIRT], world.palette[GRASS])
    assert (world.wear is None) == (track == "none")
    if world.wear is not None:  # ruts only on the track's cells
        assert world.wear.any() and not world.wear[world.materials != DIRT].any()


@pytest.mark.slow(seconds=6)
def test_conditions_name_each_world_look_and_the_stress_sets_draw_theirs(compose_config):
    cfg = compose_config(*SMALL).world
    world = build_world(cfg, 3, "held_out")
    rows = frame_conditions(world, cfg)
    assert {r["look"] for r in rows} == {"held_out"} and {r["track"] for r in rows} == {world.look.track}
    outside = next(s for s in range(100) if build_world(cfg, s, "full_variety").look.outside)
    assert {r["look"] for r in frame_conditions(build_world(cfg, outside, "full_variety"), cfg)} == {"outside"}
    assert STRESS_DRAWS == {"held_out_look": "held_out", "outside_look": "full_variety"}
    keys = {key for key, _, _ in GROUPS}
    assert keys >= {"shadow_water", "dappled", "grass_track", "no_track", "seen_look", "held_out_look", "outside_look"}


def test_auto_gain_brings_the_mean_luminance_to_the_target_and_sky_does_not_blur():
    rng = np.random.default_rng(0)
    linear = rng.uniform(0.05, 0.15, (16, 24, 3))
    out = expose(linear, np.zeros((16, 24)), plain_sensor(auto_gain=True, target=0.2), motion_m=1.0)
    luma = out @ np.array([0.2126, 0.7152, 0.0722])
    assert luma.mean() == pytest.approx(0.2, rel=1e-3)
    np.testing.assert_allclose(out / linear, out[0, 0, 0] / linear[0, 0, 0])  # one gain; depth 0 (sky): no blur


def test_motion_blur_smears_near_ground_more_than_far():
    linear = np.zeros((40, 40, 3))
    linear[:, ::2] = 1.0  # vertical stripes
    depth = np.full((40, 40), 50.0)
    depth[:, :20] = 2.0  # left half near
    out = expose(linear, depth, plain_sensor(), motion_m=0.5)
    near, far = out[10:30, 2:12, 0], out[10:30, 28:38, 0]
    assert near.std() < 0.5 * far.std()


def test_the_sensor_records_noise_of_its_strength_grey_where_greyscale_and_the_same_bytes_for_the_same_key():
    flat = np.full((64, 64, 3), 128.0)
    noisy = record(flat, plain_sensor(noise_dn=4.0), (1, 2)).astype(float)
    assert noisy.std() == pytest.approx(4.0, rel=0.1)
    np.testing.assert_array_equal(record(flat, plain_sensor(noise_dn=4.0), (1, 2)), noisy)
    assert not np.array_equal(record(flat, plain_sensor(noise_dn=4.0), (1, 3)), noisy)
    colour = np.random.default_rng(1).uniform(0, 255, (16, 16, 3))
    grey = record(colour, plain_sensor(greyscale=True), (0,))
    assert (grey[..., 0] == grey[..., 1]).all() and (grey[..., 1] == grey[..., 2]).all()


def test_jpeg_like_compression_loses_more_at_lower_quality():
    rng = np.random.default_rng(2)
    image = np.clip(rng.normal(128, 40, (32, 40, 3)), 0, 255)
    errors = [np.abs(jpeg_like(image, q) - image).mean() for q in (100, 75, 30)]
    assert errors[0] < 2.0 and errors[0] < errors[1] < errors[2]
    smooth = np.tile(np.linspace(0, 255, 40), (32, 1))[..., None].repeat(3, axis=2)
    assert np.abs(jpeg_like(smooth, 90) - smooth).max() <= 6  # a smooth ramp survives


def test_a_dressed_world_renders_through_its_sensor(compose_config):
    cfg = compose_config(*SMALL).world
    world = build_world(cfg, 11)
    camera = camera_for(cfg)
    a = render_view(world, camera, world.poses[3], cfg.max_distance_m, motion_m=0.1, noise_key=(11, 3, 0))
    b = render_view(world, camera, world.poses[3], cfg.max_distance_m, motion_m=0.1, noise_key=(11, 3, 0))
    np.testing.assert_array_equal(a.image, b.image)
    assert a.image.shape == (36, 64, 3) and a.image.std() > 5


def test_stress_sets_section_by_hand(tmp_path):
    """Two main worlds and two stress worlds (held-out looks), one frame each, one run with two seeds: the
    section scores only the stress frames, each against the prior, counted by hand."""
    from offroad_path.data.manifest import Sample
    from offroad_path.evaluate.scored_set import TestSet
    from offroad_path.evaluate.stress import StressSets
    from offroad_path.evaluate.uncertainty import HierarchicalBootstrap
    from offroad_path.statistics.bootstrap import Resampling
    from offroad_path.world.conditions import COLUMNS

    samples = []
    for name, look in (("a", "seen"), ("b", "seen"), ("c", "held_out"), ("d", "held_out")):
        (tmp_path / name / "image_l").mkdir(parents=True)
        row = {"frame": 0, "shadow": 0.0, "water": False, "fork": False, "surface": "dirt", "bend_radius_m": 50.0}
        row |= {"track": "dirt", "light": "clear", "look": look, "canopy": "open"}
        (tmp_path / name / "conditions.csv").write_text(",".join(COLUMNS) + "\n" + ",".join(str(row[c]) for c in COLUMNS) + "\n")
        samples.append(Sample(name, 0, False, str(tmp_path / name / "image_l" / "000000.png"), "", "", "", 1.0, 0.1))
    # [tp, fp, tn, fn] per frame and seed: the stress frames (c, d) tp 6, fp 9, fn 5: IoU 6 / 20.
    seed0 = np.array([[4, 1, 10, 1], [3, 1, 10, 1], [1, 2, 10, 2], [2, 2, 10, 1]], float)
    seed1 = np.array([[4, 1, 10, 0], [3, 0, 10, 1], [1, 3, 10, 0], [2, 2, 10, 2]], float)
    labels = np.zeros((4, 2, 2), bool)
    sets = np.array(["main", "main", "held_out_look", "held_out_look"], dtype=object)
    test = TestSet(["unet-none"], [0, 1], samples, labels, {}, {}, {("unet-none", "no"): [seed0, seed1]}, {}, {}, {}, labels[0], 0.5,
                   sets=sets)  # fmt: skip
    test.__dict__["prior_counts"] = np.array([[1, 1, 10, 1]] * 4, float)  # the cached property, by hand: IoU 1/3
    section = StressSets(lambda part: HierarchicalBootstrap([(s.sequence, 0) for s in part], Resampling(500, 0)))
    section.score(test)
    row = section.metrics()["stress_sets"]["held_out_look"]
    assert (row["worlds"], row["frames"]) == (2, 2) and row["mean_path_prior"] == pytest.approx(1 / 3)
    net = row["unet-none"]
    assert net["iou"] == pytest.approx(6 / 20) and net["minus_prior"] == pytest.approx(6 / 20 - 1 / 3, abs=1e-6)
    assert net["low"] <= net["minus_prior"] <= net["high"]
    # two worlds: an example, its IoU without a margin or interval; from four worlds on, with them
    assert "| a look no training drive shows (world.appearance.held_out) | 2 | 2 | 0.333 | 0.300 |" in section.markdown()
    from offroad_path.report.rendering import stress_markdown
    from offroad_path.statistics.bootstrap import Interval

    margin = Interval(net["minus_prior"], net["low"], net["high"]).difference_text()
    assert f"| 0.333 | 0.300, {margin} |" in stress_markdown({"held_out_look": row | {"worlds": 4}})


def test_the_renderers_tables_give_every_look_name_its_colours_in_drawing_order():
    """offroad_path.looks names the values the settings may use; the renderer's tables hold exactly those."""
    from offroad_path.looks import AXIS_VALUES
    from offroad_path.world.appearance import LIGHTS, SEASONS, TRACKS, VEGETATION

    assert (tuple(TRACKS), tuple(SEASONS), tuple(LIGHTS), tuple(VEGETATION)) == tuple(AXIS_VALUES.values())


@pytest.mark.parametrize(
    "overrides",
    [
        ["world.appearance.weights.track={dirt:0,gravel:0,mud:0,ruts:1}", "+world.appearance.weights.season={autumn:1}"],
        ["world.appearance.held_out=[{track:dirt},{track:gravel},{track:mud}]"],
    ],
)
def test_weights_that_can_draw_only_held_out_looks_are_refused_naming_both_keys(overrides):
    from offroad_path.config import load_config, validate_config
    from offroad_path.utils.rules import ConfigValueError

    with pytest.raises(ConfigValueError, match=r"world\.appearance\.weights and world\.appearance\.held_out: every look"):
        validate_config(load_config(*overrides))


def test_no_training_drive_or_main_test_world_of_the_default_or_a_preset_shows_a_held_out_look():
    from offroad_path.config import load_config
    from offroad_path.world.appearance import draw_appearance
    from offroad_path.world.held_out import DEVELOPMENT_STREAM, RETIRED_STREAM, held_out_seed
    from offroad_path.world.record import sequence_seed

    for preset in ([], ["experiment=gpu"], ["experiment=full"]):
        cfg = load_config(*preset)
        a, sequences = cfg.world.appearance, cfg.synthesize.sequences
        seeds = [sequence_seed(cfg.synthesize.seed, i) for i in range(sequences)]
        streams = (cfg.synthesize.test_worlds.main_stream, DEVELOPMENT_STREAM, RETIRED_STREAM)
        seeds += [held_out_seed(cfg.synthesize.seed, i, s) for i in range(40) for s in streams]
        for seed in seeds:
            look = draw_appearance(seed, list(a.held_out), "training", a.weights)
            assert not look.held_out and not any(all(getattr(look, k) == v for k, v in c.items()) for c in a.held_out), (preset, seed)
