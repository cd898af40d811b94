"""The repository states one run: every dvc.lock entry is a stage of dvc.yaml and every file
under metrics/ is an output of one (tools/prune_lock.py makes it so)."""

from __future__ import annotations

import importlib.util

from helpers import ROOT


def test_the_lock_and_metrics_hold_exactly_the_committed_run():
    spec = importlib.util.spec_from_file_location("prune_lock", ROOT / "tools" / "prune_lock.py")
    prune_lock = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(prune_lock)
    entries, files = prune_lock.orphans(ROOT)
    assert not entries, f"dvc.lock entries of no stage of dvc.yaml (run tools/prune_lock.py): {entries}"
    assert not files, f"files under metrics/ that no stage writes (run tools/prune_lock.py): {files}"


def test_no_benchmark_imports_the_tests_or_another_benchmark():
    """Benchmarks share code through benchmarks/common.py (and the raw rig, benchmarks/raw_rig.py), never
    by reaching into tests/ or into each other; development tools live outside the installed package."""
    import ast

    shared = {"common", "raw_rig"}
    benchmarks = {p.stem for p in (ROOT / "benchmarks").glob("*.py")} - shared
    for path in sorted((ROOT / "benchmarks").glob("*.py")):
        text = path.read_text()
        assert "tests" not in {part for line in text.splitlines() if "sys.path" in line for part in line.replace('"', " ").split()}
        for node in ast.walk(ast.parse(text)):
            names = (
                [a.name for a in node.names]
                if isinstance(node, ast.Import)
                else [node.module or ""]
                if isinstance(node, ast.ImportFrom)
                else []
            )
            assert not {n.split(".")[0] for n in names} & (benchmarks | {"helpers", "conftest"}), f"{path.name} imports {names}"
    package = ROOT / "src" / "offroad_path"
    assert not [p for p in ("utils/dvc_deps.py", "utils/scaled_pipeline.py", "statistics/noninferiority.py") if (package / p).exists()]
