"""A stage ends with the `dvc repro` that runs it.

DVC starts a stage's command through a shell and, stopped by SIGTERM, exits without passing the signal
on: the stage, re-parented to init, would run on, holding its output locks, and write its outputs and
metrics behind DVC's back. So a stage run by DVC watches the DVC process (the nearest ancestor without
DVC_STAGE in its environment: DVC sets it for the command alone) and, when it is gone, stops itself
as a SIGTERM would (the stage's handler: workers stopped, unfinished outputs deleted, locks released).
The stage's own workers die with the stage (utils.parallel), so the whole tree ends.
"""

from __future__ import annotations

import os
import signal
import threading
from pathlib import Path

POLL_S = 0.5  # how soon after DVC a stage stops


def process_started(pid: int) -> tuple[int, int] | None:
    """(parent pid, start time in clock ticks) of a live process; None when it is gone or a zombie.
    The start time tells the process from a later one given the same pid."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rpartition(")")[2].split()
    except OSError:
        return None
    return None if fields[0] in ("Z", "X") else (int(fields[1]), int(fields[19]))


def dvc_ancestor(start: int | None = None) -> tuple[int, int] | None:
    """(pid, start time) of the DVC process that runs this stage; None when DVC does not run it (no
    DVC_STAGE here) or /proc cannot tell (not Linux, another user's process)."""
    if "DVC_STAGE" not in os.environ:
        return None
    pid = os.getppid() if start is None else start
    for _ in range(8):  # DVC, a shell or two, a `timeout`: never deep
        found = process_started(pid)
        try:
            environ = Path(f"/proc/{pid}/environ").read_bytes().split(b"\0")
        except OSError:
            return None
        if found is None:
            return None
        if not any(entry.startswith(b"DVC_STAGE=") for entry in environ):
            return pid, found[1]
        pid = found[0]
    return None


def end_with_dvc() -> None:
    """Under `dvc repro`: a daemon thread that sends this process SIGTERM once DVC is gone."""
    ancestor = dvc_ancestor()
    if ancestor is None:
        return
    pid, started = ancestor

    def watch() -> None:
        while (found := process_started(pid)) is not None and found[1] == started:
            threading.Event().wait(POLL_S)
        os.kill(os.getpid(), signal.SIGTERM)

    threading.Thread(target=watch, name="end-with-dvc", daemon=True).start()
