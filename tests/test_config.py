"""One source of values: conf/ holds every value, the schemas in config.py only types and rules."""

from __future__ import annotations

import dataclasses

import pytest
from omegaconf import MISSING, OmegaConf

from offroad_path.config import Config
from offroad_path.models import MODELS


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
    assert not valued, f"config.py gives these a value; put it in conf/ instead: {valued}"


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
