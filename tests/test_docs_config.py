"""Docs never restate a config value by hand without a check: every "`key` (value)" in the README
and docs/ names a key of the composed default config (its full dotted path, or a unique last part
of one) and gives its value."""

from __future__ import annotations

import re

from helpers import ROOT
from omegaconf import OmegaConf

from offroad_path.config import load_config

STATED = re.compile(r"`([a-z_][a-z0-9_.]*)` \(([0-9][0-9.]*)\)")


def leaves(node, prefix: str = "") -> dict[str, object]:
    if isinstance(node, dict):
        out: dict[str, object] = {}
        for key, value in node.items():
            out |= leaves(value, f"{prefix}{key}.")
        return out
    return {prefix[:-1]: node}


def test_every_stated_config_value_is_the_composed_configs():
    config = leaves(OmegaConf.to_container(load_config(), resolve=False))
    pages = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
    wrong = []
    for page in pages:
        if page.name == "benchmark-history.md":  # history: what earlier runs used
            continue
        for key, stated in STATED.findall(page.read_text()):
            found = [key] if key in config else [k for k in config if k.endswith(f".{key}")]
            if len(found) != 1:
                wrong.append(f"{page.name}: `{key}` names {len(found)} config keys")
            elif str(config[found[0]]) != stated and not (isinstance(config[found[0]], float) and float(stated) == config[found[0]]):
                wrong.append(f"{page.name}: `{key}` ({stated}) but {found[0]} is {config[found[0]]}")
    assert not wrong, wrong
