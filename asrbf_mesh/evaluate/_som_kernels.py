"""Compiled online training of a Kohonen SOM (numba, ``cache=True``).

The algorithm is MiniSom's (rectangular grid, Gaussian neighbourhood, Euclidean
winner, asymptotic decay of radius and rate, ``w += eta h (x - w)`` on every node), run
in one compiled loop instead of one Python call per step: 40-60 times faster at the
baseline's grid sizes (see :func:`asrbf_mesh.evaluate._som.train_som`), and equal to
MiniSom's weights to round-off (``tests/test_som.py`` checks it against MiniSom).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .. import _jit_cache  # noqa: F401 (first: where numba caches the kernels below)


@njit(cache=True)
def train_online(w: np.ndarray, x: np.ndarray, order: np.ndarray, start: int, stop: int,
                 total: int, sigma: float, eta0: float) -> None:  # pragma: no cover - numba
    """Run steps ``start .. stop - 1`` of ``total`` online SOM steps, in place.

    Parameters
    ----------
    w : (rows, cols, 3) float64 array
        Node weights, updated in place.
    x : (N, 3) float64 array
        Training points.
    order : (total,) int64 array
        The point learned at each step.
    start, stop, total : int
        Step range and the schedule's length ``T``.
    sigma, eta0 : float
        Initial neighbourhood radius (cells) and learning rate; both are divided by
        ``1 + t / (T / 2)`` at step ``t`` (MiniSom's ``asymptotic_decay``).
    """
    rows, cols = w.shape[0], w.shape[1]
    gi = np.empty(rows)
    gj = np.empty(cols)
    half = total / 2
    for t in range(start, stop):
        p = order[t]
        x0, x1, x2 = x[p, 0], x[p, 1], x[p, 2]
        # winner: the first node of least Euclidean distance, row-major order
        best = math.inf
        ci = 0
        cj = 0
        for i in range(rows):
            for j in range(cols):
                d0 = x0 - w[i, j, 0]
                d1 = x1 - w[i, j, 1]
                d2 = x2 - w[i, j, 2]
                d = d0 * d0 + d1 * d1 + d2 * d2
                if d < best:
                    best = d
                    ci = i
                    cj = j
        decay = 1 + t / half
        eta = eta0 / decay
        sig = sigma / decay
        den = 2 * sig * sig
        for i in range(rows):
            gi[i] = math.exp(-((i - ci) ** 2) / den)
        for j in range(cols):
            gj[j] = math.exp(-((j - cj) ** 2) / den)
        for i in range(rows):
            if gi[i] == 0.0:  # every update of this row would add exactly zero
                continue
            for j in range(cols):
                g = gi[i] * gj[j] * eta
                w[i, j, 0] += g * (x0 - w[i, j, 0])
                w[i, j, 1] += g * (x1 - w[i, j, 1])
                w[i, j, 2] += g * (x2 - w[i, j, 2])
