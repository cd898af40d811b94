"""One single-threaded worker process per core, for stages that work sequence by sequence."""

from __future__ import annotations

import multiprocessing as mp
import os
from collections.abc import Callable, Sequence
from typing import Any

THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


def map_processes(fn: Callable[[Any], Any], jobs: Sequence[Any], workers: int = 0) -> list[Any]:
    """[fn(job) for job in jobs], on `workers` processes (0: one per core), results in job order.

    The thread variables must be set before a worker imports numpy, hence spawn: BLAS threads in
    every worker would fight over the cores (here, that cost 40 % of the rendering throughput).
    `fn` should call cv2.setNumThreads(1) for the same reason.
    """
    workers = min(workers or os.cpu_count() or 1, len(jobs))
    if workers <= 1:
        return [fn(job) for job in jobs]
    saved = {k: os.environ.get(k) for k in THREAD_VARIABLES}
    os.environ.update(dict.fromkeys(THREAD_VARIABLES, "1"))
    try:
        with mp.get_context("spawn").Pool(workers) as pool:
            return pool.map(fn, jobs, chunksize=1)
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
