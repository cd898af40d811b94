"""One single-threaded worker process per core, for stages that work sequence by sequence.

A worker's error reaches the parent whole (type and message; a traceback for a bug); a worker that
dies (a signal, the out-of-memory killer) ends the map with an error naming its job; the others are
stopped at once, and workers die with their parent, so a failure or a stop leaves no process behind.

Each worker has its own pipe and the parent hands out one job at a time, so it always knows which
job a dead worker had (multiprocessing.Pool replaces a dead worker and waits for its job forever).
"""

from __future__ import annotations

import multiprocessing as mp
import os
import pickle
import signal
import traceback
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from multiprocessing.connection import Connection, wait
from typing import Any

from offroad_path.errors import InputError
from offroad_path.utils.progress import Progress

THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
_ACTIVE: list[Any] = []  # worker processes of this process, for stop_workers (on SIGTERM)


class WorkerError(RuntimeError):
    """A worker failed with an exception that cannot be rebuilt here: its text and traceback."""


@dataclass
class _Failure:
    error: BaseException | None  # the exception, when it survives pickling
    text: str  # type, message and traceback otherwise


def _die_with_parent(parent: int) -> None:
    """In a worker: the kernel kills it when the parent dies, even by SIGKILL (Linux).

    A worker takes a second or more to start (it imports the stage's modules), and its first job is
    already waiting in its pipe: one whose parent died meanwhile ends here instead of doing that job.
    """
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C reaches the parent, which stops the workers
    try:
        import ctypes

        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):  # not Linux: orphans end when their job does
        pass
    if os.getppid() != parent:
        os._exit(1)


def _call(fn: Callable[[Any], Any], job: Any) -> Any:
    try:
        return fn(job)
    except Exception as e:
        try:
            pickle.loads(pickle.dumps(e))
            return _Failure(e, "")
        except Exception:
            return _Failure(None, "".join(traceback.format_exception(e)))


def _serve(conn: Connection, parent: int) -> None:
    """A worker's loop: (fn, job) in, its result out, until None or the parent is gone."""
    _die_with_parent(parent)
    while True:
        try:
            message = conn.recv()
        except EOFError:
            return
        if message is None:
            return
        conn.send(_call(*message))


def _raise(failure: _Failure) -> None:
    if failure.error is not None:
        raise failure.error
    raise WorkerError(f"a worker process failed:\n{failure.text}")


def _death(process: Any) -> str:
    code = process.exitcode
    if code is not None and code < 0:
        name = signal.Signals(-code).name
        why = " (the kernel's out-of-memory killer sends it)" if name == "SIGKILL" else ""
        return f"killed by {name}{why}"
    return f"exited with status {code}"


def stop_workers() -> None:
    """Terminate every worker process of this process, then kill those still alive after 5 s."""
    for process in list(_ACTIVE):
        if process.is_alive():
            process.terminate()
    for process in list(_ACTIVE):
        process.join(timeout=5)
        if process.is_alive():
            process.kill()
            process.join()


def _start(count: int, env: dict[str, str]) -> list[tuple[Any, Connection]]:
    """`count` spawned workers, each with its end of a pipe, and `env` besides one thread each. The
    thread variables must be set before a worker imports numpy, hence spawn: BLAS threads in every
    worker would fight over the cores (here, that cost 40 % of the rendering throughput)."""
    context = mp.get_context("spawn")
    saved = {k: os.environ.get(k) for k in (*THREAD_VARIABLES, *env)}
    os.environ.update(dict.fromkeys(THREAD_VARIABLES, "1") | env)
    try:
        started = []
        for _ in range(count):
            mine, theirs = context.Pipe()
            process = context.Process(target=_serve, args=(theirs, os.getpid()), daemon=True)
            process.start()
            theirs.close()
            _ACTIVE.append(process)
            started.append((process, mine))
        return started
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def _stop(pool: list[tuple[Any, Connection]]) -> None:
    for process, _ in pool:
        if process.is_alive():
            process.terminate()
    for process, conn in pool:
        process.join(timeout=5)
        if process.is_alive():
            process.kill()
            process.join()
        conn.close()
        _ACTIVE.remove(process)


def _receive(process: Any, conn: Connection, ready: set, job: str) -> Any:
    """The result a worker sent, or the error of its death (InputError naming its job)."""
    if conn in ready:
        try:
            result = conn.recv()
        except EOFError:  # died while sending
            pass
        else:
            if isinstance(result, _Failure):
                _raise(result)
            return result
    process.join()
    raise InputError(job, f"its worker process was {_death(process)}; nothing was written")


def map_processes(  # noqa: PLR0913
    fn: Callable[[Any], Any],
    jobs: Sequence[Any],
    workers: int = 0,
    names: Sequence[str] | None = None,
    progress: str | None = None,
    *,
    env: dict[str, str] | None = None,
) -> list[Any]:
    """[fn(job) for job in jobs], on `workers` processes (0: one per core), results in job order.

    `fn` should call cv2.setNumThreads(1) (one process per core). The first failing job stops the
    rest; a worker that dies raises InputError naming its job (`names`, default: its number).
    progress: what the jobs do, for a bar (a terminal) or a log line per finished job (utils.progress).
    env: variables the workers start with (read when they load their libraries); given, every job
    runs in a worker, even where one would do.
    """
    names = names or [f"job {i}" for i in range(len(jobs))]
    shown = Progress(progress, len(jobs), "jobs") if progress else None
    try:
        return _map(fn, jobs, workers, names, shown, env=env)
    finally:
        if shown is not None:
            shown.close()


def _map(  # noqa: PLR0913
    fn: Callable[[Any], Any], jobs: Sequence[Any], workers: int, names: Sequence[str], shown: Progress | None, *, env: dict[str, str] | None
) -> list[Any]:
    workers = min(workers or os.cpu_count() or 1, len(jobs))
    if workers <= 1 and env is None:
        results_in_order = []
        for job, name in zip(jobs, names, strict=True):
            results_in_order.append(fn(job))
            if shown is not None:
                shown.done(name)
        return results_in_order
    results: dict[int, Any] = {}
    pending = iter(range(len(jobs)))
    doing: dict[int, int] = {}  # worker -> its job
    pool = _start(max(workers, 1), env or {})

    def hand_out(w: int) -> None:
        i = next(pending, None)
        pool[w][1].send(None if i is None else (fn, jobs[i]))
        if i is None:
            del doing[w]
        else:
            doing[w] = i

    try:
        for w in range(workers):
            doing[w] = -1
            hand_out(w)
        while doing:
            ready = set(wait([pool[w][1] for w in doing] + [pool[w][0].sentinel for w in doing]))
            for w in [w for w in doing if pool[w][1] in ready or pool[w][0].sentinel in ready]:
                results[doing[w]] = _receive(*pool[w], ready, names[doing[w]])
                if shown is not None:
                    shown.done(names[doing[w]])
                hand_out(w)
        return [results[i] for i in range(len(jobs))]
    finally:
        _stop(pool)
