"""What the robustness and interruption tests share: hashing a folder, running a stage as its
command does, finding the processes a test started (through /proc, Linux)."""

from __future__ import annotations

import hashlib
import os
from collections.abc import Callable
from pathlib import Path

import pytest

from offroad_path.utils.cli import run_stage


def snapshot(root: Path) -> dict[str, str]:
    """Every file and folder under root with a hash of its bytes."""
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest() if p.is_file() else "dir" for p in sorted(root.rglob("*"))}


def refused(stage: Callable, cfg, capsys, root: Path, *named: str) -> str:
    """Run `stage` as its command does; assert exit 2, one error line naming `named`, nothing changed under root."""
    before = snapshot(root)
    with pytest.raises(SystemExit) as exit_info:
        run_stage(stage, cfg)
    assert exit_info.value.code == 2
    lines = [line for line in capsys.readouterr().err.splitlines() if line.startswith("error: ")]
    assert len(lines) == 1, lines
    for text in named:
        assert str(text) in lines[0], lines[0]
    assert snapshot(root) == before
    if record := os.environ.get("OFFROAD_RECORD_MESSAGES"):  # collects the messages for the docs
        with open(record, "a") as f:
            f.write(f"{os.environ.get('PYTEST_CURRENT_TEST', '').split(' ')[0]}\t{lines[0]}\n")
    return lines[0]


def user_folder(path: Path) -> Path:
    path.mkdir(parents=True)
    (path / "thesis.tex").write_text("months of work")
    return path


def label_cfg(compose_config, in_dir: Path, tmp_path: Path, *overrides: str):
    return compose_config(f"label.in_dir={in_dir}", f"label.out_dir={tmp_path / 'labels'}", f"label.metrics_path={tmp_path / 'm.json'}",
                          "label.workers=1", "mlflow.enabled=false", *overrides)  # fmt: skip


def tagged_processes(tag: str) -> list[int]:
    """Live processes started with OFFROAD_TEST_TAG=tag in their environment (workers inherit it,
    and keep it when their parent dies and they are re-parented)."""
    found = []
    for environ in Path("/proc").glob("[0-9]*/environ"):
        try:
            if f"OFFROAD_TEST_TAG={tag}".encode() in environ.read_bytes().split(b"\0"):
                state = (environ.parent / "stat").read_text().split(")")[-1].split()[0]
                if state != "Z":
                    found.append(int(environ.parent.name))
        except OSError:
            continue
    return found
