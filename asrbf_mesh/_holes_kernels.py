"""Compiled helpers of hole filling (private): triangle coverage raster, point location."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def _orient(ax, ay, bx, by, cx, cy):
    return (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)


@njit(cache=True)
def coverage(xy, faces, lo, cell, nx, ny):
    """Raster (ny, nx) of cells whose centre lies in (or on) some triangle, in xy."""
    out = np.zeros((ny, nx), np.bool_)
    for t in range(faces.shape[0]):
        a = faces[t, 0]
        b = faces[t, 1]
        c = faces[t, 2]
        ax, ay = xy[a, 0], xy[a, 1]
        bx, by = xy[b, 0], xy[b, 1]
        cx, cy = xy[c, 0], xy[c, 1]
        area = _orient(ax, ay, bx, by, cx, cy)
        if area == 0.0:
            continue
        eps = -1e-9 * abs(area)
        i0 = max(int(np.floor((min(ax, bx, cx) - lo[0]) / cell - 0.5)), 0)
        i1 = min(int(np.ceil((max(ax, bx, cx) - lo[0]) / cell - 0.5)), nx - 1)
        j0 = max(int(np.floor((min(ay, by, cy) - lo[1]) / cell - 0.5)), 0)
        j1 = min(int(np.ceil((max(ay, by, cy) - lo[1]) / cell - 0.5)), ny - 1)
        s = 1.0 if area > 0 else -1.0
        for j in range(j0, j1 + 1):
            py = lo[1] + (j + 0.5) * cell
            for i in range(i0, i1 + 1):
                px = lo[0] + (i + 0.5) * cell
                w0 = s * _orient(bx, by, cx, cy, px, py)
                w1 = s * _orient(cx, cy, ax, ay, px, py)
                w2 = s * _orient(ax, ay, bx, by, px, py)
                if w0 >= eps and w1 >= eps and w2 >= eps:
                    out[j, i] = True
    return out


@njit(cache=True)
def inside_any(points, xy, faces, cand):
    """For each point p, whether it lies strictly inside one of the candidate triangles cand[p]."""
    n = points.shape[0]
    out = np.zeros(n, np.bool_)
    for p in range(n):
        px, py = points[p, 0], points[p, 1]
        for k in range(cand.shape[1]):
            t = cand[p, k]
            if t < 0:
                continue
            a = faces[t, 0]
            b = faces[t, 1]
            c = faces[t, 2]
            area = _orient(xy[a, 0], xy[a, 1], xy[b, 0], xy[b, 1], xy[c, 0], xy[c, 1])
            if area == 0.0:
                continue
            s = 1.0 if area > 0 else -1.0
            eps = 1e-9 * abs(area)
            w0 = s * _orient(xy[b, 0], xy[b, 1], xy[c, 0], xy[c, 1], px, py)
            w1 = s * _orient(xy[c, 0], xy[c, 1], xy[a, 0], xy[a, 1], px, py)
            w2 = s * _orient(xy[a, 0], xy[a, 1], xy[b, 0], xy[b, 1], px, py)
            if w0 > eps and w1 > eps and w2 > eps:
                out[p] = True
                break
    return out
