"""Make the repository state one run: drop dvc.lock's entries for stages that dvc.yaml no longer
has (a grid made smaller: fewer seeds, a network removed) and delete committed files under metrics/
that no stage of any dvc.yaml of the repository declares (outs, metrics, plots).

    python tools/prune_lock.py [--dry-run] [--delete-untracked] [--stage-removed]

`dvc repro` updates the entries of the stages it runs and keeps every other entry, so after a
grid shrinks the lock pins stages that no longer exist and metrics/ keeps their files, which
`dvc metrics show` lists as if current. tests/repository/test_repository_state.py fails until this is run.

What may go is decided from the pipelines' declarations, never from the lock: a stage missing from
dvc.lock (not run yet, or a reset lock) keeps its outputs. A file git does not track (your notes)
is listed and kept unless `--delete-untracked` asks; a committed file with uncommitted changes is
listed and kept. Nothing goes unless DVC parsed every pipeline file whole (dvc.yaml, the others, and
the `vars` files they read) and dvc.yaml declares a stage; and a stage of dvc.lock that dvc.yaml
lacks altogether (not one member of a matrix fewer) is taken for a cut or broken dvc.yaml unless
`--stage-removed` says you removed it. A malformed or missing dvc.lock or pipeline file is one line
naming it, exit status 2, nothing changed.
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
    """dvc.lock or a pipeline file cannot be trusted to say what may go: the one line that says why."""


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
    from dvc.exceptions import DvcException
    from dvc.repo import Repo

    main = root / "dvc.yaml"
    if not main.is_file():
        raise LockError(f"{main}: no such file (without it nothing says which outputs are declared)")
    if not main.read_text().strip():
        raise LockError(f"{main}: empty (without a stage nothing says which outputs are declared)")
    try:
        with Repo(str(root)) as repo:
            stages = list(repo.index.stages)
    except DvcException as e:
        where = getattr(e, "path", None) or main
        raise LockError(f"{where}: DVC cannot parse it ({type(e).__name__}: {str(e).strip().splitlines()[0]})") from None
    names = {stage.name for stage in stages if stage.dvcfile.path == str(main)}
    if not names:
        raise LockError(f"{main}: declares no stage")
    declared = {Path(out.fs_path) for stage in stages for out in stage.outs}
    return names, declared


def removed_stages(lock: dict, names: set[str]) -> list[str]:
    """Stages of the lock that dvc.yaml lacks altogether: not a matrix member fewer (train_scratch@unet-9
    beside train_scratch@unet-0), a whole stage gone."""
    kept = {name.split("@")[0] for name in names}
    return sorted({name.split("@")[0] for name in lock} - kept)


def tracked(root: Path, *options: str) -> set[Path]:
    """The files under metrics/ that git tracks (committed or staged); with `--modified`, those whose
    working copy differs from the index."""
    listed = subprocess.run(["git", "ls-files", "-z", *options, "metrics"], cwd=root, capture_output=True, text=True, check=False)
    return {root / name for name in listed.stdout.split("\0") if name} if listed.returncode == 0 else set()


def orphans(root: Path = ROOT, stage_removed: bool = False) -> tuple[list[str], list[Path]]:
    """(dvc.lock entries of no stage, files under metrics/ that no stage of any dvc.yaml declares);
    LockError when a stage of the lock is gone from dvc.yaml altogether, unless stage_removed."""
    lock = read_lock(root)
    names, declared = pipelines(root)
    if (gone := removed_stages(lock, names)) and not stage_removed:
        raise LockError(
            f"{root / 'dvc.yaml'}: has no stage {gone[0]}, which dvc.lock records: a cut or broken dvc.yaml? "
            "(--stage-removed if you removed it on purpose)"
        )
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
    parser.add_argument("--stage-removed", action="store_true", help="a stage of dvc.lock was removed from dvc.yaml on purpose")
    args = parser.parse_args(argv)
    try:
        entries, files = orphans(root, args.stage_removed)
    except LockError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    committed, edited = tracked(root), tracked(root, "--modified")
    untracked = [path for path in files if path not in committed and owner(path) == path]  # a stage's marker is never yours
    for name in entries:
        print(f"dvc.lock: {name}")
    for path in files:
        note = " (untracked: kept without --delete-untracked)" if path in untracked else ""
        note = " (uncommitted changes: kept)" if path in edited else note
        print(f"{path.relative_to(root)}{note}")
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
        if path not in edited and (path not in untracked or args.delete_untracked):
            path.unlink()
    return 0


if __name__ == "__main__":
    sys.exit(main())
