"""Fill triangles that cross the scan or another fill: found and left out.

A patch shaped in the view plane stands where its layer would be; where the scan folds
over itself (an ear before the head, a cow's leg before its body, a depth frame's steps)
the loop stage's fills, closed in a loop's own plane or by fairing, can run as walls
between two layers and through the surface between them. pymeshlab's self-intersection
selection (what the issue's quality check uses) found such triangles on the punch
protocol, seeds 0-9: bun090 and the cows' views had 100-1,200 on most seeds, the face
map 11 and 14 on seeds 4 and 7, a Kinect frame meshed as its range grid 10,509
(2026-11-30). Such a mesh breaks what comes after it (booleans, printing, offsets); a
fill leaves those triangles out and says so.

The test is exact in double precision (separating axes, :func:`triangles_cross`) over
the pairs a bucket grid in the view plane proposes: VCG's test (pymeshlab) selected two
disjoint triangles of one plane fill 30 units from the origin, and took 4.3 s on the
Kinect frame's 558,000 triangles near its fills.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from . import _jit_cache  # noqa: F401 (first: where numba caches the kernels below)
from ._network_kernels import in_threads, threads_for

__all__ = ["crossing_faces", "crossing_of", "triangles_cross"]

#: :func:`triangles_cross`: reaching into the other triangle by up to this share of the
#: pair's longest edge is contact (a shared corner or edge), not a crossing.
CONTACT = 1e-7
#: :func:`crossing_faces`: grid cells at most this many times the faces (a few long
#: triangles over a fine grid; the cells grow until it holds).
_CELLS_PER_FACE = 8


def crossing_faces(local: np.ndarray, faces: np.ndarray, first_new: int) -> np.ndarray:
    """Return the faces from ``first_new`` on that cross another face (sorted indices).

    ``local``: the vertices in the scan's view frame (depth last). Every pair of a new
    face and another face whose boxes overlap (a grid of cells in the view plane, each
    face listed in the cells its box covers) is tested by :func:`triangles_cross`. A fill
    triangle on copies of another's corners (a crack's zero-width hole, a face whose
    corners are copies of its neighbours', closed where the copy lies) is no crossing:
    the surface is the same; one on the same vertices is (a triangle alone closed by its
    own reverse, a model view's one-triangle fragment: pymeshlab selected both).
    """
    pts = np.ascontiguousarray(local, dtype=np.float64).reshape(-1, 3)
    faces = np.ascontiguousarray(faces, dtype=np.int64).reshape(-1, 3)
    n = len(faces)
    if not 0 <= first_new <= n:
        raise ValueError("crossing_faces: first_new out of range")
    if first_new == n:
        return np.zeros(0, dtype=np.int64)
    if len(pts) == 0 or faces.min() < 0 or faces.max() >= len(pts):
        raise ValueError("crossing_faces: a face indexes no vertex")
    if not np.isfinite(pts).all():
        raise ValueError("crossing_faces: vertices must be finite")
    tri = pts[faces]
    lo, hi = tri.min(axis=1), tri.max(axis=1)
    origin = lo[:, :2].min(axis=0)
    extent = float((hi[:, :2].max(axis=0) - origin).max())
    cell = max(2.0 * float(np.median((hi - lo)[first_new:, :2].max(axis=1))),
               1e-9 * extent, 1e-300)
    while True:  # the cells the faces' boxes cover, bounded: coarser cells until they are
        ij = np.floor((np.stack([lo[:, :2], hi[:, :2]], axis=1) - origin) / cell)
        if float(np.prod(ij[:, 1] - ij[:, 0] + 1, axis=1).sum()) <= _CELLS_PER_FACE * n + 1e6:
            break
        cell *= 2.0
    ij = ij.astype(np.int64)  # (F, 2 (low, high), 2 (x, y)) cells
    ny = int(ij[:, 1, 1].max()) + 1
    keys, owner = _entries(ij, ny)
    order = np.argsort(keys, kind="stable")
    crossed = np.zeros(n, dtype=np.bool_)
    in_threads(_crossing, n - first_new, threads_for(n - first_new), tri, faces, lo, hi,
               first_new, ij, ny, keys[order], owner[order], CONTACT, crossed)
    return np.flatnonzero(crossed[first_new:]) + first_new


def crossing_of(local: np.ndarray, faces: np.ndarray, test: np.ndarray) -> np.ndarray:
    """Whether each face of ``test`` (indices into ``faces``) crosses another face.

    :func:`crossing_faces` over the faces that can: those whose boxes in the view plane
    touch a cell of a grid (twice the test faces' median box) that a test face's box
    covers; a face whose box spans at most two cells each way touches only its corners'
    cells, a wider one is always taken. The same answer as testing against every face,
    for the grid's cost over the few: a fill's second look at its patches on a Kinect
    frame (490 faces among 568,000) 0.7 s -> 0.3 s.
    """
    test = np.asarray(test, dtype=np.int64)
    out = np.zeros(len(test), dtype=bool)
    if len(test) == 0:
        return out
    xy = np.asarray(local, dtype=np.float64)[:, :2]
    rest = np.ones(len(faces), dtype=bool)
    rest[test] = False
    others = np.flatnonzero(rest)
    near = others
    t = xy[faces[test]]
    lo, hi = t.min(axis=1), t.max(axis=1)
    cell = 2.0 * float(np.median((hi - lo).max(axis=1)))
    if cell > 0.0 and np.isfinite(cell):
        origin = lo.min(axis=0)
        a = np.floor((lo - origin) / cell).astype(np.int64)
        span = np.floor((hi - origin) / cell).astype(np.int64) - a + 1
        cells = span[:, 0] * span[:, 1]
        if int(cells.sum()) <= _CELLS_PER_FACE * len(test) + 100_000:
            row = np.repeat(np.arange(len(test)), cells)
            k = np.arange(len(row)) - np.repeat(np.cumsum(cells) - cells, cells)
            marked = np.unique((a[row, 0] + k // span[row, 1]) * (1 << 32)
                               + a[row, 1] + k % span[row, 1])
            f = xy[faces[others]]
            flo = np.floor((f.min(axis=1) - origin) / cell).astype(np.int64)
            fhi = np.floor((f.max(axis=1) - origin) / cell).astype(np.int64)
            hit = ((fhi - flo) > 1).any(axis=1)
            for i in (flo[:, 0], fhi[:, 0]):
                for j in (flo[:, 1], fhi[:, 1]):
                    key = i * (1 << 32) + j
                    at = np.minimum(np.searchsorted(marked, key), len(marked) - 1)
                    hit |= marked[at] == key
            near = others[hit]
    sub = np.vstack([np.asarray(faces)[near], np.asarray(faces)[test]])
    out[crossing_faces(local, sub, len(near)) - len(near)] = True
    return out


@njit(cache=True, nogil=True)
def _entries(ij, ny):
    n = ij.shape[0]
    total = 0
    for f in range(n):
        total += (ij[f, 1, 0] - ij[f, 0, 0] + 1) * (ij[f, 1, 1] - ij[f, 0, 1] + 1)
    keys = np.empty(total, np.int64)
    owner = np.empty(total, np.int64)
    t = 0
    for f in range(n):
        for i in range(ij[f, 0, 0], ij[f, 1, 0] + 1):
            for j in range(ij[f, 0, 1], ij[f, 1, 1] + 1):
                keys[t] = i * ny + j
                owner[t] = f
                t += 1
    return keys, owner


@njit(cache=True, nogil=True)
def _crossing(tri, faces, lo, hi, first, ij, ny, keys, items, contact, crossed, i0, i1):
    # new faces first + i0 ... first + i1 - 1; each marks only itself (threads share none)
    for a in range(first + i0, first + i1):
        for i in range(ij[a, 0, 0], ij[a, 1, 0] + 1):
            for j in range(ij[a, 0, 1], ij[a, 1, 1] + 1):
                key = i * ny + j
                for t in range(np.searchsorted(keys, key), np.searchsorted(keys, key + 1)):
                    b = items[t]
                    if crossed[a]:
                        break
                    if b == a or i != max(ij[a, 0, 0], ij[b, 0, 0]) or j != max(
                            ij[a, 0, 1], ij[b, 0, 1]):
                        continue  # itself, or a pair met in the first cell both boxes share
                    if (lo[a, 0] > hi[b, 0] or lo[b, 0] > hi[a, 0] or lo[a, 1] > hi[b, 1]
                            or lo[b, 1] > hi[a, 1] or lo[a, 2] > hi[b, 2]
                            or lo[b, 2] > hi[a, 2]):
                        continue
                    if _cross(tri[a], tri[b], contact, not _shares_corner(tri[a], tri[b])) and not (
                            _same_corners(tri[a], tri[b]) and not _same_corners(faces[a],
                                                                                faces[b])):
                        crossed[a] = True  # (copies of a crack's corners: the same surface)


@njit(cache=True, nogil=True)
def _shares_corner(p, q):  # a corner of p where one of q's is: (3, 3) corners each
    for i in range(3):
        for j in range(3):
            if p[i, 0] == q[j, 0] and p[i, 1] == q[j, 1] and p[i, 2] == q[j, 2]:
                return True
    return False


@njit(cache=True, nogil=True)
def _same_corners(p, q):  # rows of p all among q's: (3, 3) corners or (3,) vertex ids
    for i in range(3):
        hit = False
        for j in range(3):
            if np.all(p[i] == q[j]):
                hit = True
        if not hit:
            return False
    return True


def triangles_cross(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Whether each pair of triangles (two (M, 3, 3) arrays) overlaps in more than contact.

    Separating axes: the two normals, the nine cross products of an edge of each and,
    for a pair in one plane, each edge crossed with its normal. A pair with a corner in
    common crosses when on every axis each reaches into the other by more than
    :data:`CONTACT` times its longest edge (triangles that only share a corner or an
    edge do not, on one of them), an axis on which both are one point excepted (the
    plane they share). A pair without one crosses when it touches, within that
    distance, on every axis: a corner of one on the other is a surface touching itself
    (a fill's corner on a wall's triangle seen edge-on, which pymeshlab's selection
    finds).
    """
    p = np.ascontiguousarray(p, dtype=np.float64).reshape(-1, 3, 3)
    q = np.ascontiguousarray(q, dtype=np.float64).reshape(-1, 3, 3)
    if len(p) != len(q):
        raise ValueError("triangles_cross: as many triangles in p as in q")
    return _cross_all(p, q, CONTACT)


@njit(cache=True, nogil=True)
def _cross_all(p, q, contact):
    out = np.empty(p.shape[0], np.bool_)
    for m in range(p.shape[0]):
        out[m] = _cross(p[m], q[m], contact, not _shares_corner(p[m], q[m]))
    return out


@njit(cache=True, nogil=True)
def _cross(p0, q0, contact, touch):
    # vectors as tuples (no arrays made per pair), moved to the pair's middle: the
    # arithmetic of a pair far from the origin
    m = ((p0[0, 0] + p0[1, 0] + p0[2, 0] + q0[0, 0] + q0[1, 0] + q0[2, 0]) / 6.0,
         (p0[0, 1] + p0[1, 1] + p0[2, 1] + q0[0, 1] + q0[1, 1] + q0[2, 1]) / 6.0,
         (p0[0, 2] + p0[1, 2] + p0[2, 2] + q0[0, 2] + q0[1, 2] + q0[2, 2]) / 6.0)
    p = (_sub(p0[0], m), _sub(p0[1], m), _sub(p0[2], m))
    q = (_sub(q0[0], m), _sub(q0[1], m), _sub(q0[2], m))
    ep = (_minus(p[1], p[0]), _minus(p[2], p[1]), _minus(p[0], p[2]))
    eq = (_minus(q[1], q[0]), _minus(q[2], q[1]), _minus(q[0], q[2]))
    scale = 0.0
    for v in range(3):
        scale = max(scale, np.sqrt(_dot(ep[v], ep[v])), np.sqrt(_dot(eq[v], eq[v])))
    tol = contact * scale
    gap = -tol if touch else tol  # parted on an axis when farther apart than this
    n_p = _crossv(ep[0], ep[1])
    n_q = _crossv(eq[0], eq[1])
    tested = 0
    for k in range(17):  # the normals first: most pairs near each other part on one
        if k == 0:
            axis = n_p
        elif k == 1:
            axis = n_q
        elif k < 11:
            axis = _crossv(ep[(k - 2) // 3], eq[(k - 2) % 3])
        elif k < 14:
            axis = _crossv(n_p, ep[k - 11])
        else:
            axis = _crossv(n_q, eq[k - 14])
        length = np.sqrt(_dot(axis, axis))
        if not length > 1e-12 * scale * scale:
            continue  # no axis (parallel edges, a triangle without area)
        tested += 1
        s0, s1, s2 = _dot(p[0], axis), _dot(p[1], axis), _dot(p[2], axis)
        lo_p, hi_p = min(s0, s1, s2) / length, max(s0, s1, s2) / length
        s0, s1, s2 = _dot(q[0], axis), _dot(q[1], axis), _dot(q[2], axis)
        lo_q, hi_q = min(s0, s1, s2) / length, max(s0, s1, s2) / length
        if hi_p - lo_p <= tol and hi_q - lo_q <= tol:  # both one point: the plane they share
            if abs(lo_p - lo_q) > tol:
                return False
        elif min(hi_p - lo_q, hi_q - lo_p) <= gap:  # a flat triangle's normal: one
            return False  # through it reaches in from both sides, one on its corner does not
    return tested > 0  # two points, or segments on one line: nothing to cross


@njit(cache=True, nogil=True)
def _sub(a, m):
    return (a[0] - m[0], a[1] - m[1], a[2] - m[2])


@njit(cache=True, nogil=True)
def _minus(a, b):
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


@njit(cache=True, nogil=True)
def _dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@njit(cache=True, nogil=True)
def _crossv(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])
