"""Every optional extra a command names when its library is missing, or the README tells users to
install, is declared in pyproject.toml, and the test extra installs all of them (CI's fresh
install once lacked three the code and README named)."""

from __future__ import annotations

import ast
import re
import tomllib

from helpers import ROOT

EXTRAS = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"]


def named_by_the_code() -> set[str]:
    """The `extra` argument of every missing_extra(command, extra, module) call in the package."""
    named = set()
    for file in (ROOT / "src" / "offroad_path").rglob("*.py"):
        for node in ast.walk(ast.parse(file.read_text())):
            if isinstance(node, ast.Call) and getattr(node.func, "id", None) == "missing_extra":
                extra = node.args[1]
                assert isinstance(extra, ast.Constant), f"{file}:{node.lineno}: name the extra literally"
                named.add(extra.value)
    return named


def test_every_extra_the_code_or_readme_names_is_declared_and_tested():
    readme = set(re.findall(r"\.\[([a-z]+)\]", (ROOT / "README.md").read_text()))
    named = named_by_the_code()
    assert named >= {"ros", "onnx", "search", "inspect"}  # the parser still finds the calls
    assert named | readme <= set(EXTRAS)
    (tested,) = [d for d in EXTRAS["test"] if d.startswith("offroad-path[")]
    assert set(tested.removeprefix("offroad-path[").removesuffix("]").split(",")) == set(EXTRAS) - {"test"}
