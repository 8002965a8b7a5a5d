"""Isolated points: stray returns far from every other point of a scan.

One stray point (a range sensor's multipath return, a corrupt line in an XYZ file) used to
ruin a fit silently: the frame normalizes each axis by the scan's extent, so a point at
z = 10⁶ squeezes the real surface into a sliver of the unit cube (a 100 × 100 surface of
amplitude ±1 fitted with RMS 1,651–4,545 over seeds 0–2 instead of 0.005–0.006).
:func:`isolated_points` finds such points so that :func:`~asrbf_mesh.fit` can leave them
out of the frame and the surface, and say so.

The rule is geometric and scale-free. Each coordinate is first divided by its *robust*
extent, the range between its 1st and 99th percentiles (so that the strays do not inflate
it; an axis with no such range takes the largest of the others), as the fit's own frame
normalizes each axis. Then a point is isolated when its ``k``-th nearest neighbour
(``k = 3``: a pair or a triple of strays is isolated too) lies farther than
``distance_rel`` (15 %) of the diagonal of that robust box, and farther than
``DENSITY_FACTOR`` (20) times the median of that distance over the scan (so that a sparse
scan, a hundred points scattered over the square, keeps its corners).

On the scans shipped and benchmarked here (the face map, the four Stanford bunny scans,
the bunny crop) the farthest real point reaches at most 0.46 of the threshold (bun090, in
3D; 0.17 in the view plane), so the rule flags no point of a real scan and a clean scan
fits exactly as before.

Most points never need their neighbours measured: a point with ``k`` others within the
threshold is not isolated, and when more than half of the points have ``k`` others within
the threshold / ``DENSITY_FACTOR``, the median cannot raise the threshold. Both are
counted on grids of cells as wide as those radii (a compiled kernel, own cell first,
stopping at the ``k``-th); only the points left in doubt (none on a real scan) and
scans that fail the median test (sparse ones) go to the k-d tree. The same answers as
the k-d tree over every point (tests); on the face map 19 ms instead of 100.
"""

from __future__ import annotations

import itertools

import numpy as np
from numba import njit
from scipy.spatial import cKDTree

from . import _jit_cache  # noqa: F401 (first: where numba caches the kernels below)
from ._validate import check_float, check_int, plural

__all__ = ["OutlierWarning", "isolated_points", "describe_isolated",
           "NEIGHBOURS", "DISTANCE_REL", "DENSITY_FACTOR"]

#: The neighbour whose distance decides (a group of up to this many strays is isolated).
NEIGHBOURS = 3
#: Isolated: the k-th neighbour farther than this fraction of the robust diagonal ...
DISTANCE_REL = 0.15
#: ... and farther than this many times the scan's median k-th neighbour distance.
DENSITY_FACTOR = 20.0


class OutlierWarning(UserWarning):
    """Isolated points were left out of a fit (how many, and where)."""


def robust_box(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Lower corner and per-axis extent of the box between the 1st and 99th percentiles.

    An axis without extent takes the largest extent of the others (all zero: ones).
    """
    lo, hi = np.quantile(points, [0.01, 0.99], axis=0)
    ext = hi - lo
    top = float(ext.max()) if ext.size else 0.0
    ext = np.where(ext > 0, ext, top if top > 0 else 1.0)
    return lo, ext


def isolated_points(points: np.ndarray, *, neighbours: int = NEIGHBOURS,
                    distance_rel: float = DISTANCE_REL, workers: int = 1) -> np.ndarray:
    """Return the mask of the isolated points of a scan, (N,) bool.

    Parameters
    ----------
    points : (N, 3) float array
        Finite scan points, world units.
    neighbours : int
        ``k``: a point is judged by the distance to its ``k``-th nearest other point.
    distance_rel : float
        Threshold, a fraction of the robust bounding-box diagonal (see the module notes).
    workers : int
        Threads of the neighbour queries (one: :func:`~asrbf_mesh.fit` runs this beside
        the segmentation; the footprint of fill-holes, alone, takes numba's count).

    Returns
    -------
    (N,) bool array
        True for isolated points. All False for scans of at most ``neighbours + 1``
        points.

    Examples
    --------
    >>> xy = np.stack(np.meshgrid(np.arange(20.0), np.arange(20.0)), -1).reshape(-1, 2)
    >>> pts = np.c_[xy, np.sin(xy[:, 0] / 3)]
    >>> pts[7, 2] = 1e6
    >>> np.flatnonzero(isolated_points(pts)).tolist()
    [7]
    """
    k = check_int(neighbours, "neighbours", 1)
    rel = check_float(distance_rel, "distance_rel", low=0.0, low_open=True)
    p = np.asarray(points, dtype=np.float64)
    n = len(p)
    if n <= k + 1:
        return np.zeros(n, dtype=bool)
    lo, ext = robust_box(p)
    u = (p - lo) / ext  # each axis in units of its robust extent, as the frame does
    bound = rel * float(np.sqrt(u.shape[1]))  # of the robust box's diagonal
    # the threshold is max(bound, DENSITY_FACTOR x the median k-th distance): when more
    # than half of the points have k others within bound / DENSITY_FACTOR, the median
    # cannot raise it, and a point with k others within the bound is not isolated (both
    # counted on grids, _crowded). Only the others need their neighbours measured (none
    # on a real scan)
    fine = _crowded(u, bound / DENSITY_FACTOR, k)
    if 2 * int(fine.sum()) > n:
        doubt = np.flatnonzero(~fine)
        doubt = doubt[~_crowded(u, bound, k, doubt)]
        out = np.zeros(n, dtype=bool)
        if len(doubt):
            dist, _ = cKDTree(u).query(u[doubt], k=k + 1, workers=workers)
            out[doubt] = dist[:, -1] > bound
        return out
    dist, _ = cKDTree(u).query(u, k=k + 1, workers=workers)
    dk = dist[:, -1]
    return dk > max(bound, DENSITY_FACTOR * float(np.median(dk)))


#: Cell coordinates beyond this (in cells, either sign) are not binned: such a point is
#: judged by its neighbours through the k-d tree (:func:`_crowded` says False for it).
_CELL_RANGE = 1 << 19


def _crowded(u: np.ndarray, radius: float, k: int, at: np.ndarray | None = None
             ) -> np.ndarray:
    """Whether points have ``k`` others within 0.999 x ``radius`` (Euclidean).

    For every point, or for the points ``at`` (then one answer each). Through a grid of
    cells as wide as that radius (a neighbour that near is in one of the 3^d cells
    around), own cell first, stopping at the ``k``-th: on a scan, a few distances per
    point. The 0.1 % keeps the answer clear of the k-d tree's rounding. Points farther
    than :data:`_CELL_RANGE` cells from the origin are not binned (nor found as
    neighbours): False, which only sends points to the exact search.
    """
    n, d = u.shape
    at = np.arange(n) if at is None else np.asarray(at, dtype=np.int64)
    r = 0.999 * radius
    if not r > 0 or d > 3:
        return np.zeros(len(at), dtype=bool)
    offsets = np.array(list(itertools.product((0, -1, 1), repeat=d)), dtype=np.int64)
    strides = (2 * _CELL_RANGE) ** np.arange(d - 1, -1, -1, dtype=np.int64)
    return _near_enough(np.ascontiguousarray(u, np.float64), at, r, k, offsets @ strides,
                        _CELL_RANGE)


@njit(cache=True, nogil=True)
def _near_enough(u, at, r, k, steps, span):
    """Count neighbours within ``r`` of the points ``at``, up to ``k`` (:func:`_crowded`).

    ``steps`` are the key offsets of the cells around a cell (its own first) for keys of
    ``2 span`` values per axis.
    """
    n, d = u.shape
    key = np.zeros(n, dtype=np.int64)
    inside = np.ones(n, dtype=np.bool_)
    for i in range(n):
        for a in range(d):
            c = np.floor(u[i, a] / r)
            if not abs(c) < span - 1:  # NaN included
                inside[i] = False
                key[i] = 0
                break
            key[i] = key[i] * (2 * span) + np.int64(c) + span
    order = np.argsort(key)  # (any order within a cell gives the same answer)
    sorted_keys = key[order]
    r2 = r * r
    out = np.zeros(len(at), dtype=np.bool_)
    for q in range(len(at)):
        i = at[q]
        if not inside[i]:
            continue
        found = 0
        for s in steps:
            want = key[i] + s
            t = np.searchsorted(sorted_keys, want)
            while t < n and sorted_keys[t] == want and found < k:
                j = order[t]
                t += 1
                if j == i or not inside[j]:
                    continue
                dist2 = 0.0
                for a in range(d):
                    diff = u[i, a] - u[j, a]
                    dist2 += diff * diff
                if dist2 <= r2:
                    found += 1
            if found >= k:
                break
        out[q] = found >= k
    return out


def describe_isolated(points: np.ndarray, mask: np.ndarray, name: str = "") -> str:
    """One line for an :class:`OutlierWarning`: how many, what share, the farthest one."""
    n_out = int(mask.sum())
    inliers = points[~mask]
    centre = np.median(inliers, axis=0) if len(inliers) else np.zeros(3)
    out = points[mask]
    far = out[np.argmax(np.linalg.norm(out - centre, axis=1))]
    where = ", ".join(f"{v:.6g}" for v in far)
    return (f"{name}{plural(n_out, 'isolated point')} ({100.0 * n_out / len(points):.3g} % "
            f"of the scan, far from every other point) left "
            f"out of the frame and the fit; {'the farthest ' if n_out > 1 else ''}at "
            f"({where})")
