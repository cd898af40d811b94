"""Outputs that are safe to write: a stage writes into a temporary sibling and renames it into place
at the end, so an interrupted or failed run never leaves a partial output where the next stage would
read it; and it only ever replaces a folder that this project made (a marker file inside it), never
one of the user's, and never one of its own inputs.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path

MARKER = ".offroad-path-output"  # inside every folder the project wrote; its text names the stage
_UNFINISHED: set[Path] = set()  # temporary folders of this process's outputs still being written


class UnsafeOutputError(ValueError):
    """An output location that would delete or overwrite something the project did not make."""


def remove_unfinished() -> None:
    """Delete the temporary folders of outputs still being written: for a process being stopped."""
    for tmp in list(_UNFINISHED):
        shutil.rmtree(tmp, ignore_errors=True)


def marker_stage(marker: Path) -> str | None:
    """The stage a marker (or sidecar marker) names; None when there is none."""
    try:
        words = marker.read_text().split()
    except (OSError, UnicodeDecodeError):
        return None
    return words[0] if words and marker.is_file() else None


def sidecar(path: Path) -> Path:
    """The marker beside a file output, naming the stage that wrote it."""
    return path.parent / f".{path.name}{MARKER}"


def check_output_dir(target: str | Path, key: str, stage: str) -> None:
    """Refuse a folder output that exists and is not the output of `stage`: a file, or a folder
    with content and no marker naming the stage. Checked before any work (utils.outputs) and again
    when the output is replaced (nothing else appeared meanwhile)."""
    target = Path(target)
    if target.is_symlink() or (target.exists() and not target.is_dir()):
        raise UnsafeOutputError(f"{key}={target}: exists and is not a folder; it is left as it is. Choose another {key}")
    if not target.is_dir() or not any(target.iterdir()):
        return
    owner = marker_stage(target / MARKER)
    if owner is None:
        raise UnsafeOutputError(
            f"{key}={target}: a folder this project did not write (no {MARKER} inside) is not replaced. "
            f"Choose another {key}, or empty or remove it yourself"
        )
    if owner != stage:
        raise UnsafeOutputError(
            f"{key}={target}: holds the output of the {owner} stage, which {stage} does not replace; choose another {key}"
        )


def owned(folder: Path) -> bool:
    return folder.is_dir() and not folder.is_symlink() and (folder / MARKER).is_file()


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def remove_stale_siblings(target: Path) -> list[Path]:
    """Temporary folders beside target left by a killed run (its process is gone): removed."""
    removed = []
    if not target.parent.is_dir():
        return removed
    for sibling in target.parent.glob(f".{target.name}.*-*"):
        kind, _, rest = sibling.name.removeprefix(f".{target.name}.").partition("-")
        pid = rest.split("-")[0]
        if kind in ("tmp", "old") and pid.isdigit() and owned(sibling) and not _pid_alive(int(pid)):
            shutil.rmtree(sibling, ignore_errors=True)
            removed.append(sibling)
    return removed


@contextlib.contextmanager
def atomic_directory(target: str | Path, stage: str, key: str | None = None) -> Iterator[Path]:
    """Yield an empty temporary directory that replaces `target` completely on success.

    `stage` is written into the marker; `key` is the config key of target, for messages (default:
    the stage's name). The stage runner has checked target against the stage's inputs (utils.outputs).
    """
    target = Path(target)
    check_output_dir(target, key or stage, stage)
    target.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_siblings(target)
    tmp = Path(tempfile.mkdtemp(prefix=f".{target.name}.tmp-{os.getpid()}-", dir=target.parent))
    tmp.chmod(0o777 & ~current_umask())  # mkdtemp's is 0700: the folder takes the user's umask as mkdir's would
    (tmp / MARKER).write_text(f"{stage}\n")
    _UNFINISHED.add(tmp)
    try:
        yield tmp
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    finally:
        _UNFINISHED.discard(tmp)
    old = target.parent / f".{target.name}.old-{os.getpid()}"
    if target.exists():
        check_output_dir(target, key or stage, stage)  # nothing of the user's appeared there meanwhile
        os.replace(target, old)
    os.replace(tmp, target)
    shutil.rmtree(old, ignore_errors=True)


def current_umask() -> int:
    """The process's umask (Linux: read from /proc without changing it; elsewhere set and restored)."""
    status = Path("/proc/self/status")
    if status.is_file():
        for line in status.read_text().splitlines():
            if line.startswith("Umask:"):
                return int(line.split()[1], 8)
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def write_text_atomic(path: str | Path, text: str, stage: str | None = None) -> None:
    """Replace the file at `path` with `text` in one rename; a stage's output (`stage` given) gets
    a sidecar marker naming the stage, which lets the next run of that stage replace it."""
    path = Path(path)
    if path.is_dir():
        raise UnsafeOutputError(f"{path}: is a folder; a file was expected here and the folder is left as it is")
    path.parent.mkdir(parents=True, exist_ok=True)
    if stage is not None:
        write_text_atomic(sidecar(path), f"{stage}\n")
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.tmp-", dir=path.parent)
    try:
        with os.fdopen(fd, "w") as f:
            f.write(text)
        os.chmod(tmp, 0o666 & ~current_umask())  # mkstemp's is 0600: the file takes the user's umask as open's would
        os.replace(tmp, path)
    finally:
        Path(tmp).unlink(missing_ok=True)
