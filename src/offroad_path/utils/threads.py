"""How many threads a stage's process computes with, set once for torch, OpenCV and onnxruntime.

Two busy processes with two threads each on two cores run several times slower than with one
thread each: the threads of OpenMP and oneDNN spin while they wait for each other, and with more
threads than free cores they wait for a core instead. So every stage sets its thread count on
purpose, from the `threads` setting:

- a number: exactly that many. The stages' default is 2: the thread count changes the rounding of
  training, and so its results (one laptop epoch of SegNet: test IoU 0.721 on 2 threads, 0.614 on
  1), so a fixed count gives the same numbers on every machine.
- "all": one per core this process may run on (os.sched_getaffinity).
- "free": the cores not busy right now, from two readings of the CPU times 0.2 s apart (at least 1).
  For inference, whose output does not depend on the thread count (`predict`'s default).
"""

from __future__ import annotations

import os
import sys

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


def busy_cores(interval_s: float = 0.2) -> float:
    """How many cores are busy on average over the next interval_s (psutil's reading of the system's CPU times)."""
    import psutil

    return psutil.cpu_percent(interval=interval_s) / 100 * (os.cpu_count() or 1)


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
