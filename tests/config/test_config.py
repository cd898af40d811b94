"""One source of values: conf/ holds every value, the schemas in offroad_path/config/ only types and rules."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
from omegaconf import MISSING, OmegaConf

from offroad_path.config import Config, load_config, validate_config
from offroad_path.models import MODELS
from offroad_path.utils.rules import ConfigValueError


def leaf_fields(schema: type, prefix: str = "") -> list[tuple[str, dataclasses.Field]]:
    out = []
    for f in dataclasses.fields(schema):
        if f.default_factory is not dataclasses.MISSING and dataclasses.is_dataclass(f.default_factory):
            out += leaf_fields(f.default_factory, f"{prefix}{f.name}.")
        else:
            out.append((f"{prefix}{f.name}", f))
    return out


# Optional nodes a config file may leave out, whose absence the schema must allow.
OPTIONAL_NODES = {"model.paper"}  # how the paper trained a network (conf/model/paper/): none for a network of yours


def test_the_schemas_hold_no_values():
    valued = [
        key
        for key, f in leaf_fields(Config)
        if (f.default is not MISSING or f.default_factory is not dataclasses.MISSING) and key not in OPTIONAL_NODES
    ]
    assert not valued, f"the schemas give these a value; put it in conf/ instead: {valued}"


@pytest.mark.parametrize(
    "overrides",
    [
        [],
        ["experiment=paper"],
        ["experiment=full"],
        ["trainer=ddp"],
        *([f"model={m}"] for m in MODELS),
        ["pretraining=segmentation"],
        ["pretraining=imagenet"],
    ],
)
def test_conf_gives_every_setting_a_value(compose_config, overrides):
    cfg = compose_config(*overrides)
    assert OmegaConf.missing_keys(cfg) == {"predict.input"}  # the one setting a user must give


def path_settings(cfg, prefix: str = "") -> dict[str, str]:
    """Every `*_dir`, `*_path`, `out`, `checkpoint` and `pilotnets` value of the config, resolved."""
    found = {}
    for key, value in cfg.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            found |= path_settings(value, f"{name}.")
        elif isinstance(value, str) and (key.endswith(("_dir", "_path")) or key in ("out", "checkpoint") or "pilotnets" in name):
            found[name] = value
    return found


def test_the_default_paths_are_the_committed_runs():
    cfg = OmegaConf.to_container(load_config(), resolve=True)
    paths = path_settings(cfg)
    assert (paths["label.out_dir"], paths["label.metrics_path"], paths["evaluate.plots_dir"]) == (
        "data/labels", "metrics/label.json", "metrics/precision_recall",
    )  # fmt: skip
    assert paths["train.out_dir"] == "data/runs/unet-none/seed0"


def test_paths_own_puts_every_path_under_the_users_folder(tmp_path):
    """The README's own-data recipe: with paths=own no stage reads or writes the project's data/ or metrics/."""
    root = tmp_path / "field"
    for overrides in ([], ["pretraining=segmentation"], ["experiment=paper"]):
        cfg = OmegaConf.to_container(load_config("paths=own", f"paths.root={root}", *overrides), resolve=True)
        paths = {k: v for k, v in path_settings(cfg).items() if not k.startswith("model.")}  # model.imagenet_weights: a file of yours
        assert len(paths) > 25
        outside = {k: v for k, v in paths.items() if not Path(v).is_relative_to(root)}
        assert not outside, f"paths=own leaves these outside {root}: {outside}"
    assert cfg["label"]["in_dir"] == str(root / "recordings")
    with pytest.raises(Exception, match=r"paths\.root"):
        OmegaConf.to_container(load_config("paths=own"), resolve=True)  # no folder given


@pytest.mark.parametrize(
    ("override", "says"),
    [
        ("evaluate.seeds=[0,0]", r"evaluate\.seeds=\[0, 0\]: must list at least one value, no value twice"),
        ("evaluate.seeds=[]", r"evaluate\.seeds=\[\]: must list at least one value"),
        ("drive.seeds=[1,1]", r"drive\.seeds=\[1, 1\]: must list at least one value, no value twice"),
        (
            "synthesize.test_worlds.stress_sets=[off_track,off_track]",
            r"stress_sets=\['off_track', 'off_track'\]: must list no value twice.*valid: .*dappled",
        ),
    ],
)
def test_a_list_naming_a_value_twice_or_nothing_is_refused_before_any_work(override, says):
    from offroad_path.config import load_config, validate_config
    from offroad_path.utils.rules import ConfigValueError

    with pytest.raises(ConfigValueError, match=says):
        validate_config(load_config(override))


@pytest.mark.parametrize(
    ("override", "says"),
    [
        ("seed=-1", r"seed=-1: must be a whole number in \[0, 4294967295\]"),
        ("world.paved_fraction=1.5", r"world\.paved_fraction=1\.5: must be a number in \[0, 1\]"),
        ("world.sun_elevation_deg=[70,20]", r"sun_elevation_deg=\[70\.0, 20\.0\]: must be \[low, high\].*with low <= high"),
        ("label.odometry.min_inliers=0", r"label\.odometry\.min_inliers=0: must be a number >= 4"),
        ("label.footprint.width_m=-2", r"label\.footprint\.width_m=-2\.0: must be a number > 0"),
        ("drive.body_band_m=[2,0.5]", r"drive\.body_band_m=\[2\.0, 0\.5\]: must be \[low, high\]"),
    ],
)
def test_a_number_out_of_its_range_is_refused_before_any_work(override, says):
    from offroad_path.config import load_config, validate_config

    with pytest.raises(ConfigValueError, match=says):
        validate_config(load_config(override))


@pytest.mark.parametrize("model", ["segnet", "unet"])
def test_batch_norm_is_refused_before_any_work_for_a_network_whose_normalisation_is_not_a_choice(model):
    from offroad_path.config import load_config, validate_config

    with pytest.raises(ConfigValueError, match=rf"model\.batch_norm=True: {model} has batch norm after every convolution as published"):
        validate_config(load_config(f"model={model}", "model.batch_norm=true"), ("model",))
    validate_config(load_config("model=fcn", "model.batch_norm=true"), ("model",))  # FCN-8s's is a choice


def test_each_choice_list_is_the_one_its_implementation_uses():
    """config/ holds the names a setting may take; the module that implements them imports the list or
    keys a table by exactly those names, so the schema's check and the code cannot drift apart."""
    from offroad_path.config import label_schema as labelling
    from offroad_path.config import training_schema as training
    from offroad_path.config import world_schema as world
    from offroad_path.data import splitting
    from offroad_path.label import frame_selection, labeller
    from offroad_path.odometry.sequence_trajectory import ESTIMATORS
    from offroad_path.steering import balance
    from offroad_path.world.groups import GROUP_KEYS

    assert tuple(ESTIMATORS) == labelling.ODOMETRY_METHODS and tuple(GROUP_KEYS) == world.GROUP_KEYS
    assert labeller.POSE_SOURCES is labelling.POSE_SOURCES and labeller.OCCLUSION_DEPTHS is labelling.OCCLUSION_DEPTHS
    assert frame_selection.STRATEGIES is labelling.FRAME_STRATEGIES and splitting.STRATEGIES is labelling.SPLIT_STRATEGIES
    assert training.UNKNOWN_DEPTH == ("keep", "drop") and balance.BALANCES is training.BALANCES  # filter: "drop" zeroes
    with pytest.raises(ConfigValueError, match=r"label\.odometry\.method=.bundle.: must be one of: frame_to_frame, windowed"):
        validate_config(load_config("label.odometry.method=bundle"))
