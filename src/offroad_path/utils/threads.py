"""How many threads a stage's process computes with, set once for torch, OpenCV and onnxruntime.

Two busy processes with two threads each on two cores run several times slower than with one
thread each: the threads of OpenMP and oneDNN spin while they wait for each other, and with more
threads than free cores they wait for a core instead. So every stage sets its thread count on
purpose, from the `threads` setting:

- a number: exactly that many. The stages' default is 2: the thread count changes the rounding of
  training, and so its results (one laptop epoch of SegNet: test IoU 0.721 on 2 threads, 0.614 on
  1), so a fixed count gives the same numbers on every machine.
- "all": one per core this process may run on (os.sched_getaffinity).
- "free": the cores not busy right now, from two readings of /proc/stat 0.2 s apart (at least 1).
  For inference, whose output does not depend on the thread count (`predict`'s default).
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

CHOICES = ("all", "free")


def is_thread_setting(value: object) -> bool:
    """True for "all", "free" or a whole number >= 1 (as a number or a string)."""
    text = str(value)
    return text in CHOICES or (text.isdigit() and int(text) >= 1)


def usable_cores() -> int:
    """Cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


def cpu_times(stat: Path = Path("/proc/stat")) -> tuple[int, int]:
    """(idle, total) jiffies of all cores together, from the first line of /proc/stat."""
    fields = [int(v) for v in stat.read_text().split("\n", 1)[0].split()[1:]]
    idle = fields[3] + (fields[4] if len(fields) > 4 else 0)  # idle + iowait
    return idle, sum(fields[:8])  # guest time is already counted in user time


def busy_between(before: tuple[int, int], after: tuple[int, int], cores: int) -> float:
    """Cores busy on average between two cpu_times readings."""
    (idle0, total0), (idle1, total1) = before, after
    if total1 <= total0:
        return 0.0
    return cores * (1 - (idle1 - idle0) / (total1 - total0))


def busy_cores(interval_s: float = 0.2) -> float:
    """How many cores are busy, over the next interval_s (0 where /proc/stat cannot be read)."""
    try:
        before = cpu_times()
        time.sleep(interval_s)
        return busy_between(before, cpu_times(), os.cpu_count() or 1)
    except (OSError, ValueError, IndexError):
        return 0.0


def thread_count(setting: object) -> int:
    """The thread count a `threads` setting stands for (see the module's docstring)."""
    if not is_thread_setting(setting):
        raise ValueError(f"threads={setting!r}: must be 'all', 'free' or a whole number >= 1")
    text = str(setting)
    if text == "all":
        return usable_cores()
    if text == "free":
        return max(1, min(usable_cores(), round((os.cpu_count() or 1) - busy_cores())))
    return int(text)


def set_threads(setting: object) -> int:
    """Set the thread count of torch, OpenCV and OpenMP from a `threads` setting; returns it (an
    onnxruntime session takes it too: offroad_path.inference.runners). torch is set through
    OMP_NUM_THREADS when this process has not imported it yet, so that a stage without torch
    does not pay for its import."""
    import cv2

    n = thread_count(setting)
    os.environ["OMP_NUM_THREADS"] = str(n)
    if "torch" in sys.modules:
        sys.modules["torch"].set_num_threads(n)
    cv2.setNumThreads(n)
    return n
