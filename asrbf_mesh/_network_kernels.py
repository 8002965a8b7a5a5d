"""Compiled evaluation of a fixed Gaussian RBF network (private).

A static grid over the evaluation box holds, per cell, the neurons whose
truncated support (``support * sigma``) meets the cell, in CSR form. Cell
indices are clamped, so border cells also hold every neuron reaching beyond the
box and points outside the box are still evaluated exactly.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange


@njit(cache=True, inline="always")
def _cell(v, lo, h, g):
    c = int(np.floor((v - lo) / h))
    if c < 0:
        return 0
    if c >= g:
        return g - 1
    return c


@njit(cache=True, inline="always")
def _locate(pts, i, lo, h, g):
    """Point i (x, y) and the index of its grid cell."""
    x = pts[i, 0]
    y = pts[i, 1]
    return x, y, _cell(y, lo[1], h, g) * g + _cell(x, lo[0], h, g)


@njit(cache=True, inline="always")
def _offset(x, y, centers, widths, j):
    """Offset (dx, dy) of a point from neuron j, its squared length d2 and sigma_j^2."""
    dx = x - centers[j, 0]
    dy = y - centers[j, 1]
    return dx, dy, dx * dx + dy * dy, widths[j] * widths[j]


@njit(cache=True)
def build_grid(centers, widths, support, lo, h, g):
    """CSR lists ``(start, items)`` of the neurons meeting each of the g x g cells."""
    k = centers.shape[0]
    counts = np.zeros(g * g + 1, np.int64)
    for n in range(2):  # pass 0 counts, pass 1 fills
        if n == 1:
            for c in range(g * g):
                counts[c + 1] += counts[c]
            items = np.empty(counts[g * g], np.int64)
            fill = counts[:-1].copy()
        for j in range(k):
            s = support * widths[j]
            x0 = _cell(centers[j, 0] - s, lo[0], h, g)
            x1 = _cell(centers[j, 0] + s, lo[0], h, g)
            y0 = _cell(centers[j, 1] - s, lo[1], h, g)
            y1 = _cell(centers[j, 1] + s, lo[1], h, g)
            for cy in range(y0, y1 + 1):
                for cx in range(x0, x1 + 1):
                    c = cy * g + cx
                    if n == 0:
                        counts[c + 1] += 1
                    else:
                        items[fill[c]] = j
                        fill[c] += 1
    return counts, items


_FAST = {"reassoc", "contract", "nsz", "arcp"}  # no nnan/ninf: inputs are clamped instead


@njit(cache=True, inline="always", fastmath=_FAST)
def _exp_neg(t):
    """exp(-t) for 0 <= t <= 40 by a degree-11 Taylor polynomial of exp(-t/32), squared 5 times.

    Pure arithmetic, so loops over it vectorize; relative error < 1e-12 on [0, 12.25].
    """
    y = -t * 0.03125
    p = 2.505210838544172e-08
    p = p * y + 2.755731922398589e-07
    p = p * y + 2.7557319223985893e-06
    p = p * y + 2.48015873015873e-05
    p = p * y + 0.0001984126984126984
    p = p * y + 0.001388888888888889
    p = p * y + 0.008333333333333333
    p = p * y + 0.041666666666666664
    p = p * y + 0.16666666666666666
    p = p * y + 0.5
    p = p * y + 1.0
    p = p * y + 1.0
    p = p * p
    p = p * p
    p = p * p
    p = p * p
    return p * p


@njit(cache=True)
def pack_cells(centers, widths, weights, items):
    """Neuron parameters in cell-list order (cx, cy, 1/sigma^2, a): contiguous per cell."""
    n = items.shape[0]
    out = np.empty((4, n))
    for p in range(n):
        j = items[p]
        out[0, p] = centers[j, 0]
        out[1, p] = centers[j, 1]
        out[2, p] = 1.0 / (widths[j] * widths[j])
        out[3, p] = weights[j]
    return out


#: Below this many points :func:`evaluate_values` runs on one thread: waking the thread
#: pool costs more than it saves, and much more on a loaded machine (1,000 points: 0.16 ms
#: on one thread, 2.0 ms on two with the other core busy). Same values either way.
SERIAL_BELOW = 8192


@njit(cache=True, fastmath=_FAST, inline="always")
def _value_at(pts, i, a0, packed, supp2, lo, h, g, start):
    """Value of f at point ``i``: a branch-free, gather-free loop over its cell's neurons."""
    x, y, c = _locate(pts, i, lo, h, g)
    f = 0.0
    for p in range(start[c], start[c + 1]):
        dx = x - packed[0, p]
        dy = y - packed[1, p]
        t = (dx * dx + dy * dy) * packed[2, p]
        v = packed[3, p] * _exp_neg(min(t, 40.0))
        f += v if t < supp2 else 0.0
    return a0 + f


@njit(cache=True, parallel=True, fastmath=_FAST)
def _values_parallel(pts, a0, packed, support, lo, h, g, start):
    out = np.empty(pts.shape[0])
    for i in prange(pts.shape[0]):
        out[i] = _value_at(pts, i, a0, packed, support * support, lo, h, g, start)
    return out


@njit(cache=True, fastmath=_FAST)
def _values_serial(pts, a0, packed, support, lo, h, g, start):
    out = np.empty(pts.shape[0])
    for i in range(pts.shape[0]):
        out[i] = _value_at(pts, i, a0, packed, support * support, lo, h, g, start)
    return out


def evaluate_values(pts, a0, packed, support, lo, h, g, start):
    """Evaluate f (M,) at unit-square points (M, 2) (threads from :data:`SERIAL_BELOW` up)."""
    kernel = _values_serial if pts.shape[0] < SERIAL_BELOW else _values_parallel
    return kernel(pts, a0, packed, support, lo, h, g, start)


@njit(cache=True, parallel=True)
def evaluate_with_gradient(pts, a0, centers, widths, weights, support, lo, h, g, start, items):
    """Evaluate f (M,) and its gradient df/dx, df/dy (M, 2) at unit-square points (M, 2)."""
    m = pts.shape[0]
    out = np.empty(m)
    grad = np.empty((m, 2))
    supp2 = support * support
    for i in prange(m):
        x, y, c = _locate(pts, i, lo, h, g)
        f = a0
        gx = 0.0
        gy = 0.0
        for p in range(start[c], start[c + 1]):
            j = items[p]
            dx, dy, d2, s2 = _offset(x, y, centers, widths, j)
            if d2 < supp2 * s2:
                v = weights[j] * np.exp(-d2 / s2)
                f += v
                gx -= 2.0 * v * dx / s2
                gy -= 2.0 * v * dy / s2
        out[i] = f
        grad[i, 0] = gx
        grad[i, 1] = gy
    return out, grad


@njit(cache=True, parallel=True)
def design_rows(pts, centers, widths, weights, support, lo, h, g, start, items, full):
    """Sparse Jacobian of f at ``pts`` in CSR form ``(indptr, indices, data)``.

    Column 0 is the bias a0 (ones). With ``full=False`` column 1 + k is the weight
    a_k; with ``full=True`` four columns per neuron, (a, log sigma, ux, uy) at
    1 + 4k .. 4 + 4k.
    """
    m = pts.shape[0]
    supp2 = support * support
    per = 4 if full else 1
    indptr = np.zeros(m + 1, np.int64)
    for i in range(m):
        x, y, c = _locate(pts, i, lo, h, g)
        cnt = 1
        for p in range(start[c], start[c + 1]):
            _, _, d2, s2 = _offset(x, y, centers, widths, items[p])
            if d2 < supp2 * s2:  # the same test as the fill below, to the last bit
                cnt += per
        indptr[i + 1] = indptr[i] + cnt
    nnz = indptr[m]
    cols = np.empty(nnz, np.int64)
    vals = np.empty(nnz)
    for i in prange(m):
        x, y, c = _locate(pts, i, lo, h, g)
        n = indptr[i]
        cols[n] = 0
        vals[n] = 1.0
        n += 1
        for p in range(start[c], start[c + 1]):
            j = items[p]
            dx, dy, d2, s2 = _offset(x, y, centers, widths, j)
            if d2 < supp2 * s2:
                phi = np.exp(-d2 / s2)
                if full:
                    ap = weights[j] * phi
                    cols[n] = 4 * j + 1
                    cols[n + 1] = 4 * j + 2
                    cols[n + 2] = 4 * j + 3
                    cols[n + 3] = 4 * j + 4
                    vals[n] = phi
                    vals[n + 1] = 2.0 * ap * d2 / s2
                    vals[n + 2] = 2.0 * ap * dx / s2
                    vals[n + 3] = 2.0 * ap * dy / s2
                    n += 4
                else:
                    cols[n] = j + 1
                    vals[n] = phi
                    n += 1
    return indptr, cols, vals
