"""One single-threaded worker process per core, for stages that work sequence by sequence.

A worker's error reaches the parent whole (type and message; a traceback for a bug), the pool is
shut down at once, and workers die with their parent, so a failure or a stop leaves no process behind.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import pickle
import signal
import traceback
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
_ACTIVE_POOLS: list[Any] = []  # for stop_workers, called on SIGTERM


class WorkerError(RuntimeError):
    """A worker failed with an exception that cannot be rebuilt here: its text and traceback."""


@dataclass
class _Failure:
    error: BaseException | None  # the exception, when it survives pickling
    text: str  # type, message and traceback otherwise


def _die_with_parent() -> None:
    """Pool initialiser: the kernel kills this worker when the parent dies, even by SIGKILL (Linux)."""
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    try:
        import ctypes

        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):  # not Linux: orphans end when their job does
        pass


def _call(fn_job: tuple[Callable[[Any], Any], Any]) -> Any:
    fn, job = fn_job
    try:
        return fn(job)
    except Exception as e:
        try:
            pickle.loads(pickle.dumps(e))
            return _Failure(e, "")
        except Exception:
            return _Failure(None, "".join(traceback.format_exception(e)))


def _raise(failure: _Failure) -> None:
    if failure.error is not None:
        raise failure.error
    raise WorkerError(f"a worker process failed:\n{failure.text}")


def stop_workers() -> None:
    """Terminate every pool of this process (no replacement workers start) and its processes."""
    for pool in list(_ACTIVE_POOLS):
        pool.terminate()
    for child in mp.active_children():
        child.terminate()
        child.join(timeout=5)


def map_processes(fn: Callable[[Any], Any], jobs: Sequence[Any], workers: int = 0) -> list[Any]:
    """[fn(job) for job in jobs], on `workers` processes (0: one per core), results in job order.

    The thread variables must be set before a worker imports numpy, hence spawn: BLAS threads in
    every worker would fight over the cores (here, that cost 40 % of the rendering throughput).
    `fn` should call cv2.setNumThreads(1) for the same reason. The first failing job stops the rest.
    """
    workers = min(workers or os.cpu_count() or 1, len(jobs))
    if workers <= 1:
        return [fn(job) for job in jobs]
    saved = {k: os.environ.get(k) for k in THREAD_VARIABLES}
    os.environ.update(dict.fromkeys(THREAD_VARIABLES, "1"))
    pool = mp.get_context("spawn").Pool(workers, initializer=_die_with_parent)
    _ACTIVE_POOLS.append(pool)
    try:
        results = []
        for result in pool.imap(_call, [(fn, job) for job in jobs], chunksize=1):
            if isinstance(result, _Failure):
                _raise(result)
            results.append(result)
        pool.close()
        return results
    finally:
        pool.terminate()
        pool.join()
        _ACTIVE_POOLS.remove(pool)
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
