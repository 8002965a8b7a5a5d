"""BLAS on one thread while a fit runs (the numba kernels own the cores).

OpenBLAS workers spin for a while after each threaded call (up to about 0.1 s) before
they sleep: a threaded matrix-vector product or factorization between two parallel
numba kernels left them spinning on the cores those kernels wanted. The fits' dense
algebra is small (normal equations of at most a few thousand neurons), so the fits run
BLAS on one thread. Measured on the face map (seeds 0-4, the fastest of 3 alternating
fits each): the piecewise fit 0.53-0.56 s with BLAS threaded outside its LAPACK calls,
0.46-0.48 s on one thread (the residual after the idle neurons' drop 11 -> 3 ms, a
1,000-neuron ``w' A'A w`` 5 -> 0.3 ms), the single network 0.41-0.44 s either way; the
networks are the same bytes (face map, bun000, bun090, seeds 0-1, both models).

The limit is process-wide (threadpoolctl), so it is counted: the first fit or solve to
enter sets it, the last to leave restores what was there, whatever the order in which
threads leave (two pieces polished on two threads, fits on several threads at once).
"""

from __future__ import annotations

import contextlib
import functools
import threading
from collections.abc import Iterator
from typing import Any

__all__ = ["one_blas_thread"]

_LOCK = threading.Lock()
_STATE: dict[str, Any] = {"depth": 0, "limiter": None}


@functools.cache
def _controller() -> Any:
    """Return the process's BLAS libraries, inspected once (an inspection costs 1-2 ms)."""
    from threadpoolctl import ThreadpoolController

    return ThreadpoolController()


@contextlib.contextmanager
def one_blas_thread() -> Iterator[None]:
    """Run the block with BLAS on one thread; nested and concurrent blocks share the limit.

    Examples
    --------
    >>> import numpy as np
    >>> from threadpoolctl import threadpool_info
    >>> before = [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]
    >>> with one_blas_thread():
    ...     with one_blas_thread():
    ...         inner = {i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"}
    >>> inner <= {1}
    True
    >>> [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"] == before
    True
    """
    with _LOCK:
        if _STATE["depth"] == 0:
            _STATE["limiter"] = _controller().limit(limits=1, user_api="blas")
        _STATE["depth"] += 1
    try:
        yield
    finally:
        with _LOCK:
            _STATE["depth"] -= 1
            if _STATE["depth"] == 0:
                _STATE["limiter"].restore_original_limits()
                _STATE["limiter"] = None
