"""tools/prune_lock.py on a real git + DVC repository holding this checkout's pipelines, lock and
metrics: it deletes only committed files that no dvc.yaml declares, whatever the lock says, keeps
what git does not track unless asked, and answers a bad lock in one line."""

from __future__ import annotations

import importlib.util
import shutil
import subprocess
import sys

import pytest
import yaml
from helpers import ROOT, git

spec = importlib.util.spec_from_file_location("prune_lock", ROOT / "tools" / "prune_lock.py")
prune_lock = importlib.util.module_from_spec(spec)
spec.loader.exec_module(prune_lock)


@pytest.fixture
def repo(tmp_path):
    pipelines = ("dvc.yaml", "dvc.lock", "gpu/dvc.yaml", "gpu/params.yaml", "tour/dvc.yaml", "tour/params.yaml", "own/dvc.yaml",
                 "own/params.yaml")  # fmt: skip
    for item in ("conf", "metrics", ".dvcignore", *pipelines):
        if (ROOT / item).exists():
            (tmp_path / item).parent.mkdir(parents=True, exist_ok=True)
            (shutil.copytree if (ROOT / item).is_dir() else shutil.copy)(ROOT / item, tmp_path / item)
    git(tmp_path, "init", "-q")
    subprocess.run([sys.executable, "-m", "dvc", "init", "-q"], cwd=tmp_path, check=True)
    git(tmp_path, "add", "metrics")
    return tmp_path


def committed_metrics(repo) -> set[str]:
    return {str(p.relative_to(repo)) for p in (repo / "metrics").rglob("*") if p.is_file()}


def edit_lock(repo, change) -> None:
    lock = yaml.safe_load((repo / "dvc.lock").read_text())
    change(lock["stages"])
    (repo / "dvc.lock").write_text(yaml.safe_dump(lock, sort_keys=False))


@pytest.mark.slow(seconds=4)
def test_a_stage_missing_from_the_lock_keeps_its_declared_outputs(repo):
    before = committed_metrics(repo)
    assert "metrics/evaluation.json" in before and "metrics/label.json" in before
    edit_lock(repo, lambda stages: [stages.pop(name) for name in ("evaluate", "label", "train_steering@0")])
    assert prune_lock.main([], root=repo) == 0
    assert committed_metrics(repo) == before
    edit_lock(repo, lambda stages: stages.clear())  # a reset lock, or a checkout before its first repro
    assert prune_lock.main([], root=repo) == 0
    assert committed_metrics(repo) == before


@pytest.mark.slow(seconds=7)
def test_a_committed_file_no_stage_declares_goes_and_yours_stays_unless_asked(repo, capsys):
    stale = repo / "metrics" / "steering" / "seed7.json"  # a seed the grid no longer trains
    stale.write_text("{}\n")
    git(repo, "add", str(stale))
    notes = repo / "metrics" / "notes.md"
    notes.write_text("my notes\n")
    edit_lock(repo, lambda stages: stages.update({"train_scratch@unet-9": stages["train_scratch@unet-0"]}))
    assert prune_lock.main([], root=repo) == 0
    out = capsys.readouterr().out
    assert "dvc.lock: train_scratch@unet-9" in out and "metrics/notes.md (untracked: kept without --delete-untracked)" in out
    assert not stale.exists() and notes.read_text() == "my notes\n"
    assert "train_scratch@unet-9" not in yaml.safe_load((repo / "dvc.lock").read_text())["stages"]
    assert prune_lock.main(["--delete-untracked"], root=repo) == 0
    assert not notes.exists() and "metrics/evaluation.json" in committed_metrics(repo)


@pytest.mark.parametrize(
    ("lock", "says"),
    [
        (None, "no such file"),
        ("stages: [unclosed\n", "not valid YAML"),
        ("", "has no mapping 'stages'"),
        ("schema: '2.0'\n", "has no mapping 'stages'"),
        ("schema: '2.0'\nstages:\n  label: 3\n", "stage 'label' is not a mapping"),
        (
            "schema: '2.0'\nstages:\n  label:\n    cmd: python -m offroad_path.label\n    outs: null\n",
            "stage 'label' is not a mapping with a list of outs",
        ),
    ],
    ids=["missing", "broken YAML", "empty", "without stages", "an entry no mapping", "outs null"],
)
def test_a_missing_or_malformed_lock_is_one_line_naming_it(repo, capsys, lock, says):
    before = committed_metrics(repo)
    if lock is None:
        (repo / "dvc.lock").unlink()
    else:
        (repo / "dvc.lock").write_text(lock)
    assert prune_lock.main([], root=repo) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"error: {repo / 'dvc.lock'}: ") and says in err and len(err.splitlines()) == 1
    assert committed_metrics(repo) == before


def _cut(repo, name: str, size: int) -> None:
    path = repo / name
    path.write_bytes(path.read_bytes()[:size])


@pytest.mark.slow(seconds=10)
@pytest.mark.parametrize(
    ("breakage", "file", "says"),
    [
        (lambda repo: (repo / "dvc.yaml").write_text(""), "dvc.yaml", "empty"),
        (lambda repo: (repo / "dvc.yaml").unlink(), "dvc.yaml", "no such file"),
        (lambda repo: _cut(repo, "dvc.yaml", 1500), "dvc.yaml", "a cut or broken dvc.yaml?"),
        (
            lambda repo: (repo / "dvc.yaml").write_text("vars:\n  - conf/evaluate/default.yaml\nstages: {}\n"),
            "dvc.yaml",
            "declares no stage",
        ),
        (lambda repo: (repo / "dvc.yaml").write_text("stages:\n  label: [unclosed\n"), "dvc.yaml", "DVC cannot parse it"),
        (lambda repo: (repo / "dvc.yaml").write_text("stages:\n  label:\n    cmd: x\n    outz: [a]\n"), "dvc.yaml", "DVC cannot parse it"),
        (lambda repo: (repo / "tour" / "dvc.yaml").write_text("stages: [unclosed\n"), "tour/dvc.yaml", "DVC cannot parse it"),
        (lambda repo: (repo / "conf/evaluate/design/laptop.yaml").write_text("seeds: [unclosed\n"), "laptop.yaml", "DVC cannot"),
    ],
    ids=["empty", "missing", "cut at 1500 bytes", "no stage", "syntax error", "misspelt key", "another pipeline broken", "vars file"],
)
def test_a_broken_pipeline_file_deletes_nothing_and_is_one_line(repo, capsys, breakage, file, says):
    """The critical case: a missing, empty, cut or unparsable dvc.yaml read as "no stages" would delete
    every committed metrics file and lock entry."""
    before, lock = committed_metrics(repo), (repo / "dvc.lock").read_text()
    breakage(repo)
    assert prune_lock.main([], root=repo) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and says in err and file in err, err
    assert committed_metrics(repo) == before and (repo / "dvc.lock").read_text() == lock


@pytest.mark.slow(seconds=8)
def test_a_committed_orphan_with_uncommitted_edits_is_kept_and_a_removed_stage_needs_saying(repo, capsys):
    stale = repo / "metrics" / "steering" / "seed7.json"
    stale.write_text("{}\n")
    git(repo, "add", str(stale))
    stale.write_text('{"my": "edit"}\n')  # changed since it was staged: the edit would be lost
    assert prune_lock.main([], root=repo) == 0
    assert "metrics/steering/seed7.json (uncommitted changes: kept)" in capsys.readouterr().out and stale.exists()
    # a whole stage gone from dvc.yaml: refused until the user says so
    pipeline = yaml.safe_load((repo / "dvc.yaml").read_text())
    del pipeline["stages"]["drive"]
    (repo / "dvc.yaml").write_text(yaml.safe_dump(pipeline, sort_keys=False))
    assert prune_lock.main([], root=repo) == 2 and "has no stage drive" in capsys.readouterr().err
    assert "metrics/drive.json" in committed_metrics(repo)
    assert prune_lock.main(["--stage-removed"], root=repo) == 0
    assert "metrics/drive.json" not in committed_metrics(repo) and "drive" not in yaml.safe_load((repo / "dvc.lock").read_text())["stages"]
