"""Make the repository state one run: drop dvc.lock's entries for stages that dvc.yaml no longer
has (a grid made smaller: fewer seeds, a network removed) and delete files under metrics/ that no
stage of dvc.yaml writes.

    python tools/prune_lock.py [--dry-run]

`dvc repro` updates the entries of the stages it runs and keeps every other entry, so after a
grid shrinks the lock pins stages that no longer exist and metrics/ keeps their files, which
`dvc metrics show` lists as if current. tests/test_repository_state.py fails until this is run.
"""

from __future__ import annotations

import argparse
import subprocess
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
MARKER = "offroad-path-output"  # offroad_path.utils.atomic.MARKER, less its dot: `.<file>.` + this marks a file output


def stage_names(root: Path = ROOT) -> set[str]:
    """Every stage of dvc.yaml, matrix stages expanded (`train_scratch@unet-0`)."""
    listed = subprocess.run(["dvc", "stage", "list", "--name-only"], cwd=root, capture_output=True, text=True, check=True)
    return set(listed.stdout.split())


def orphans(root: Path = ROOT) -> tuple[list[str], list[Path]]:
    """(dvc.lock entries of no stage, files under metrics/ that no current stage writes)."""
    lock = yaml.safe_load((root / "dvc.lock").read_text())
    names = stage_names(root)
    entries = sorted(set(lock["stages"]) - names)
    written = {root / out["path"] for name in names & set(lock["stages"]) for out in lock["stages"][name].get("outs", [])}
    files = sorted(
        path
        for path in (root / "metrics").rglob("*")
        if path.is_file() and not any(owner(path) == out or out in owner(path).parents for out in written)
    )
    return entries, files


def owner(path: Path) -> Path:
    """The output a file stands for: a stage's marker beside a file output (`.seed0.json` + MARKER)
    stands for that file; any other file for itself."""
    if path.name.startswith(".") and path.name.endswith(MARKER) and path.name != f".{MARKER}":
        return path.with_name(path.name[1 : -len(MARKER) - 1])
    return path


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dry-run", action="store_true", help="list what would go, change nothing")
    args = parser.parse_args()
    entries, files = orphans()
    for name in entries:
        print(f"dvc.lock: {name}")
    for path in files:
        print(path.relative_to(ROOT))
    if args.dry_run or not (entries or files):
        return
    lock_path = ROOT / "dvc.lock"
    lock = yaml.safe_load(lock_path.read_text())
    lock["stages"] = {name: entry for name, entry in lock["stages"].items() if name not in entries}
    tmp = lock_path.with_suffix(".lock.tmp")
    tmp.write_text(yaml.safe_dump(lock, sort_keys=False, width=1000))
    tmp.replace(lock_path)
    for path in files:
        path.unlink()


if __name__ == "__main__":
    main()
