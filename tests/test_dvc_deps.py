"""Every stage of dvc.yaml depends on all the code it runs: each module its entry point imports,
directly or not (imports inside functions included), lies under one of the stage's deps. A
missing dep means `dvc repro` keeps a stale output after a code change."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest
import yaml
from helpers import ROOT

PACKAGE = ROOT / "src" / "offroad_path"
STAGES = yaml.safe_load((ROOT / "dvc.yaml").read_text())["stages"]


def module_file(name: str) -> Path | None:
    path = ROOT / "src" / Path(*name.split("."))
    for candidate in (path.with_suffix(".py"), path / "__init__.py"):
        if candidate.is_file():
            return candidate
    return None


def has_code(file: Path) -> bool:
    """False for a module that holds only its docstring (and `from __future__` imports)."""
    body = ast.parse(file.read_text()).body
    return any(
        not (isinstance(n, ast.Expr) and isinstance(n.value, ast.Constant))
        and not (isinstance(n, ast.ImportFrom) and n.module == "__future__")
        for n in body
    )


def imported_files(entry: str) -> set[Path]:
    """The package's files that running `python -m <entry>` can import."""
    seen: set[Path] = set()
    todo = [entry]
    while todo:
        name = todo.pop()
        # Importing a.b.c runs a/__init__.py and a/b/__init__.py first.
        parts = name.split(".")
        for i in range(1, len(parts) + 1):
            file = module_file(".".join(parts[:i]))
            if file is None or file in seen:
                continue
            seen.add(file)
            for node in ast.walk(ast.parse(file.read_text())):
                if isinstance(node, ast.Import):
                    todo += [a.name for a in node.names if a.name.startswith("offroad_path")]
                elif isinstance(node, ast.ImportFrom) and (node.module or "").startswith("offroad_path"):
                    todo += [node.module] + [f"{node.module}.{a.name}" for a in node.names]
    return seen


@pytest.mark.parametrize("stage", sorted(STAGES))
def test_the_stage_depends_on_every_module_it_imports(stage):
    spec = STAGES[stage]
    entry = spec["cmd"].split()[2]  # python -m offroad_path.<stage> ...
    deps = [ROOT / d for d in spec["deps"] if d.startswith("src/")]
    ran = {f for f in imported_files(entry) if has_code(f)}
    missing = sorted(str(f.relative_to(ROOT)) for f in ran if not any(f == d or d in f.parents for d in deps))
    assert not missing, f"dvc.yaml stage {stage} runs these files but does not list them in its deps: {missing}"
