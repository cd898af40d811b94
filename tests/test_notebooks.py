"""The notebooks run top to bottom on the outputs of `dvc repro` (skipped before it has run)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def run_notebook(name: str, needs: list[Path], monkeypatch) -> dict:
    """Execute a notebook's code cells top to bottom from the repository root; its namespace."""
    for path in needs:
        if not path.exists():
            pytest.skip(f"no pipeline outputs ({path.relative_to(ROOT)}): run `dvc repro` first")
    monkeypatch.chdir(ROOT)
    notebook = json.loads((ROOT / "notebooks" / name).read_text())
    namespace: dict = {}
    for cell in notebook["cells"]:
        if cell["cell_type"] == "code":
            exec(compile("".join(cell["source"]), name, "exec"), namespace)
    return namespace


def test_world_and_labels_notebook_runs(monkeypatch):
    namespace = run_notebook("01_world_and_labels.ipynb", [ROOT / "data" / "labels" / "summary.json"], monkeypatch)
    assert namespace["kept"] and namespace["mask"].any()
    assert namespace["panel"].shape == (288, 3 * 512, 3)


def test_results_notebook_runs(monkeypatch):
    namespace = run_notebook("02_results.ipynb", [ROOT / "data" / "evaluation" / "results.csv", ROOT / "mlflow.db"], monkeypatch)
    assert len(namespace["results"]) == 12 and len(namespace["curves"]) == 6
    assert namespace["evaluation"].data.tags.get("stage") == "evaluate"
