"""The package's import graph runs downward only: each module imports from its own layer or below,
and no two packages import each other (the layers are declared here and in docs/design.md)."""

from __future__ import annotations

import ast
from collections import defaultdict
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[2] / "src" / "offroad_path"
STAGES = ["calibrate", "drive", "evaluate", "export", "ingest", "label", "postprocess", "predict", "pretrain", "split",
          "synthesize", "train", "train_steering"]  # fmt: skip
LAYERS = [  # lowest first; a unit is a subpackage or a top-level module of offroad_path
    ["offroad_path", "errors", "utils"],
    ["config", "looks", "stage", "geometry", "statistics", "viz"],
    ["sequence"],
    ["recordings", "world", "odometry", "data", "models"],
    ["training"],
    ["steering", "inference", "report"],
    STAGES,  # each imports the libraries above, never another stage
]
LAYER = {unit: k for k, units in enumerate(LAYERS) for unit in units}


def unit(module: str) -> str:
    """offroad_path.evaluate.bootstrap -> evaluation; offroad_path.label -> label; offroad_path -> offroad_path."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else parts[0]


def imports() -> list[tuple[str, str, str]]:
    """(importing unit, imported unit, where) for every import of offroad_path, at any depth of a module."""
    found = []
    for path in sorted(PACKAGE.rglob("*.py")):
        module = ".".join(path.relative_to(PACKAGE.parent).with_suffix("").parts).removesuffix(".__init__")
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.ImportFrom) and node.level == 0 and (node.module or "").startswith("offroad_path"):
                targets = [f"{node.module}.{a.name}" for a in node.names] if node.module == "offroad_path" else [node.module]
            elif isinstance(node, ast.Import):
                targets = [a.name for a in node.names if a.name.startswith("offroad_path")]
            else:
                continue
            here = f"{path.relative_to(PACKAGE)}:{node.lineno}"
            found += [(unit(module), unit(t) if unit(t) in LAYER else "offroad_path", here) for t in targets]
    return found


def test_every_unit_has_a_layer():
    modules = {p.stem for p in PACKAGE.glob("*.py") if p.stem != "__init__"}
    packages = {p.parent.name for p in PACKAGE.glob("*/*.py")}
    assert (modules | packages) - set(LAYER) == set(), "declare its layer here and in docs/design.md"


def test_no_import_reaches_a_higher_layer():
    upward = [f"{where}: {a} imports {b}" for a, b, where in imports() if a != b and LAYER[b] > LAYER[a]]
    assert upward == []


def test_no_two_packages_import_each_other():
    edges = defaultdict(set)
    for a, b, _ in imports():
        if a != b:
            edges[a].add(b)
    mutual = sorted({tuple(sorted((a, b))) for a in edges for b in edges[a] if a in edges.get(b, set())})
    assert mutual == []


@pytest.mark.parametrize(("source", "upward"), [("from offroad_path.evaluate.sections import x\n", True),
                                                ("from offroad_path.errors import InputError\n", False)])  # fmt: skip
def test_the_check_sees_an_upward_import(tmp_path, monkeypatch, source, upward):
    """The graph is read from the source: a config module importing evaluation is caught."""
    package = tmp_path / "offroad_path"
    package.mkdir()
    (package / "config.py").write_text(source)
    monkeypatch.setattr(f"{__name__}.PACKAGE", package)
    caught = [a for a, b, _ in imports() if LAYER[b] > LAYER[a]]
    assert bool(caught) is upward


def module_imports() -> dict[str, set[str]]:
    """Module -> the offroad_path modules it imports (a name imported from a package counts as the
    package's module when it is no module of its own), at any depth, TYPE_CHECKING blocks included."""
    graph: dict[str, set[str]] = defaultdict(set)
    modules = {".".join(p.relative_to(PACKAGE.parent).with_suffix("").parts).removesuffix(".__init__") for p in PACKAGE.rglob("*.py")}
    for path in sorted(PACKAGE.rglob("*.py")):
        module = ".".join(path.relative_to(PACKAGE.parent).with_suffix("").parts).removesuffix(".__init__")
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.ImportFrom) and node.level == 0 and (node.module or "").startswith("offroad_path"):
                names = [f"{node.module}.{a.name}" for a in node.names]
                graph[module] |= {n for n in names if n in modules} or {node.module}
            elif isinstance(node, ast.Import):
                graph[module] |= {a.name for a in node.names if a.name in modules}
    return graph


def test_no_import_circle_between_modules():
    """No module reaches itself through imports (a circle of two, training/run and training/published,
    once hid behind TYPE_CHECKING)."""
    graph = module_imports()
    circles = []
    for start in sorted(graph):
        seen, frontier = set(), [start]
        while frontier:
            for nxt in graph.get(frontier.pop(), ()):
                if nxt == start:
                    circles.append(start)
                elif nxt not in seen:
                    seen.add(nxt)
                    frontier.append(nxt)
    assert sorted(set(circles)) == []


def test_no_two_modules_share_a_name():
    """A module's name finds it: no two modules or packages of offroad_path are named alike
    (a package's __init__ and __main__ aside)."""
    names = defaultdict(list)
    for path in PACKAGE.rglob("*.py"):
        if path.stem not in ("__init__", "__main__"):
            names[path.stem].append(str(path.relative_to(PACKAGE)))
    for folder in (p.parent for p in PACKAGE.rglob("__init__.py") if p.parent != PACKAGE):
        names[folder.name].append(f"{folder.relative_to(PACKAGE)}/")
    assert {name: where for name, where in names.items() if len(where) > 1} == {}


def test_no_stage_imports_another():
    """A stage's package imports libraries only: code two stages share lives in a library below them."""
    across = [f"{where}: {a} imports {b}" for a, b, where in imports() if a != b and a in STAGES and b in STAGES]
    assert across == []


def test_every_stage_is_a_package_named_as_its_command():
    """`python -m offroad_path.<stage>` runs the package of that name: its function in __init__.py, a short
    __main__.py, and no top-level module but the shared ones (errors, looks, stage)."""
    from offroad_path.stage import stage_modules

    assert sorted(STAGES) == sorted([*stage_modules(), "calibrate"])  # calibrate: a command of its own, no Hydra stage
    for stage in STAGES:
        assert (PACKAGE / stage / "__init__.py").is_file() and (PACKAGE / stage / "__main__.py").is_file(), stage
        assert len((PACKAGE / stage / "__main__.py").read_text().splitlines()) <= 5, f"{stage}/__main__.py: only the call of main"
    top = sorted(p.stem for p in PACKAGE.glob("*.py"))
    assert top == ["__init__", "errors", "looks", "stage"]


def test_every_package_has_its_tests_folder():
    """The tests mirror the packages: tests/<package>/ holds a test file for each package of offroad_path,
    so that a unit's tests are found where its code is (the shared top-level modules' in tests/stage/)."""
    tests = PACKAGE.parents[1] / "tests"
    packages = sorted(p.parent.name for p in PACKAGE.glob("*/__init__.py"))
    missing = [name for name in packages if not any((tests / name).glob("test_*.py"))]
    assert missing == [], f"packages without tests/<package>/test_*.py: {', '.join(missing)}"
