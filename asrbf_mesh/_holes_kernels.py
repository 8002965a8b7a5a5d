"""Compiled helpers of hole filling (private): triangle coverage raster, point location.

Numba does not check array bounds: an index past an array reads or writes whatever
memory lies there, and the process dies with a segmentation fault (a cKDTree query with
``k=1`` returns a 1-D index array, which ``np.atleast_2d`` turned into one row for all
points: bun090's punched seed 6 crashed that way). So the kernels are private and the
public functions check shapes and index ranges first.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from . import _jit_cache  # noqa: F401 (first: where numba caches the kernels below)


@njit(cache=True)
def _orient(ax, ay, bx, by, cx, cy):
    return (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)


def _faces_in(xy: np.ndarray, faces: np.ndarray, what: str) -> tuple[np.ndarray, np.ndarray]:
    """Return ``xy`` (V, 2) float64 and ``faces`` (F, 3) int64, checked to index ``xy``."""
    xy = np.ascontiguousarray(xy, dtype=np.float64)
    faces = np.ascontiguousarray(faces, dtype=np.int64).reshape(-1, 3)
    if xy.ndim != 2 or xy.shape[1] != 2:
        raise ValueError(f"{what}: points must have shape (V, 2), got {xy.shape}")
    if len(faces) and (faces.min() < 0 or faces.max() >= len(xy)):
        raise ValueError(f"{what}: a triangle indexes a point that does not exist")
    return xy, faces


def coverage(xy: np.ndarray, faces: np.ndarray, lo: np.ndarray, cell: float, nx: int,
             ny: int) -> np.ndarray:
    """Raster (ny, nx) of cells whose centre lies in (or on) some triangle, in xy.

    Raises
    ------
    ValueError
        A triangle indexing a missing point, a bad raster size or cell.
    """
    xy, faces = _faces_in(xy, faces, "coverage")
    if not (int(nx) >= 1 and int(ny) >= 1 and np.isfinite(cell) and cell > 0):
        raise ValueError("coverage: the raster needs nx, ny >= 1 and a positive cell")
    return _coverage(xy, faces, np.ascontiguousarray(lo, dtype=np.float64), float(cell),
                     int(nx), int(ny))


def inside_any(points: np.ndarray, xy: np.ndarray, faces: np.ndarray,
               cand: np.ndarray) -> np.ndarray:
    """For each point, whether it lies strictly inside one of its candidate triangles.

    ``cand`` holds each point's candidate triangle indices, (M, k) or (M,) as a
    ``cKDTree.query`` returns them for ``k`` = 1; an index past the last triangle
    (``cKDTree``'s "no neighbour") or below 0 is skipped.
    """
    points = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 2)
    xy, faces = _faces_in(xy, faces, "inside_any")
    cand = np.asarray(cand, dtype=np.int64).reshape(len(points), -1)
    cand = np.where((cand >= 0) & (cand < len(faces)), cand, -1)
    return _inside_any(points, xy, faces, np.ascontiguousarray(cand))


@njit(cache=True)
def _coverage(xy, faces, lo, cell, nx, ny):
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
def _inside_any(points, xy, faces, cand):
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
