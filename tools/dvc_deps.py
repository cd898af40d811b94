"""The code deps of each dvc.yaml stage, from the imports of its entry point, written into dvc.yaml:

    python tools/dvc_deps.py          # rewrite each stage's src/ deps in dvc.yaml
    python tools/dvc_deps.py --check  # exit 1 when dvc.yaml differs (tests/repository/test_dvc_deps.py)

A stage depends on every module its `python -m offroad_path.<stage>` can import, directly or not,
imports inside functions included: a missing dep would let `dvc repro` keep a stale output after a
code change, an extra one rerun a stage for nothing. A package folder is listed whole when the
stage imports more than half of its modules (an edit to one of the others then reruns the stage for
nothing, which keeps dvc.yaml short), else module by module. Only the `src/` lines of each stage's
deps are rewritten; data deps, params, comments and order stay as written.
"""

from __future__ import annotations

import argparse
import ast
import functools
import re
import sys
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
SRC = ROOT / "src"
PACKAGE = "offroad_path"


def module_file(name: str) -> Path | None:
    path = SRC / Path(*name.split("."))
    for candidate in (path.with_suffix(".py"), path / "__init__.py"):
        if candidate.is_file():
            return candidate
    return None


@functools.cache
def has_code(file: Path) -> bool:
    """False for a module that holds only its docstring (and `from __future__` imports)."""
    return any(
        not (isinstance(n, ast.Expr) and isinstance(n.value, ast.Constant))
        and not (isinstance(n, ast.ImportFrom) and n.module == "__future__")
        for n in ast.parse(file.read_text()).body
    )


def imported_files(entry: str) -> set[Path]:
    """The package's files that running `python -m <entry>` can import."""
    seen: set[Path] = set()
    todo = [entry, f"{entry}.__main__"]  # a stage package's command runs its __main__.py
    while todo:
        parts = todo.pop().split(".")
        for i in range(1, len(parts) + 1):  # importing a.b.c runs a/__init__.py and a/b/__init__.py first
            file = module_file(".".join(parts[:i]))
            if file is None or file in seen:
                continue
            seen.add(file)
            todo += imports_of(file)
    return seen


@functools.cache
def imports_of(file: Path) -> list[str]:
    """The package's modules (and names that may be modules) `file` imports, anywhere in it."""
    found: list[str] = []
    for node in ast.walk(ast.parse(file.read_text())):
        if isinstance(node, ast.Import):
            found += [a.name for a in node.names if a.name.startswith(PACKAGE)]
        elif isinstance(node, ast.ImportFrom) and (node.module or "").startswith(PACKAGE):
            found += [node.module, *(f"{node.module}.{a.name}" for a in node.names)]
    return found


def code_deps(entry: str) -> list[str]:
    """The stage's code deps, relative to the repository: the stage's package first, then folders and
    files in path order; a folder of which the stage imports more than half the modules with code
    stands for them."""
    used = {f for f in imported_files(entry) if has_code(f)}
    entry_file = module_file(entry)
    # A stage package (its function in __init__.py) is listed whole: all of it is the stage's own code.
    entry_dep = entry_file.parent if entry_file.name == "__init__.py" else entry_file
    deps: set[Path] = {entry_dep}
    for file in used:
        folder = file.parent
        package_files = {f for f in folder.rglob("*.py") if has_code(f)}
        whole = folder != SRC / PACKAGE and 2 * len(package_files & used) > len(package_files)
        deps.add(folder if whole else file)
    # A folder listed whole stands for the files and subfolders under it.
    deps = {d for d in deps if not any(p in deps for p in d.parents)}
    rel = sorted(str(d.relative_to(ROOT)) for d in deps if d != entry_dep)
    return [str(entry_dep.relative_to(ROOT)), *rel]


def rewrite(text: str) -> str:
    """dvc.yaml's text with every stage's src/ deps replaced by code_deps of its command."""
    stages = yaml.safe_load(text)["stages"]
    lines = text.splitlines(keepends=True)
    out: list[str] = []
    stage: str | None = None
    for line in lines:
        if match := re.match(r"^  ([A-Za-z_][\w-]*):\s*$", line):
            stage = match.group(1) if match.group(1) in stages else None
        if stage is not None and re.match(r"^      - src/", line):
            if out and out[-1].startswith("      - src/"):
                continue  # the stage's src/ lines are written once, at the first of them
            entry = stages[stage]["cmd"].split()[2]  # python -m offroad_path.<stage> ...
            out += [f"      - {dep}\n" for dep in code_deps(entry)]
            continue
        out.append(line)
    return "".join(out)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="dvc.yaml's code deps from each stage's imports")
    parser.add_argument("--check", action="store_true", help="exit 1 when dvc.yaml differs, without writing")
    parser.add_argument("--dvc-yaml", type=Path, default=ROOT / "dvc.yaml")
    a = parser.parse_args(argv)
    text = a.dvc_yaml.read_text()
    generated = rewrite(text)
    if generated == text:
        return 0
    if a.check:
        print(f"{a.dvc_yaml}: its code deps differ from the stages' imports; run python tools/dvc_deps.py", file=sys.stderr)
        return 1
    a.dvc_yaml.write_text(generated)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
