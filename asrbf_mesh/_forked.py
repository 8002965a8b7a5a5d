"""Independent jobs on processes forked from this one, where that pays: hole fills.

A hole's fill is Python-heavy (a triangulation, two splines, many small array steps), so
threads would queue on the interpreter lock; forked processes share the scan, its trees
and the network with the parent page by page, copy-on-write, and send back only their
results. The jobs run in order of the list given, on as many processes as numba may use
threads (``NUMBA_NUM_THREADS``; a batch worker has 1): the results are the same bits as
running them here (the network kernels already run serially in a forked child,
:func:`asrbf_mesh._network_kernels._forked`). Off Linux (fork is unsafe
with macOS's system libraries and absent on Windows), in a daemonic process (a batch
worker), with one thread, or when a worker dies, the jobs run here, one after the other.
"""

from __future__ import annotations

import multiprocessing
import os
import sys
import warnings
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from typing import Any

__all__ = ["map_forked"]

#: What the forked workers run: (function, shared state), set while a pool works.
_JOB: tuple[Callable[[Any, Any], Any], Any] | None = None
_NOT_YET = object()


def _run(items: list[Any]) -> list[Any]:
    fn, state = _JOB  # type: ignore[misc]  # set by the parent before it forked
    return [fn(state, item) for item in items]


def _die_with_parent(parent: int) -> None:
    """In a worker: end when the parent process ends (killed by ``timeout``, SIGKILL).

    A worker outlives a killed parent otherwise, and goes on filling holes nobody will
    read, on the cores and memory of whatever runs next. Linux's parent-death signal
    (``prctl(PR_SET_PDEATHSIG, SIGKILL)``); where it is not there, nothing changes.
    """
    import ctypes
    import signal

    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, int(signal.SIGKILL), 0, 0, 0)  # 1: PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        return
    if os.getppid() != parent:  # the parent ended before the signal was armed
        os._exit(1)


def workers_available() -> int:
    """How many processes :func:`map_forked` would use (1: it runs the jobs here)."""
    import numba

    # fork only on Linux: macOS's system libraries are not safe in a forked child
    if not sys.platform.startswith("linux") or multiprocessing.current_process().daemon:
        return 1
    return max(1, int(numba.get_num_threads()))


def map_forked(fn: Callable[[Any, Any], Any], state: Any, items: Sequence[Any], *,
               cost: Sequence[float] | None = None, min_items: int = 16,
               per_task: int = 4) -> list[Any]:
    """Return ``[fn(state, item) for item in items]``, computed on forked processes.

    ``state`` reaches the workers through the fork (it is never pickled); each item and
    result is. Fewer than ``min_items`` items, or one worker, run here, and each worker
    gets at least ``min_items / 2`` items (on a Kinect frame, forking two workers took
    about 25 ms, a small hole's fill about 5 ms). ``cost`` (one estimate per item)
    orders the work, the dearest first, in tasks of ``per_task`` items taken by whichever
    worker is free, so one large job does not finish alone at the end.
    """
    global _JOB
    n = len(items)
    workers = min(workers_available(), n // max(min_items // 2, 1))
    if workers < 2 or n < min_items:
        return [fn(state, item) for item in items]
    order = sorted(range(n), key=lambda i: -cost[i]) if cost is not None else list(range(n))
    tasks = [order[i:i + per_task] for i in range(0, n, per_task)]
    out: list[Any] = [_NOT_YET] * n
    _JOB = (fn, state)
    pool = ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("fork"),
                               initializer=_die_with_parent, initargs=(os.getpid(),))
    try:
        with warnings.catch_warnings():
            # Python 3.12 warns that a fork from a process with threads may deadlock: the
            # threads here (numba's, the kernels' pool) hold no lock the children take
            warnings.simplefilter("ignore", DeprecationWarning)
            done = pool.map(_run, [[items[i] for i in t] for t in tasks])
            for task, results in zip(tasks, done, strict=True):
                for i, r in zip(task, results, strict=True):
                    out[i] = r
    except BrokenProcessPool:  # a worker died (killed, out of memory): the rest here
        for i in range(n):
            if out[i] is _NOT_YET:
                out[i] = fn(state, items[i])
    finally:
        # on an interrupt, the tasks not started are dropped, not waited for
        pool.shutdown(wait=True, cancel_futures=True)
        _JOB = None
    return out
