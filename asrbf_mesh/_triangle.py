"""The one door to the ``triangle`` library: input it cannot take never reaches it.

``triangle`` (Shewchuk's Triangle through its Python wrapper) is fast and exact, but it
crashes the process or loops forever on some inputs (:func:`triangulate` lists them) and
prints with C's printf when it refuses one. Every call goes through here: the input is
checked and cleaned first, and what it prints goes to the null device.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import sys
import threading
from collections.abc import Iterator

import numpy as np

from . import _holes_kernels as _hk

__all__ = ["delaunay", "squared_edges", "triangulate"]


def triangulate(pts: np.ndarray, seg: np.ndarray, flags: str) -> tuple[np.ndarray, np.ndarray]:
    """Constrained triangulation; returns (triangles, vertices triangle had to add).

    The one door to the ``triangle`` library, which crashes the process or raises from its
    wrapper on input it cannot take: points all on one line (SIGSEGV), an empty segment
    list with the ``p`` switch (IndexError; a rim whose every edge crossed another), fewer
    than three points; copies of a point (exact, or within 1e-9 of the extent) joined by
    segments, or a segment given twice (an endless loop), a point within rounding of a
    segment's inside but off it to triangle's exact tests (it inserts the crossings next
    to that point: an endless loop). Those get no triangle here, copies of a point are
    passed once (triangles use the first copy), zero-length and repeated segments are
    dropped, a segment is split at each point within 1e-9 of the extent of its inside,
    and segments crossing within that distance of another crossing get no triangle (the
    crossings are returned as the vertices triangle would add); segments must index the
    points. Input triangle still refuses (it raises) gets no triangle either.
    """
    import triangle

    # copies: triangle's wrapper takes no read-only buffer (np.frombuffer's: it raised,
    # and the input got no triangle)
    pts = np.array(pts, dtype=np.float64, order="C").reshape(-1, 2)
    seg = np.array(seg, dtype=np.int64, order="C").reshape(-1, 2)
    none = np.zeros((0, 3), dtype=np.int64), np.zeros((0, 2))
    if not np.isfinite(pts).all():
        raise ValueError("triangulate: points must be finite")
    if len(seg) and (seg.min() < 0 or seg.max() >= len(pts)):
        raise ValueError("triangulate: a segment indexes no point")
    if len(pts) < 3 or not _spans_area(pts):
        return none
    n = len(pts)
    first = _first_copies(pts)
    if first is not None:  # segments between copies of a point make triangle loop forever
        keep = np.unique(first)
        slot = np.full(n, -1, dtype=np.int64)
        slot[keep] = np.arange(len(keep))
        pts, seg = pts[keep], slot[first[seg]]
    seg = _once_each(seg[seg[:, 0] != seg[:, 1]], n)  # a segment twice loops forever
    if len(seg):
        # a point within rounding of a segment's inside (not on it, to triangle's exact
        # tests) made it insert a crossing next to that point and loop forever (a fold's
        # rim closed by its chord, a synthetic bunny view punched with seed 69): the
        # segment is split at the point, as triangle splits one through a point exactly
        tol = _SAME_POINT * float(np.ptp(pts, axis=0).max())
        seg = _split_at_touching(pts, seg, tol, n)
        cross = _hk.crossings(pts, seg)
        if len(cross) > 1 and _any_close(cross, tol):  # crossings that near: the same
            return none[0], cross
        data, switches = {"vertices": pts, "segments": seg}, flags
    else:  # no constraint left: the points' own (convex hull) triangulation
        data, switches = {"vertices": pts}, flags.replace("p", "").replace("c", "")
    try:
        with _native_stdout_muted():
            res = triangle.triangulate(data, switches)
    except (RuntimeError, ValueError, IndexError):  # "invalid geometry on input"
        return none
    tris = np.asarray(res.get("triangles", np.zeros((0, 3))), dtype=np.int64).reshape(-1, 3)
    extra = np.asarray(res["vertices"])[len(pts):]
    if first is not None:  # back to the caller's ids (the first copy; added vertices after)
        tris = np.where(tris < len(keep), keep[np.minimum(tris, len(keep) - 1)],
                        n + tris - len(keep))
    return tris, extra


_STDOUT_LOCK = threading.Lock()


def _once_each(seg: np.ndarray, n: int) -> np.ndarray:
    """Return the segments (m, 2) without repeats (either way round), in their order."""
    if len(seg) < 2:
        return seg
    key = np.sort(seg, axis=1)
    _, once = np.unique(key[:, 0] * n + key[:, 1], return_index=True)
    return seg[np.sort(once)] if len(once) < len(seg) else seg


def _split_at_touching(pts: np.ndarray, seg: np.ndarray, tol: float, n: int) -> np.ndarray:
    """Split each segment at the points within ``tol`` of its inside, in their order."""
    at, v, t = _hk.touching(pts, seg, tol)
    if len(at) == 0:
        return seg
    keep = np.ones(len(seg), dtype=bool)
    keep[at] = False
    parts = [seg[keep]]
    order = np.lexsort((t, at))
    at, v = at[order], v[order]
    starts = np.flatnonzero(np.r_[True, at[1:] != at[:-1]])
    for lo, hi in zip(starts, np.r_[starts[1:], len(at)], strict=True):
        chain = np.r_[seg[at[lo], 0], v[lo:hi], seg[at[lo], 1]]
        parts.append(np.column_stack([chain[:-1], chain[1:]]))
    out = np.concatenate(parts)
    return _once_each(out[out[:, 0] != out[:, 1]], n)


def _any_close(p: np.ndarray, tol: float) -> bool:
    """Whether two of the points (k, 2) lie within ``tol`` of each other."""
    from scipy.spatial import cKDTree

    return bool(cKDTree(p).query_pairs(tol, output_type="ndarray").size)


def _flush_c_streams() -> None:
    """Flush the C library's stdio buffers (where native code's printf waits)."""
    with contextlib.suppress(OSError, AttributeError, TypeError):
        ctypes.CDLL(None).fflush(None)


@contextlib.contextmanager
def _native_stdout_muted() -> Iterator[None]:
    """Send what native code prints on file descriptor 1 to the null device meanwhile.

    On an input it cannot take, triangle prints "Internal error in segmentintersection()"
    (or the like) with C's printf before its wrapper raises; on stdout that text went
    into ``asrbf fill-holes --json``'s output and made it invalid JSON (a synthetic bunny
    view, punch seed 8). Python's own stdout is flushed first; one thread at a time.
    """
    with _STDOUT_LOCK:
        try:
            if sys.stdout is not None:
                sys.stdout.flush()
            saved = os.dup(1)
        except (OSError, ValueError):  # no file descriptor 1: nothing to mute
            yield
            return
        null = os.open(os.devnull, os.O_WRONLY)
        try:
            _flush_c_streams()
            os.dup2(null, 1)
            yield
        finally:
            _flush_c_streams()
            os.dup2(saved, 1)
            os.close(saved)
            os.close(null)


#: Points closer than this share of the points' extent are copies of one point.
_SAME_POINT = 1e-9


def _first_copies(pts: np.ndarray) -> np.ndarray | None:
    """Each point's first copy (smallest index of its group), or None if no two coincide.

    Points chained closer than ``_SAME_POINT`` of the (n, 2) points' extent are copies.
    """
    from ._segment_kernels import close_components

    group = close_components(pts, _SAME_POINT * float(np.ptp(pts, axis=0).max()))
    if group.max() == len(pts) - 1:  # every point a group of its own
        return None
    lead = np.full(int(group.max()) + 1, len(pts), dtype=np.int64)
    np.minimum.at(lead, group, np.arange(len(pts)))
    return lead[group]


def _spans_area(pts: np.ndarray) -> bool:
    """Whether the (n, 2) points are not all on one line (nor all one point), exactly.

    Exact in floating point: some point lies off the line through the first point and
    the point farthest from it (orientation test with a relative tolerance of 1e-12).
    """
    d = pts - pts[0]
    far = int(np.argmax(np.abs(d).sum(axis=1)))
    u = d[far]
    if not np.any(u):
        return False
    cross = u[0] * d[:, 1] - u[1] * d[:, 0]
    return bool(np.abs(cross).max() > 1e-12 * float(np.abs(u).max()) * float(np.abs(d).max()))


def delaunay(xy: np.ndarray, longest: float = np.inf) -> np.ndarray:
    """Counter-clockwise Delaunay triangles of (n, 2) points, through :func:`triangulate`.

    Triangles with an edge longer than ``longest`` or without area are left out. Copies
    of a point are in no triangle but their first copy's; points that span no area give
    none. On a regular grid of 90,000 points (cocircular quadruples everywhere) scipy's
    qhull took 1.2 s, triangle 0.06 s; on random points 0.42 s and 0.06 s.
    """
    xy = np.asarray(xy, dtype=np.float64)
    tris, _ = triangulate(xy, np.zeros((0, 2), dtype=np.int64), "Q")
    if len(tris) == 0:
        return tris
    x, y = xy[:, 0], xy[:, 1]
    a, b, c = tris[:, 0], tris[:, 1], tris[:, 2]
    cross = (x[b] - x[a]) * (y[c] - y[a]) - (y[b] - y[a]) * (x[c] - x[a])
    keep = cross != 0
    if np.isfinite(longest):
        keep &= np.logical_and.reduce([e <= longest * longest for e in squared_edges(xy, tris)])
    flip = cross < 0
    if flip.any():
        tris[flip] = tris[flip][:, [0, 2, 1]]
    return tris[keep]


def squared_edges(xy: np.ndarray, tris: np.ndarray) -> tuple[np.ndarray, ...]:
    """Squared lengths of each triangle's edges ab, ac, bc in the plane: three (F,) arrays.

    The same numbers whichever way round a triangle is listed (a turned triangle swaps
    ab and ac, and bc changes sign before it is squared).
    """
    x, y = xy[:, 0], xy[:, 1]
    a, b, c = tris[:, 0], tris[:, 1], tris[:, 2]
    ux, uy = x[b] - x[a], y[b] - y[a]
    vx, vy = x[c] - x[a], y[c] - y[a]
    wx, wy = vx - ux, vy - uy
    return ux * ux + uy * uy, vx * vx + vy * vy, wx * wx + wy * wy
