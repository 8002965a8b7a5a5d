"""Compiled spatial queries of the tail refinement (private).

:func:`plane_slopes` measures the data's slope at some points of a piece: a least-squares
plane through each point's ``k`` nearest samples in (x, y), found in a uniform grid of
the samples (:func:`point_grid`) by rings of cells around the point's own, so no k-d tree
is built and no Python loop runs per point. :func:`spread` keeps a greedy subset of
candidates no two of which are closer than a radius, from the candidates' close pairs.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from . import _jit_cache  # noqa: F401 (first: where numba caches the kernels below)
from ._frame import bounds

#: Samples per grid cell on average (the grid's cell size follows from it).
_PER_CELL = 2.0


def point_grid(xy: np.ndarray) -> tuple[np.ndarray, float, int, int, np.ndarray, np.ndarray]:
    """Return a uniform grid of (N, 2) points: ``(lo, h, gx, gy, start, items)``.

    Cells of side ``h`` (about :data:`_PER_CELL` points each over the bounding box),
    ``gx`` x ``gy`` of them, row-major; the points of cell ``c`` are
    ``items[start[c]:start[c + 1]]``, in their order.
    """
    xy = np.ascontiguousarray(xy, dtype=np.float64)
    lo, hi = bounds(xy)
    ext = np.maximum(hi - lo, 1e-300)
    n = len(xy)
    # by area; a thin box (points on a line: no area) by its longer side
    h = max(float(np.sqrt(ext[0] * ext[1] * _PER_CELL / n)), float(ext.max()) * _PER_CELL / n)
    gx = min(int(ext[0] / h) + 1, n + 1)
    gy = min(int(ext[1] / h) + 1, n + 1)
    start, items = _bin(xy, lo, h, gx, gy)
    return lo, h, gx, gy, start, items


@njit(cache=True, nogil=True)
def _bin(xy, lo, h, gx, gy):
    n = xy.shape[0]
    cell = np.empty(n, np.int64)
    start = np.zeros(gx * gy + 1, np.int64)
    for i in range(n):
        cx = min(max(int((xy[i, 0] - lo[0]) / h), 0), gx - 1)
        cy = min(max(int((xy[i, 1] - lo[1]) / h), 0), gy - 1)
        cell[i] = cy * gx + cx
        start[cell[i] + 1] += 1
    for c in range(gx * gy):
        start[c + 1] += start[c]
    fill = start[:-1].copy()
    items = np.empty(n, np.int64)
    for i in range(n):  # stable: each cell keeps the points' order
        items[fill[cell[i]]] = i
        fill[cell[i]] += 1
    return start, items


@njit(cache=True, inline="always")
def _nearest(xy, q, k, lo, h, gx, gy, start, items, best_d, best_i):
    """Find the ``k`` nearest points of point ``q`` (itself among them); returns how many.

    Cells are visited ring by ring around q's cell; after ring r every point not yet
    seen lies farther than r * h, so the search stops once k points are held and the
    k-th is within that. Ties keep the point met first (rings, then the cells' order).
    """
    x = xy[q, 0]
    y = xy[q, 1]
    cx = min(max(int((x - lo[0]) / h), 0), gx - 1)
    cy = min(max(int((y - lo[1]) / h), 0), gy - 1)
    held = 0
    r = 0
    rmax = max(gx, gy)
    while r <= rmax:
        for yy in range(cy - r, cy + r + 1):
            if yy < 0 or yy >= gy:
                continue
            ring_row = yy == cy - r or yy == cy + r
            step = 1 if ring_row else 2 * r
            xx = cx - r
            while xx <= cx + r:
                if 0 <= xx < gx:
                    c = yy * gx + xx
                    for t in range(start[c], start[c + 1]):
                        j = items[t]
                        dx = xy[j, 0] - x
                        dy = xy[j, 1] - y
                        d = dx * dx + dy * dy
                        if held < k or d < best_d[held - 1]:
                            p = held if held < k else k - 1
                            while p > 0 and best_d[p - 1] > d:  # insertion, stable
                                best_d[p] = best_d[p - 1]
                                best_i[p] = best_i[p - 1]
                                p -= 1
                            best_d[p] = d
                            best_i[p] = j
                            if held < k:
                                held += 1
                xx += step
        if held == k and best_d[k - 1] <= (r * h) * (r * h):
            break
        r += 1
    return held


@njit(cache=True, parallel=True, nogil=True)
def plane_slopes(xy, z, at, k, ratio_x, ratio_y, lo, h, gx, gy, start, items):
    """Squared slope of the plane through each point ``at[m]``'s ``k`` nearest samples.

    The plane ``z = c + s . (x - mean)`` by least squares over the samples (its 2 x 2
    normal matrix ridged by 1e-12), ``s`` scaled by ``(ratio_x, ratio_y)`` (depth over
    the xy scales: physical proportions); returns ``|s|^2`` per point.
    """
    m = at.shape[0]
    out = np.empty(m)
    for i in prange(m):
        best_d = np.empty(k)
        best_i = np.empty(k, np.int64)
        held = _nearest(xy, at[i], k, lo, h, gx, gy, start, items, best_d, best_i)
        mx = 0.0
        my = 0.0
        mz = 0.0
        for t in range(held):
            mx += xy[best_i[t], 0]
            my += xy[best_i[t], 1]
            mz += z[best_i[t]]
        mx /= held
        my /= held
        mz /= held
        sxx = 1e-12
        syy = 1e-12
        sxy = 0.0
        sxz = 0.0
        syz = 0.0
        for t in range(held):
            dx = xy[best_i[t], 0] - mx
            dy = xy[best_i[t], 1] - my
            dz = z[best_i[t]] - mz
            sxx += dx * dx
            syy += dy * dy
            sxy += dx * dy
            sxz += dx * dz
            syz += dy * dz
        det = sxx * syy - sxy * sxy
        sx = (syy * sxz - sxy * syz) / det * ratio_x
        sy = (sxx * syz - sxy * sxz) / det * ratio_y
        out[i] = sx * sx + sy * sy
    return out


@njit(cache=True, nogil=True)
def _greedy(n, pairs):
    """Greedy independent set in candidate order, given the close pairs (i < j)."""
    deg = np.zeros(n + 1, np.int64)
    for p in range(pairs.shape[0]):
        deg[pairs[p, 0] + 1] += 1
        deg[pairs[p, 1] + 1] += 1
    for i in range(n):
        deg[i + 1] += deg[i]
    fill = deg[:-1].copy()
    adj = np.empty(deg[n], np.int64)
    for p in range(pairs.shape[0]):
        a = pairs[p, 0]
        b = pairs[p, 1]
        adj[fill[a]] = b
        fill[a] += 1
        adj[fill[b]] = a
        fill[b] += 1
    blocked = np.zeros(n, np.bool_)
    keep = np.empty(n, np.int64)
    kept = 0
    for i in range(n):
        if not blocked[i]:
            keep[kept] = i
            kept += 1
            for t in range(deg[i], deg[i + 1]):
                blocked[adj[t]] = True
    return keep[:kept]


def spread(xy: np.ndarray, radius: float) -> np.ndarray:
    """Return a greedy subset of ``xy`` (indices, in its order), no two within ``radius``.

    Each point is kept unless a point kept before it lies within ``radius``.

    Examples
    --------
    >>> spread(np.array([[0.0, 0.0], [0.5, 0.0], [2.0, 0.0], [1.2, 0.0]]), 1.0).tolist()
    [0, 2]
    """
    from scipy.spatial import cKDTree

    if len(xy) == 0:
        return np.zeros(0, dtype=np.int64)
    pairs = cKDTree(xy).query_pairs(radius, output_type="ndarray").astype(np.int64)
    return _greedy(len(xy), pairs.reshape(-1, 2))
