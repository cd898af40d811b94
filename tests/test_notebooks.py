"""The notebooks run top to bottom on the outputs of `dvc repro` (skipped before it has run)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def test_world_and_labels_notebook_runs(monkeypatch):
    if not (ROOT / "data" / "labels" / "summary.json").is_file():
        pytest.skip("no pipeline outputs: run `dvc repro` first")
    monkeypatch.chdir(ROOT)
    notebook = json.loads((ROOT / "notebooks" / "01_world_and_labels.ipynb").read_text())
    namespace: dict = {}
    for cell in notebook["cells"]:
        if cell["cell_type"] == "code":
            exec(compile("".join(cell["source"]), "notebook", "exec"), namespace)
    assert namespace["kept"] and namespace["mask"].any()
    assert namespace["panel"].shape == (288, 3 * 512, 3)
