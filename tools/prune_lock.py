"""Make the repository state one run: drop dvc.lock's entries for stages that dvc.yaml no longer
has (a grid made smaller: fewer seeds, a network removed) and delete committed files under metrics/
that no stage of any dvc.yaml of the repository declares (outs, metrics, plots).

    python tools/prune_lock.py [--dry-run] [--delete-untracked]

`dvc repro` updates the entries of the stages it runs and keeps every other entry, so after a
grid shrinks the lock pins stages that no longer exist and metrics/ keeps their files, which
`dvc metrics show` lists as if current. tests/repository/test_repository_state.py fails until this is run.

What may go is decided from the pipelines' declarations, never from the lock: a stage missing from
dvc.lock (not run yet, or a reset lock) keeps its outputs. A file git does not track (your notes)
is listed and kept unless `--delete-untracked` asks. A malformed or missing dvc.lock is one line
naming it, exit status 2.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
MARKER = "offroad-path-output"  # offroad_path.utils.atomic.MARKER, less its dot: `.<file>.` + this marks a file output
# Records of the run that no stage writes: the repro's stage times (benchmarks/pipeline_time.py --json).
RECORDS = ("metrics/pipeline_time.json",)


class LockError(Exception):
    """dvc.lock cannot be read as a lock: the one line that says why."""


def read_lock(root: Path) -> dict[str, dict]:
    """dvc.lock's stages (name -> entry); LockError naming the file when it is missing or malformed."""
    path = root / "dvc.lock"
    try:
        lock = yaml.safe_load(path.read_text())
    except FileNotFoundError:
        raise LockError(f"{path}: no such file (run dvc repro first)") from None
    except (yaml.YAMLError, UnicodeDecodeError) as e:
        raise LockError(f"{path}: not valid YAML ({str(e).splitlines()[0]})") from None
    if not isinstance(lock, dict) or not isinstance(lock.get("stages"), dict):
        raise LockError(f"{path}: has no mapping 'stages' of stage entries (a lock DVC wrote has one)")
    for name, entry in lock["stages"].items():
        if not isinstance(entry, dict) or not isinstance(entry.get("outs", []), list):
            raise LockError(f"{path}: stage {name!r} is not a mapping with a list of outs")
    return lock["stages"]


def pipelines(root: Path) -> tuple[set[str], set[Path]]:
    """(the stage names of root's dvc.yaml, matrix stages expanded; every output path that any
    dvc.yaml of the repository declares, absolute)."""
    from dvc.repo import Repo

    with Repo(str(root)) as repo:
        stages = list(repo.index.stages)
    main = str(root / "dvc.yaml")
    names = {stage.name for stage in stages if stage.dvcfile.path == main}
    declared = {Path(out.fs_path) for stage in stages for out in stage.outs}
    return names, declared


def tracked(root: Path) -> set[Path]:
    """The files under metrics/ that git tracks (committed or staged)."""
    listed = subprocess.run(["git", "ls-files", "-z", "metrics"], cwd=root, capture_output=True, text=True, check=False)
    return {root / name for name in listed.stdout.split("\0") if name} if listed.returncode == 0 else set()


def orphans(root: Path = ROOT) -> tuple[list[str], list[Path]]:
    """(dvc.lock entries of no stage, files under metrics/ that no stage of any dvc.yaml declares)."""
    lock = read_lock(root)
    names, declared = pipelines(root)
    records = {root / record for record in RECORDS}
    files = sorted(
        path
        for path in (root / "metrics").rglob("*")
        if path.is_file() and path not in records and not any(owner(path) == out or out in owner(path).parents for out in declared)
    )
    return sorted(set(lock) - names), files


def owner(path: Path) -> Path:
    """The output a file stands for: a stage's marker beside a file output (`.seed0.json` + MARKER)
    stands for that file; any other file for itself."""
    if path.name.startswith(".") and path.name.endswith(MARKER) and path.name != f".{MARKER}":
        return path.with_name(path.name[1 : -len(MARKER) - 1])
    return path


def main(argv: list[str] | None = None, root: Path = ROOT) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dry-run", action="store_true", help="list what would go, change nothing")
    parser.add_argument("--delete-untracked", action="store_true", help="also delete listed files git does not track")
    args = parser.parse_args(argv)
    try:
        entries, files = orphans(root)
    except LockError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    committed = tracked(root)
    untracked = [path for path in files if path not in committed and owner(path) == path]  # a stage's marker is never yours
    for name in entries:
        print(f"dvc.lock: {name}")
    for path in files:
        print(f"{path.relative_to(root)}{' (untracked: kept without --delete-untracked)' if path in untracked else ''}")
    if args.dry_run:
        return 0
    if entries:
        lock_path = root / "dvc.lock"
        lock = yaml.safe_load(lock_path.read_text())
        lock["stages"] = {name: entry for name, entry in lock["stages"].items() if name not in entries}
        tmp = lock_path.with_suffix(".lock.tmp")
        tmp.write_text(yaml.safe_dump(lock, sort_keys=False, width=1000))
        tmp.replace(lock_path)
    for path in files:
        if path not in untracked or args.delete_untracked:
            path.unlink()
    return 0


if __name__ == "__main__":
    sys.exit(main())
