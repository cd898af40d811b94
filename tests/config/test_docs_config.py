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
        for key, stated in STATED.findall(page.read_text()):
            found = [key] if key in config else [k for k in config if k.endswith(f".{key}")]
            if len(found) != 1:
                wrong.append(f"{page.name}: `{key}` names {len(found)} config keys")
            elif str(config[found[0]]) != stated and not (isinstance(config[found[0]], float) and float(stated) == config[found[0]]):
                wrong.append(f"{page.name}: `{key}` ({stated}) but {found[0]} is {config[found[0]]}")
    assert not wrong, wrong


def test_every_file_the_docs_and_configs_name_exists():
    """A name leads to the code: every `src/...`, `conf/...`, `tools/...`, `benchmarks/...` or `tests/...`
    path written in the README, docs/, conf/ and the code's docstrings is a file or folder of this
    checkout (history pages excepted: they name what was; extending.md's example network, mynet, too)."""
    named = re.compile(r"(?<![\w/.-])((?:src|conf|tools|benchmarks|tests|docs)/[\w./-]*[\w/])")
    history = {"CHANGELOG.md"}
    pages = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md")), *sorted((ROOT / "conf").rglob("*.yaml")),
             *sorted((ROOT / "src").rglob("*.py")), *sorted((ROOT / "tools").glob("*.py"))]  # fmt: skip

    def found(path: str) -> bool:
        return "<" in path or "*" in path or "mynet" in path or (ROOT / path.rstrip(".")).exists()

    missing = sorted(
        {f"{page.relative_to(ROOT)}: {path}" for page in pages if page.name not in history for path in named.findall(page.read_text())
         if not found(path)}
    )  # fmt: skip
    assert not missing, missing
