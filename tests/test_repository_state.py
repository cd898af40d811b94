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
