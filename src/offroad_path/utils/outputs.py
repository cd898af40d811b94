"""The rule every stage's outputs follow, applied by the stage runner before any work.

A stage declares what it writes (folders and files, by config key) and everything it reads. An
output is refused when it is, holds or lies inside an input or another output; a folder is replaced
only when its marker names the same stage, a file only when its sidecar marker does (utils.atomic
writes both); the place it goes must be writable. While the stage runs it holds a lock beside each
output, so a second run into the same output is refused at once, naming the first run's process.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

from offroad_path.utils.atomic import UnsafeOutputError, check_output_dir, marker_stage, sidecar

_HELD: set[Path] = set()  # lock files of this process, for a stop by signal (release_locks)


@dataclass(frozen=True)
class Outputs:
    """What one run of a stage writes (config key -> path) and every path it reads."""

    stage: str  # the name its markers carry
    folders: dict[str, str | Path] = field(default_factory=dict)
    files: dict[str, str | Path] = field(default_factory=dict)
    inputs: Iterable[str | Path | None] = ()
    # Folders the run adds files to without owning them (a file logger's save_dir, shared by every
    # run): they may not overlap an input or an output, and must be writable; never replaced or locked.
    shared: dict[str, str | Path | None] = field(default_factory=dict)


def _related(a: Path, b: Path) -> bool:
    return a == b or a.is_relative_to(b) or b.is_relative_to(a)


def _writable_place(path: Path, key: str) -> None:
    """The nearest existing folder above `path` is a folder this process may write in (the
    missing ones between are made when the stage writes)."""
    parent = path.parent
    while not parent.exists() and parent != parent.parent:
        parent = parent.parent
    if not parent.is_dir():
        raise UnsafeOutputError(f"{key}={path}: {parent} is not a folder; choose another {key}")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise UnsafeOutputError(f"{key}={path}: the folder {parent} is not writable; choose another {key}")


def _check_file(path: Path, key: str, stage: str) -> None:
    if path.is_symlink() or (path.exists() and not path.is_file()):
        raise UnsafeOutputError(f"{key}={path}: exists and is not a file; it is left as it is. Choose another {key}")
    if not path.exists():
        return
    owner = marker_stage(sidecar(path))
    if owner != stage:
        made = f"was written by the {owner} stage" if owner else f"was not written by this project (no {sidecar(path).name} beside it)"
        raise UnsafeOutputError(f"{key}={path}: {made} and is not replaced. Choose another {key}, or remove it yourself")


def check_outputs(outputs: Outputs) -> None:
    """Refuse, before any work, every output the rule above forbids: UnsafeOutputError naming the key."""
    inputs = [(str(p), Path(p).resolve()) for p in outputs.inputs if p not in (None, "")]
    declared = [(key, Path(p), True) for key, p in outputs.folders.items()] + [(key, Path(p), False) for key, p in outputs.files.items()]
    for i, (key, path, is_folder) in enumerate(declared):
        resolved = path.resolve()
        for shown, source in inputs:
            if _related(resolved, source):
                raise UnsafeOutputError(f"{key}={path}: overlaps the input {shown}; writing there would replace it. Choose another {key}")
        for other_key, other, _ in declared[:i]:
            if _related(resolved, other.resolve()):
                raise UnsafeOutputError(f"{key}={path}: overlaps {other_key}={other}, another output of this stage. Choose another {key}")
        (check_output_dir if is_folder else _check_file)(path, key, outputs.stage)
        _writable_place(path, key)
    for key, place in outputs.shared.items():
        if place not in (None, ""):
            _check_shared(Path(place), key, inputs, declared)


def check_metrics_follow(outputs: Outputs, metrics_dir: str | Path, pipeline_dirs: Iterable[str | Path]) -> None:
    """A run whose inputs or outputs lie outside the pipeline's folders (`pipeline_dirs`: the data and
    recordings folders) is a run of other data: it may not write into `metrics_dir`, which holds the
    pipeline's metrics (the committed run's, in this checkout). Refused naming the metrics key, so that
    its metrics follow its outputs (UnsafeOutputError)."""
    metrics = Path(metrics_dir).resolve()
    pipeline = [Path(p).resolve() for p in pipeline_dirs if p not in (None, "")]
    written = {**outputs.folders, **outputs.files}
    into_metrics = [(key, p) for key, p in written.items() if Path(p).resolve().is_relative_to(metrics)]
    if not into_metrics:
        return
    elsewhere = [(key, p) for key, p in written.items() if not Path(p).resolve().is_relative_to(metrics)]
    elsewhere += [("input", p) for p in outputs.inputs if p not in (None, "")]
    for key, path in elsewhere:
        if not any(Path(path).resolve().is_relative_to(folder) for folder in pipeline):
            metrics_key, metrics_path = into_metrics[0]
            shown = f"{key}={path}" if key != "input" else f"the input {path}"
            raise UnsafeOutputError(
                f"{metrics_key}={metrics_path}: this run reads or writes outside the pipeline's folders ({shown}), "
                f"so its metrics would replace the pipeline's in {metrics_dir}; set {metrics_key} beside its outputs"
            )


def _check_shared(place: Path, key: str, inputs: list[tuple[str, Path]], declared: list[tuple[str, Path, bool]]) -> None:
    resolved = place.resolve()
    for shown, source in inputs:
        if _related(resolved, source):
            raise UnsafeOutputError(f"{key}={place}: overlaps the input {shown}; the run would write into it. Choose another {key}")
    for other_key, other, _ in declared:
        if _related(resolved, other.resolve()):
            raise UnsafeOutputError(f"{key}={place}: overlaps {other_key}={other}, which this run replaces. Choose another {key}")
    _writable_place(resolved / "x", key)


def lock_path(output: Path) -> Path:
    return output.parent / f".{output.name}.lock"


def _holder(lock: Path) -> str:
    try:
        text = lock.read_text().strip()
    except OSError:
        return "another process"
    return f"process {text}" if text else "another process"


@contextlib.contextmanager
def output_lock(output: Path, key: str) -> Iterator[None]:
    """Hold an exclusive lock beside `output` (fcntl.flock on .<name>.lock) for the block; refuse
    at once when another process holds it. The lock file is removed on release."""
    lock = lock_path(output)
    lock.parent.mkdir(parents=True, exist_ok=True)
    while True:
        fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            holder = _holder(lock)
            raise UnsafeOutputError(
                f"{key}={output}: another run is writing it ({holder}); wait for it to end or choose another {key}"
            ) from None
        try:  # the file locked must still be the one at the path (a releasing run unlinks it)
            same = os.fstat(fd).st_ino == os.stat(lock).st_ino
        except FileNotFoundError:
            same = False
        if same:
            break
        os.close(fd)
    _HELD.add(lock)
    try:
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()}: {' '.join(_command())}\n".encode())
        yield
    finally:
        _HELD.discard(lock)
        lock.unlink(missing_ok=True)
        os.close(fd)


def release_locks() -> None:
    """Remove this process's lock files: for a process being stopped (the locks end with it)."""
    for lock in list(_HELD):
        lock.unlink(missing_ok=True)


def _command() -> list[str]:
    try:
        return Path("/proc/self/cmdline").read_bytes().decode(errors="replace").split("\0")[:-1][:6]
    except OSError:
        return []


@contextlib.contextmanager
def claimed(outputs: Outputs) -> Iterator[None]:
    """Check every output (check_outputs) and hold its lock while the block runs."""
    check_outputs(outputs)
    with contextlib.ExitStack() as locks:
        for key, path in (*outputs.folders.items(), *outputs.files.items()):
            locks.enter_context(output_lock(Path(path), key))
        check_outputs(outputs)  # again under the locks: a run that ended meanwhile may have changed them
        yield
