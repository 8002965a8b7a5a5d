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


@njit(cache=True, parallel=True)
def evaluate(pts, a0, centers, widths, weights, support, lo, h, g, start, items, want_grad):
    """F (M,) and, if ``want_grad``, df/dx, df/dy (M, 2) at unit-square points (M, 2)."""
    m = pts.shape[0]
    out = np.empty(m)
    grad = np.zeros((m if want_grad else 0, 2))
    supp2 = support * support
    for i in prange(m):
        x = pts[i, 0]
        y = pts[i, 1]
        c = _cell(y, lo[1], h, g) * g + _cell(x, lo[0], h, g)
        f = a0
        gx = 0.0
        gy = 0.0
        for p in range(start[c], start[c + 1]):
            j = items[p]
            dx = x - centers[j, 0]
            dy = y - centers[j, 1]
            d2 = dx * dx + dy * dy
            s2 = widths[j] * widths[j]
            if d2 < supp2 * s2:
                v = weights[j] * np.exp(-d2 / s2)
                f += v
                if want_grad:
                    gx -= 2.0 * v * dx / s2
                    gy -= 2.0 * v * dy / s2
        out[i] = f
        if want_grad:
            grad[i, 0] = gx
            grad[i, 1] = gy
    return out, grad


@njit(cache=True)
def design_rows(pts, centers, widths, weights, support, lo, h, g, start, items, full):
    """Sparse Jacobian of f at ``pts`` in COO form.

    With ``full=False`` the columns are the weights a_k (column k); with
    ``full=True`` four columns per neuron: (a, log sigma, ux, uy) at 4k..4k+3.
    The bias a0 (a column of ones) is left to the caller.
    """
    m = pts.shape[0]
    supp2 = support * support
    per = 4 if full else 1
    nnz = 0
    for i in range(m):
        x = pts[i, 0]
        y = pts[i, 1]
        c = _cell(y, lo[1], h, g) * g + _cell(x, lo[0], h, g)
        for p in range(start[c], start[c + 1]):
            j = items[p]
            dx = x - centers[j, 0]
            dy = y - centers[j, 1]
            if dx * dx + dy * dy < supp2 * widths[j] * widths[j]:
                nnz += per
    rows = np.empty(nnz, np.int64)
    cols = np.empty(nnz, np.int64)
    vals = np.empty(nnz)
    n = 0
    for i in range(m):
        x = pts[i, 0]
        y = pts[i, 1]
        c = _cell(y, lo[1], h, g) * g + _cell(x, lo[0], h, g)
        for p in range(start[c], start[c + 1]):
            j = items[p]
            dx = x - centers[j, 0]
            dy = y - centers[j, 1]
            d2 = dx * dx + dy * dy
            s2 = widths[j] * widths[j]
            if d2 < supp2 * s2:
                phi = np.exp(-d2 / s2)
                if full:
                    ap = weights[j] * phi
                    rows[n:n + 4] = i
                    cols[n] = 4 * j
                    cols[n + 1] = 4 * j + 1
                    cols[n + 2] = 4 * j + 2
                    cols[n + 3] = 4 * j + 3
                    vals[n] = phi
                    vals[n + 1] = 2.0 * ap * d2 / s2
                    vals[n + 2] = 2.0 * ap * dx / s2
                    vals[n + 3] = 2.0 * ap * dy / s2
                    n += 4
                else:
                    rows[n] = i
                    cols[n] = j
                    vals[n] = phi
                    n += 1
    return rows, cols, vals
