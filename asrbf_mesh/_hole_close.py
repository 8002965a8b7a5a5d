"""Closing a boundary loop so that it joins the mesh manifold.

The loop stage of :func:`~asrbf_mesh._holes.fill_holes` fills each loop the view-plane
fills left open (:func:`~asrbf_mesh._hole_loops.fill_loop`); what it adds must give no
edge a third face and no triangle a vertex twice. Here: the test of a loop's fill
(:func:`_fits`), what follows when it fails (the disk fill, chords the mesh lacks, a fan
around one new vertex) and a loop that passes a vertex twice filled cycle by cycle. Edges
are int64 keys ``min * 2**31 + max`` kept sorted (:class:`_EdgeSet`).
"""

from __future__ import annotations

import numpy as np
from numba import njit
from scipy.spatial import cKDTree

from . import _jit_cache  # noqa: F401 (first: where numba caches the kernel below)
from ._hole_loops import _oriented, fill_loop, simple_cycles

_KEY = np.int64(2) ** 31  # edge key base: vertex indices stay below 2**31


def _fits(t: np.ndarray, loop: np.ndarray, known: _EdgeSet | np.ndarray) -> bool:
    """Tell whether a loop's fill joins the mesh manifold.

    No edge the mesh already has but the rim's (:func:`_reuses`), no triangle with a
    vertex twice, no edge in three of the fill's triangles and no rim edge in two (a loop
    through a pinch vertex, filled as one polygon, gave both: Kinect frame desk2 as a
    float32 PLY).
    """
    if _reuses(t, loop, known):
        return False
    if np.any((t[:, 0] == t[:, 1]) | (t[:, 1] == t[:, 2]) | (t[:, 0] == t[:, 2])):
        return False
    keys, count = np.unique(_edge_keys(t), return_counts=True)
    if np.any(count > 2):
        return False
    rim = np.isin(keys, _rim_keys(loop))
    return not np.any(count[rim] > 1)


def _fill_fallback(loop: np.ndarray, vertices: np.ndarray, step: float,
                   scan_points: np.ndarray, tree: cKDTree, known: _EdgeSet | np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray, str | None]:
    """Fill a loop whose plane fill does not fit: the disk fill, else chords or a fan."""
    v, t, reason = fill_loop(loop, vertices, step, scan_points, tree, disk=True)
    if len(t) and not _fits(t, loop, known):  # a small loop: chords the mesh lacks
        v, t = _close_small(loop, vertices, known)
        reason = None if len(t) else ("the fill would reuse an edge of the mesh (the rim "
                                      "touches itself)")
    return v, t, reason


def _fill_cycles(loop: np.ndarray, vertices: np.ndarray, step: float,
                 scan_points: np.ndarray, tree: cKDTree, known: _EdgeSet | np.ndarray,
                 R: np.ndarray, ccw: bool, parts: _Parts | None = None
                 ) -> tuple[np.ndarray, np.ndarray, str | None]:
    """Fill a loop that passes a vertex twice cycle by cycle (all or nothing).

    Its simple cycles (:func:`~asrbf_mesh._hole_loops.simple_cycles`) that wind as holes
    in the view plane are filled each on its own (plane, disk, chords or a fan); one
    winding the other way is a blob pinched to the rim, left as it is, unless ``parts``
    (the mesh's :class:`_Parts`) tells it is a gap all the same (:meth:`_Parts.is_gap`:
    a sliver's winding says little). New vertices are
    numbered -1, -2, ... across the cycles. Nothing and no reason when no cycle winds as
    a hole (blobs pinched together: desk2 as a float32 PLY had two quads so).
    """
    new_v: list[np.ndarray] = []
    tris: list[np.ndarray] = []
    n_new = 0
    for cycle in simple_cycles(loop):
        if not _winds_as_hole(vertices[cycle] @ R, ccw) and not (
                parts is not None and parts.is_gap(cycle)):
            continue
        v, t, reason = fill_loop(cycle, vertices, step, scan_points, tree)
        if len(t) and not _fits(t, cycle, known):
            v, t, reason = _fill_fallback(cycle, vertices, step, scan_points, tree, known)
        if len(t) == 0 or not _fits(t, cycle, known):
            return np.zeros((0, 3)), np.zeros((0, 3), np.int64), (
                reason or "the fill would reuse an edge of the mesh (the rim touches itself)")
        new_v.append(v)
        tris.append(np.where(t < 0, t - n_new, t))
        n_new += len(v)
    # no cycle winds as a hole: blobs pinched together, no gap (None: not a hole)
    if not tris:
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64), None
    return np.vstack(new_v), np.vstack(tris), None


#: Largest loop :func:`_chords_avoiding` triangulates (O(n^3) dynamic programming).
_DP_MAX = 40
#: Largest loop closed by :func:`_centre_fan` when no triangulation of it by chords avoids
#: the mesh's edges.
_FAN_MAX = 8


def _close_small(loop: np.ndarray, vertices: np.ndarray,
                 known: _EdgeSet | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Close a small simple loop by chords the mesh lacks, else by a centre fan.

    Returns (new vertices, triangles), empty when neither closes it. A loop that passes a
    vertex twice comes here one cycle at a time (:func:`_fill_cycles`).
    """
    t = _chords_avoiding(loop, vertices, known)
    if len(t) == 0 and len(loop) <= _FAN_MAX:  # no triangulation avoids them
        return _centre_fan(loop, vertices)
    return np.zeros((0, 3)), t


def _centre_fan(loop: np.ndarray, vertices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Close a small loop by one new vertex at its centroid: (that vertex, the fan).

    Each triangle holds one rim edge and two new edges to the new vertex (id -1), so no
    edge of the mesh gets a third face: what closes a gap of a few rim edges that no
    triangulation by chords closes without an edge the mesh already has (a patch's
    dropped triangles beside a fold left a quad with both diagonals taken: bun090,
    punch protocol seed 77).
    """
    fan = np.column_stack([loop, np.roll(loop, -1), np.full(len(loop), -1)]).astype(np.int64)
    return vertices[loop].mean(axis=0)[None, :], _oriented(fan, loop)


def _chords_avoiding(loop: np.ndarray, vertices: np.ndarray,
                     known: _EdgeSet | np.ndarray) -> np.ndarray:
    """Triangulate a small loop without new vertices and without an edge the mesh has.

    The minimum-area triangulation of the polygon (dynamic programming over its
    diagonals, Barequet & Sharir's scheme as used by Liepa) in which no diagonal joins
    two vertices the mesh already joins (a quad whose one diagonal is a mesh edge takes
    the other). Returns (T, 3) mesh vertex ids, empty when none exists or the loop is
    larger than :data:`_DP_MAX`.
    """
    n = len(loop)
    if n < 3 or n > _DP_MAX:
        return np.zeros((0, 3), np.int64)
    p = vertices[loop]
    a, b = np.minimum.outer(loop, loop), np.maximum.outer(loop, loop)
    free = ~_EdgeSet.of(known).contains(a.astype(np.int64) * _KEY + b)
    for i in range(n):  # the rim's own edges are fine
        free[i, (i + 1) % n] = free[(i + 1) % n, i] = True
    cost, pick = _min_area(np.ascontiguousarray(p, dtype=np.float64), free)
    if not np.isfinite(cost[0, n - 1]):
        return np.zeros((0, 3), np.int64)
    tris, stack = [], [(0, n - 1)]
    while stack:
        i, j = stack.pop()
        if j - i < 2:
            continue
        k = int(pick[i, j])
        tris.append((loop[i], loop[k], loop[j]))
        stack += [(i, k), (k, j)]
    return _oriented(np.array(tris, dtype=np.int64), loop)


@njit(cache=True, nogil=True)
def _min_area(p, free):
    # cost[i, j]: least area of the polygon i..j triangulated by free diagonals; pick: apex
    n = p.shape[0]
    cost = np.full((n, n), np.inf)
    pick = np.full((n, n), -1, dtype=np.int64)
    for i in range(n - 1):
        cost[i, i + 1] = 0.0
    for span in range(2, n):
        for i in range(n - span):
            j = i + span
            if not free[i, j]:
                continue
            for k in range(i + 1, j):
                c = cost[i, k] + cost[k, j]
                if c == np.inf:
                    continue
                u0, u1, u2 = p[k, 0] - p[i, 0], p[k, 1] - p[i, 1], p[k, 2] - p[i, 2]
                v0, v1, v2 = p[j, 0] - p[i, 0], p[j, 1] - p[i, 1], p[j, 2] - p[i, 2]
                w0, w1, w2 = u1 * v2 - u2 * v1, u2 * v0 - u0 * v2, u0 * v1 - u1 * v0
                c += 0.5 * np.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
                if c < cost[i, j]:
                    cost[i, j] = c
                    pick[i, j] = k
    return cost, pick


def _edge_keys(tris: np.ndarray) -> np.ndarray:
    """One int64 key per (undirected) edge of each triangle: ``min * 2**31 + max``."""
    e = np.sort(np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]]), axis=1)
    return e[:, 0].astype(np.int64) * _KEY + e[:, 1]


#: :meth:`_Parts.is_gap` looks at cycles of at most this many vertices.
_GAP_MAX = 8


def facing(local: np.ndarray, tris: np.ndarray) -> float:
    """Area-weighted mean of |n . view| over triangles (1: seen face-on, 0: edge-on)."""
    t = local[tris]
    normal = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
    area = float(np.linalg.norm(normal, axis=1).sum())
    return float(np.abs(normal[:, 2]).sum()) / area if area > 0 else 0.0


def _edge_parts(tris: np.ndarray) -> np.ndarray:
    """Label of each triangle's part, triangles joined by shared edges."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    _, edge = np.unique(_edge_keys(tris), return_inverse=True)
    t = len(tris)
    tri = np.tile(np.arange(t), 3)  # _edge_keys lists the edges ab, then bc, then ca
    graph = coo_matrix((np.ones(len(tri)), (tri, t + edge.ravel())),
                       shape=(t + int(edge.max()) + 1,) * 2)
    return connected_components(graph, directed=False)[1][:t]


def _agree_with_scan(tris: np.ndarray, rim_keys: np.ndarray, inner_keys: np.ndarray
                     ) -> tuple[np.ndarray, int]:
    """Orient a patch the scan's way; drop the triangles that cannot join it consistently.

    A patch is triangulated counter-clockwise in the view plane; where the scan folds over
    itself its rim runs clockwise there (a back layer), and a patch joined to it that way
    gives a rim edge two faces in one direction (an inconsistently oriented mesh: bun090,
    punched with seeds 1 and 2). Each edge-connected part of the patch is flipped when
    more of its edges run along a rim edge (``rim_keys``: the scan's boundary half-edges
    ``a * 2**31 + b``, sorted) the scan's way than against it; then a triangle that still
    runs a rim edge the scan's way, or lies on an edge two scan faces share
    (``inner_keys``, undirected keys, sorted), is dropped. Returns the triangles and how
    many were dropped.
    """
    if len(tris) == 0:
        return tris, 0
    he = np.stack([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]], axis=1).astype(np.int64)
    same = _in_sorted(he[..., 0] * _KEY + he[..., 1], rim_keys).sum(axis=1)
    und = np.sort(he, axis=2)
    third = _in_sorted(und[..., 0] * _KEY + und[..., 1], inner_keys).any(axis=1)
    if not same.any() and not third.any():
        return tris, 0
    out = tris.copy()
    if same.any():
        against = _in_sorted(he[..., 1] * _KEY + he[..., 0], rim_keys).sum(axis=1)
        part = _edge_parts(tris)
        flip = (np.bincount(part, weights=same) > np.bincount(part, weights=against))[part]
        out[flip] = out[flip][:, [0, 2, 1]]
        fwd = out[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 3, 2).astype(np.int64)
        same = _in_sorted(fwd[..., 0] * _KEY + fwd[..., 1], rim_keys).sum(axis=1)
    bad = (same > 0) | third
    return out[~bad], int(bad.sum())


class _Parts:
    """The parts of a mesh joined across edges, and how much border each has.

    Computed on first use (most fills never ask). A boundary cycle whose view-plane
    winding says "blob" may still be a gap: a sliver of three vertices seen nearly
    edge-on winds either way by rounding (Kinect frame desk2: a missing triangle whose
    corners lie within 0.03 % of its perimeter squared of a line, left open, held a
    hole's rim edge open).
    """

    def __init__(self, faces: np.ndarray) -> None:
        self.faces = faces
        self._comp: np.ndarray | None = None

    def _build(self) -> None:
        import scipy.sparse as sp
        from scipy.sparse.csgraph import connected_components

        n = len(self.faces)
        keys = _edge_keys(self.faces)  # edge slot j of face f at j * n + f
        order = np.argsort(keys, kind="stable")
        k = keys[order]
        same = np.flatnonzero(k[1:] == k[:-1])
        a, b = order[same] % n, order[same + 1] % n
        _, comp = connected_components(
            sp.coo_matrix((np.ones(len(a)), (a, b)), shape=(n, n)), directed=False)
        _, first, count = np.unique(k, return_index=True, return_counts=True)
        border_face = order[first[count == 1]] % n
        self._keys, self._order, self._comp = k, order, comp
        self._border = np.bincount(comp[border_face], minlength=int(comp.max()) + 1)

    def is_gap(self, cycle: np.ndarray) -> bool:
        """Whether a boundary cycle is a gap in its part rather than a blob's border.

        Asked of small cycles only (up to :data:`_GAP_MAX` vertices): a gap is then
        one whose edges' triangles (one part) have more border elsewhere than the cycle
        is long (a blob pinched to the rest at a vertex is a part of its own, its cycle
        its whole border, or its longest). A large cycle's winding is trusted: the
        border of a depth frame's far-range fragment joined to the rest runs so too
        (desk2: a 102-vertex cycle filled with 5,268 triangles over the outside).
        """
        if len(cycle) > _GAP_MAX:
            return False
        if self._comp is None:
            self._build()
        rim = _rim_keys(cycle)
        pos = np.minimum(np.searchsorted(self._keys, rim), len(self._keys) - 1)
        pos = pos[self._keys[pos] == rim]  # the cycle's edges that are the mesh's
        if len(pos) == 0:
            return False
        parts = np.unique(self._comp[self._order[pos] % len(self.faces)])
        if len(parts) != 1:
            return False
        return int(self._border[parts[0]]) - len(cycle) > len(cycle)


def _winds_as_hole(local: np.ndarray, ccw: bool) -> bool:
    """Whether a boundary cycle (view-frame xyz, in its faces' direction) winds as a hole.

    The boundary half-edges of triangles counter-clockwise in the view plane run
    counter-clockwise around a blob and clockwise around a hole (and the other way round).
    """
    x, y = local[:, 0], local[:, 1]
    area = float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))
    return area < 0 if ccw else area > 0


def _rim_keys(loop: np.ndarray) -> np.ndarray:
    """Keys of a loop's rim edges."""
    return _rim_keys_of(np.column_stack([loop, np.roll(loop, -1)]))


def _rim_keys_of(edges: np.ndarray) -> np.ndarray:
    """Keys of (E, 2) vertex pairs, either way round."""
    e = np.sort(edges, axis=1)
    return e[:, 0].astype(np.int64) * _KEY + e[:, 1]


def _reuses(tris: np.ndarray, loop: np.ndarray, known: _EdgeSet | np.ndarray) -> bool:
    """Whether a loop's fill joins two mesh vertices the mesh already joins (not a rim edge)."""
    e = np.sort(np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]]), axis=1)
    e = e[e[:, 0] >= 0]  # both ends mesh vertices (new vertices are negative)
    chords = np.setdiff1d(e[:, 0].astype(np.int64) * _KEY + e[:, 1], _rim_keys(loop))
    return bool(_EdgeSet.of(known).contains(chords).any())


def _in_sorted(keys: np.ndarray, table: np.ndarray) -> np.ndarray:
    """Whether each of ``keys`` is in the sorted array ``table`` (a binary search each)."""
    if len(table) == 0:
        return np.zeros(np.shape(keys), dtype=bool)
    at = np.minimum(np.searchsorted(table, keys), len(table) - 1)
    return table[at] == keys


class _EdgeSet:
    """The mesh's edge keys (sorted, fixed) and those the fills add, for membership tests.

    A loop's test costs O(k log E) for its k keys: ``np.isin`` against the whole set, or
    merging each fill into one sorted array, cost O(E) per loop, and a Kinect frame's
    mesh (E = 600,000 edges, 300 loops) spent 300 s there.
    """

    def __init__(self, keys: np.ndarray) -> None:
        """``keys``: the mesh's edge keys, sorted ascending."""
        self._base = np.asarray(keys, dtype=np.int64)
        self._added: set[int] = set()

    @classmethod
    def of(cls, keys: _EdgeSet | np.ndarray) -> _EdgeSet:
        """``keys`` as an edge set (an array of keys is sorted first)."""
        return keys if isinstance(keys, _EdgeSet) else cls(np.unique(keys))

    def with_keys(self, keys: np.ndarray) -> _EdgeSet:
        """Return a copy that also holds ``keys`` (this set unchanged)."""
        out = _EdgeSet.__new__(_EdgeSet)
        out._base, out._added = self._base, set(self._added)
        out.add(keys)
        return out

    def add(self, keys: np.ndarray) -> None:
        self._added.update(np.asarray(keys, dtype=np.int64).ravel().tolist())

    def contains(self, keys: np.ndarray) -> np.ndarray:
        keys = np.asarray(keys, dtype=np.int64)
        hit = _in_sorted(keys, self._base)
        if self._added:
            flat = keys.ravel()
            extra = np.fromiter((k in self._added for k in flat.tolist()), dtype=bool,
                                count=len(flat))
            hit |= extra.reshape(keys.shape)
        return hit


def close_gaps(local: np.ndarray, faces: np.ndarray, still_open: np.ndarray,
               left_keys: np.ndarray, wall_facing: float, keys: np.ndarray | None = None
               ) -> tuple[np.ndarray, np.ndarray]:
    """Close by chords the small gaps that left-out crossing triangles opened.

    ``local``: the vertices in the view frame; ``faces``: the mesh without the triangles
    left out; ``still_open``: sorted keys of its boundary edges on no outer border;
    ``left_keys``: sorted keys of the left-out triangles' edges; ``keys``: all of
    ``faces``' edge keys, sorted, when known. Each boundary cycle of open edges, one of
    them a left-out triangle's, of at most :data:`_DP_MAX` vertices, is triangulated by
    chords (:func:`_chords_avoiding`, no new vertex, no edge the mesh has); a
    triangulation seen edge-on (area-weighted ``|n_z|`` below ``wall_facing``: a wall
    between two layers) or crossing the mesh or another gap's
    (:func:`~asrbf_mesh._hole_cross.crossing_of`) is not used. Returns the triangles
    and, for each, the key of one left-out edge on its cycle (whose fill it mends).
    """
    from ._hole_cross import crossing_of
    from ._hole_loops import boundary_cycles

    none = np.zeros((0, 3), np.int64), np.zeros(0, np.int64)
    if len(still_open) == 0:
        return none
    cycles = [c for cycle in boundary_cycles(faces) for c in simple_cycles(cycle)
              if 3 <= len(c) <= _DP_MAX]
    known: _EdgeSet | None = None
    tris: list[np.ndarray] = []
    mends: list[int] = []
    for c in cycles:
        rim = _rim_keys(c)
        if not _in_sorted(rim, still_open).all():
            continue
        hit = rim[_in_sorted(rim, left_keys)]
        if len(hit) == 0:
            continue
        if known is None:
            known = _EdgeSet(np.unique(_edge_keys(faces)) if keys is None else keys)
        t = _chords_avoiding(c, local, known)
        if len(t) == 0:
            continue
        if facing(local, t) < wall_facing:
            continue
        known.add(_edge_keys(t))
        tris.append(t)
        mends.append(int(hit[0]))
    if not tris:
        return none
    new = np.vstack(tris)
    cycle_of = np.repeat(np.arange(len(tris)), [len(t) for t in tris])
    bad = crossing_of(local, np.vstack([faces, new]), len(faces) + np.arange(len(new)))
    ok = ~np.isin(cycle_of, np.unique(cycle_of[bad]))
    return new[ok], np.asarray(mends, dtype=np.int64)[cycle_of[ok]]
