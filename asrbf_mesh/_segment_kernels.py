"""Compiled helpers of segmentation (private): triangle shapes, edges, jumps, cliffs.

:func:`smooth_fits` is rule 1b's test (a quadratic height field through the points
around a steep triangle or a jump pair), each row's 6 x 6 least squares solved by
Cholesky on threads of their own; numpy's batched solves and a k-d tree took 31 ms of
the face map's cut as a cloud, holding the interpreter's lock, and 3 ms here, with the
same answers on 125,000 rows of the five dev scans (their cuts the same triangles, as
meshes and as clouds, but one of bun000's 79,493 as a cloud; the same pieces).

:func:`triangle_shapes` and :func:`edge_lengths` measure what numpy measured in passes
over (F, 3, 3) temporaries (its norm over a last axis of three is slow), with the same
arithmetic, so the same bits.

A jump pair is two points close in the view plane (within ``radius``) but apart in depth
by more than ``jump`` and steeper than ``slope``. Found through a bucket grid of cells at
least ``radius`` wide, so each point looks at its own and the eight neighbouring cells.
The public wrapper checks the input and bounds the grid, as numba checks no index.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from . import _jit_cache  # noqa: F401 (first: where numba caches the kernels below)
from ._grid_knn import _nearest, bounds, robust_box


@njit(cache=True, nogil=True)
def triangle_shapes(local, faces):
    """Edge lengths (F, 3), twice the area and the normal's depth part of each triangle.

    Edge ``e`` of triangle ``(a, b, c)`` runs to vertex ``e`` from the one before it
    (``a - c``, ``b - a``, ``c - b``); the normal is ``(b - a) x (c - a)``.
    """
    f = faces.shape[0]
    length = np.empty((f, 3))
    area2 = np.empty(f)
    nz = np.empty(f)
    for t in range(f):
        for e in range(3):
            p = faces[t, e]
            q = faces[t, (e + 2) % 3]
            dx = local[p, 0] - local[q, 0]
            dy = local[p, 1] - local[q, 1]
            dz = local[p, 2] - local[q, 2]
            length[t, e] = np.sqrt(dx * dx + dy * dy + dz * dz)
        a, b, c = faces[t, 0], faces[t, 1], faces[t, 2]
        ux = local[b, 0] - local[a, 0]
        uy = local[b, 1] - local[a, 1]
        uz = local[b, 2] - local[a, 2]
        vx = local[c, 0] - local[a, 0]
        vy = local[c, 1] - local[a, 1]
        vz = local[c, 2] - local[a, 2]
        nx = uy * vz - uz * vy
        ny = uz * vx - ux * vz
        n2 = ux * vy - uy * vx
        area2[t] = np.sqrt(nx * nx + ny * ny + n2 * n2)
        nz[t] = n2
    return length, area2, nz


@njit(cache=True, nogil=True)
def edge_graph(n, faces):
    """CSR ``(indptr, indices)`` of the triangles' edges over ``n`` points, both ways.

    Each row's neighbours sorted and once each (an edge of two triangles is one entry):
    the structure scipy's ``coo_matrix(...).tocsr()`` gives, built in one pass.
    """
    count = np.zeros(n + 1, np.int64)
    for t in range(faces.shape[0]):
        for e in range(3):
            count[faces[t, e] + 1] += 2  # the edges to the next and the previous vertex
    for i in range(n):
        count[i + 1] += count[i]
    fill = count[:-1].copy()
    raw = np.empty(count[n], np.int64)
    for t in range(faces.shape[0]):
        for e in range(3):
            a = faces[t, e]
            raw[fill[a]] = faces[t, (e + 1) % 3]
            raw[fill[a] + 1] = faces[t, (e + 2) % 3]
            fill[a] += 2
    indptr = np.zeros(n + 1, np.int64)
    indices = np.empty(count[n], np.int64)
    m = 0
    for i in range(n):
        a = count[i]
        b = count[i + 1]
        for p in range(a + 1, b):  # insertion sort: a vertex has a few neighbours
            v = raw[p]
            q = p - 1
            while q >= a and raw[q] > v:
                raw[q + 1] = raw[q]
                q -= 1
            raw[q + 1] = v
        for p in range(a, b):
            if p == a or raw[p] != raw[p - 1]:
                indices[m] = raw[p]
                m += 1
        indptr[i + 1] = m
    return indptr, indices[:m].copy()


@njit(cache=True, nogil=True)
def edge_lengths(local, indptr, indices):
    """Length of each edge of a CSR graph over the points (entry ``t`` of row ``i``)."""
    n = indptr.shape[0] - 1
    out = np.empty(indices.shape[0])
    for i in range(n):
        for t in range(indptr[i], indptr[i + 1]):
            j = indices[t]
            dx = local[i, 0] - local[j, 0]
            dy = local[i, 1] - local[j, 1]
            dz = local[i, 2] - local[j, 2]
            out[t] = np.sqrt(dx * dx + dy * dy + dz * dz)
    return out


@njit(cache=True, nogil=True)
def components(n, faces):
    """Component of each of ``n`` points over the triangles' edges (union-find), and used.

    Labels are the smallest point index of each component, so they depend on the
    triangles' connectivity only; points in no triangle are their own component.
    """
    parent = np.arange(n)
    used = np.zeros(n, np.bool_)
    for t in range(faces.shape[0]):
        for e in range(3):
            a = faces[t, e]
            used[a] = True
            b = faces[t, (e + 1) % 3]
            while parent[a] != a:  # path halving
                parent[a] = parent[parent[a]]
                a = parent[a]
            while parent[b] != b:
                parent[b] = parent[parent[b]]
                b = parent[b]
            if a < b:
                parent[b] = a
            elif b < a:
                parent[a] = b
    for i in range(n):  # the root of i's component, its smallest index, is below i
        parent[i] = parent[parent[i]]
    return parent, used


#: The bucket grid has at most this many cells per point (wider cells beyond).
_CELLS_PER_POINT = 4


def jump_pairs(local: np.ndarray, radius: float, slope: float, jump: float) -> np.ndarray:
    """(P, 2) int64: index pairs ``i < j`` of ``local`` ((N, 3) view frame) that are jumps.

    Examples
    --------
    >>> pts = np.array([[0.0, 0, 0], [0.1, 0, 5], [0.2, 0, 0.01], [3.0, 0, 9]])
    >>> jump_pairs(pts, 0.5, 5.0, 1.0).tolist()
    [[0, 1], [1, 2]]
    """
    from ._network_kernels import in_threads, threads_for

    pts = np.ascontiguousarray(local, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3 or not np.isfinite(pts).all():
        raise ValueError("jump_pairs: points must be a finite (N, 3) array")
    if not (radius > 0 and np.isfinite(radius)) or len(pts) < 2:
        return np.zeros((0, 2), dtype=np.int64)
    # the points' robust box (points beyond it in the border cells: clamping only brings
    # cells closer, so no pair is missed): a far stray point would put all the others in
    # one cell. Cells at least radius wide, and no more than a few per point
    lo, hi = robust_box(pts[:, :2])
    span = hi - lo
    cell = max(radius, float(np.sqrt(span[0] * span[1] / (_CELLS_PER_POINT * len(pts)))),
               float(span.max()) / 65536.0)
    nx = int(span[0] / cell) + 1
    ny = int(span[1] / cell) + 1
    ij = np.clip((pts[:, :2] - lo) / cell, 0.0, [nx - 1, ny - 1]).astype(np.int64)
    key = ij[:, 1] * nx + ij[:, 0]
    order = np.argsort(key, kind="stable")
    start = np.searchsorted(key[order], np.arange(nx * ny + 1))
    args = (pts, ij, order, start, nx, ny, radius * radius, float(slope), float(jump))
    some = np.zeros(len(pts), dtype=np.bool_)
    in_threads(_pair_marks, len(pts), threads_for(len(pts)), *args, some)
    out = _pairs(*args, some)
    return out[np.lexsort((out[:, 1], out[:, 0]))]


@njit(cache=True, inline="always")
def _is_jump(pts, i, k, r2, slope, jump):
    # within r of each other in the view plane, farther apart in depth than jump and
    # than the slope allows
    dx = pts[k, 0] - pts[i, 0]
    dy = pts[k, 1] - pts[i, 1]
    d2 = dx * dx + dy * dy
    if d2 > r2:
        return False
    dz = abs(pts[k, 2] - pts[i, 2])
    return dz > jump and dz * dz > slope * slope * d2


@njit(cache=True, nogil=True)
def _pair_marks(pts, ij, order, start, nx, ny, r2, slope, jump, some, i0, i1):
    # whether each point i in [i0, i1) has a jump partner k > i: the first one found
    # ends its search (jumps are rare; the pairs are listed from the marked points)
    for i in range(i0, i1):
        ci, cj = ij[i, 0], ij[i, 1]
        for dj in range(-1, 2):
            y = cj + dj
            if some[i] or y < 0 or y >= ny:
                continue
            for di in range(-1, 2):
                x = ci + di
                if some[i] or x < 0 or x >= nx:
                    continue
                c = y * nx + x
                for t in range(start[c], start[c + 1]):
                    k = order[t]
                    if k > i and _is_jump(pts, i, k, r2, slope, jump):
                        some[i] = True
                        break


@njit(cache=True, nogil=True)
def _pairs(pts, ij, order, start, nx, ny, r2, slope, jump, some):
    # two sweeps over the marked points: the first counts their pairs, the second fills
    # them (one kernel to compile, no growing list)
    out = np.empty((0, 2), dtype=np.int64)
    for sweep in range(2):
        n = 0
        for i in range(pts.shape[0]):
            if not some[i]:
                continue
            ci, cj = ij[i, 0], ij[i, 1]
            for dj in range(-1, 2):
                y = cj + dj
                if y < 0 or y >= ny:
                    continue
                for di in range(-1, 2):
                    x = ci + di
                    if x < 0 or x >= nx:
                        continue
                    c = y * nx + x
                    for t in range(start[c], start[c + 1]):
                        k = order[t]
                        if k > i and _is_jump(pts, i, k, r2, slope, jump):
                            if sweep == 1:
                                out[n, 0] = i
                                out[n, 1] = k
                            n += 1
        if sweep == 0:
            out = np.empty((n, 2), dtype=np.int64)
    return out


def close_components(xy: np.ndarray, gap: float) -> np.ndarray:
    """(n,) int64: groups of the points ``xy`` chained by steps of at most ``gap``.

    Single linkage at ``gap``: the connected components of the graph joining points
    within ``gap`` of each other, numbered by their first point (as scipy's
    ``connected_components`` numbers the graph's components). Union-find over a grid of
    cells ``gap / sqrt(2)`` wide: the points of a cell are all within ``gap`` of each
    other, and two cells up to two apart join at their first close pair. Listing every
    close pair instead (``cKDTree.query_pairs``) gave 15 million pairs for a Kinect
    frame's 69,000 jump pairs: 2.1 s of its 2.7 s segmentation.

    Examples
    --------
    >>> close_components(np.array([[0.0, 0], [5, 0], [0.9, 0], [1.8, 0], [5.5, 0]]), 1.0).tolist()
    [0, 1, 0, 0, 1]
    """
    pts = np.ascontiguousarray(xy, dtype=np.float64).reshape(-1, 2)
    n = len(pts)
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    if not (np.isfinite(pts).all() and gap > 0 and np.isfinite(gap)):
        raise ValueError("close_components: points must be finite and gap > 0")
    cell = gap / np.sqrt(2.0)
    lo, hi = bounds(pts)
    # cell (i, j) has the key i * 2**32 + j: below 2**31 cells a side, a neighbour's key
    # two cells away stays within int64 (copies of a point, 1e-9 of the extent apart:
    # 1.4e9 cells a side)
    if not float((hi - lo).max()) / cell < 2**31 - 8:  # too many cells: list the pairs
        from scipy.sparse import coo_matrix
        from scipy.sparse.csgraph import connected_components
        from scipy.spatial import cKDTree

        pairs = cKDTree(pts).query_pairs(gap, output_type="ndarray")
        if len(pairs) == 0:
            return np.arange(n, dtype=np.int64)
        graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
        return connected_components(graph, directed=False)[1].astype(np.int64)
    ij = np.floor((pts - lo) / cell).astype(np.int64)
    key = ij[:, 0] * (2**32) + ij[:, 1]
    order = np.argsort(key, kind="stable")
    key = key[order]
    start = np.flatnonzero(np.r_[True, key[1:] != key[:-1], True])  # cells' runs
    keys = key[start[:-1]]
    return _close_components(pts, float(gap) * float(gap), order, keys, start)


@njit(cache=True, nogil=True)
def _find(parent, a):
    while parent[a] != a:
        parent[a] = parent[parent[a]]
        a = parent[a]
    return a


@njit(cache=True, nogil=True)
def _close_components(pts, g2, order, keys, start):
    n = pts.shape[0]
    parent = np.arange(n)
    m = keys.shape[0]
    for c in range(m):  # a cell's points are within gap of each other
        first = order[start[c]]
        for t in range(start[c] + 1, start[c + 1]):
            ra, rb = _find(parent, first), _find(parent, order[t])
            if ra != rb:
                parent[max(ra, rb)] = min(ra, rb)
    # the cells up to two ahead, each pair of cells once: (0, 1), (0, 2), (1, -2) ...
    offs = np.empty(12, np.int64)
    o = 0
    for dx in range(3):
        for dy in range(-2, 3):
            if dx > 0 or dy > 0:
                offs[o] = dx * (2**32) + dy
                o += 1
    # keys are sorted and each neighbour's key grows with the cell's: one pointer per
    # offset walks forward (a binary search per cell and offset took 22 ms of 27 on the
    # face map's 85,000 points)
    ptr = np.zeros(12, np.int64)
    for c in range(m):
        for o in range(12):
            nb = keys[c] + offs[o]
            d = ptr[o]
            while d < m and keys[d] < nb:
                d += 1
            ptr[o] = d
            if d >= m or keys[d] != nb:
                continue
            if _find(parent, order[start[c]]) == _find(parent, order[start[d]]):
                continue
            joined = False
            for t in range(start[c], start[c + 1]):
                a = order[t]
                for u in range(start[d], start[d + 1]):
                    b = order[u]
                    ex = pts[a, 0] - pts[b, 0]
                    ey = pts[a, 1] - pts[b, 1]
                    if ex * ex + ey * ey <= g2:
                        ra, rb = _find(parent, a), _find(parent, b)
                        parent[max(ra, rb)] = min(ra, rb)
                        joined = True
                        break
                if joined:
                    break
    out = np.full(n, -1, dtype=np.int64)
    label = np.full(n, -1, dtype=np.int64)
    k = 0
    for i in range(n):
        r = _find(parent, i)
        if label[r] < 0:
            label[r] = k
            k += 1
        out[i] = label[r]
    return out


def smooth_fits(xy: np.ndarray, z: np.ndarray, tris: np.ndarray, k: int, fit: float,
                grid: tuple, floor: float = 0.0, rms: np.ndarray | None = None) -> np.ndarray:
    """(M,) bool: whether a quadratic height field fits the ``k`` points around each row.

    Rows of ``tris`` (M, 2 or 3) are point indices; the ``k`` points of ``xy`` nearest to a
    row's centroid (``grid``: :func:`~asrbf_mesh._grid_knn.point_grid` of ``xy``) get a
    least-squares ``z = c0 + c1 u + c2 v + c3 u^2 + c4 uv + c5 v^2`` in coordinates
    scaled by the farthest of them; True where its RMS residual is under ``fit`` times
    the row's own depth extent or under ``floor``. With ``rms`` ((M,) float64), each
    row's RMS residual is written there too (NaN where no fit). Each row's fit is its
    own, so the rows run in parts on threads
    (:func:`~asrbf_mesh._network_kernels.in_threads`).
    """
    from ._network_kernels import in_threads, threads_for

    tris = np.ascontiguousarray(tris, np.int64)
    out = np.zeros(len(tris), dtype=np.bool_)
    if len(tris) and (tris.min() < 0 or tris.max() >= len(xy)):
        raise ValueError("smooth_fits: a row indexes no point")
    if len(tris) == 0 or not 6 <= k <= len(xy):
        return out
    if rms is None:
        rms = np.empty(len(tris))
    rms[:] = np.nan
    in_threads(_smooth_fits, len(tris), threads_for(len(tris)),
               np.ascontiguousarray(xy, np.float64), np.ascontiguousarray(z, np.float64),
               tris, int(k), float(fit), float(floor), *grid, out, rms)
    return out


@njit(cache=True, nogil=True)
def _smooth_fits(xy, z, tris, k, fit, floor, lo, h, gx, gy, start, items, out, rms, i0, i1):
    corners = tris.shape[1]
    best_d = np.empty(k)
    best_i = np.empty(k, np.int64)
    q = np.empty(2)
    a = np.empty(6)
    ata = np.empty((6, 6))
    atb = np.empty(6)
    zn = np.empty(k)
    for i in range(i0, i1):
        cx = 0.0
        cy = 0.0
        zlo = np.inf
        zhi = -np.inf
        for c in range(corners):
            p = tris[i, c]
            cx += xy[p, 0]
            cy += xy[p, 1]
            zlo = min(zlo, z[p])
            zhi = max(zhi, z[p])
        q[0] = cx / corners
        q[1] = cy / corners
        held = _nearest(xy, q, k, lo, h, gx, gy, start, items, best_d, best_i)
        reach = max(np.sqrt(best_d[held - 1]), 1e-300)
        zm = 0.0
        for t in range(held):
            zm += z[best_i[t]]
        zm /= held
        for r in range(6):
            atb[r] = 0.0
            for c in range(6):
                ata[r, c] = 1e-9 if r == c else 0.0
        for t in range(held):
            _quadratic_row(xy, q, reach, best_i[t], a)
            zn[t] = z[best_i[t]] - zm
            for r in range(6):
                atb[r] += a[r] * zn[t]
                for c in range(r + 1):
                    ata[r, c] += a[r] * a[c]
        if not _cholesky_solve6(ata, atb):
            continue  # no fit: not smooth
        ss = 0.0
        for t in range(held):
            _quadratic_row(xy, q, reach, best_i[t], a)
            res = zn[t]
            for r in range(6):
                res -= a[r] * atb[r]
            ss += res * res
        rms[i] = np.sqrt(ss / held)
        out[i] = rms[i] < max(fit * (zhi - zlo), floor)


@njit(cache=True, inline="always")
def _quadratic_row(xy, q, reach, j, a):
    u = (xy[j, 0] - q[0]) / reach
    v = (xy[j, 1] - q[1]) / reach
    a[0] = 1.0
    a[1] = u
    a[2] = v
    a[3] = u * u
    a[4] = u * v
    a[5] = v * v


@njit(cache=True, nogil=True)
def _cholesky_solve6(m, b):
    """Solve ``m x = b`` in place (x in ``b``) from ``m``'s lower triangle; False if not PD."""
    for j in range(6):
        d = m[j, j]
        for t in range(j):
            d -= m[j, t] * m[j, t]
        if not d > 0.0:
            return False
        d = np.sqrt(d)
        m[j, j] = d
        for r in range(j + 1, 6):
            s = m[r, j]
            for t in range(j):
                s -= m[r, t] * m[j, t]
            m[r, j] = s / d
    for r in range(6):  # L y = b
        s = b[r]
        for t in range(r):
            s -= m[r, t] * b[t]
        b[r] = s / m[r, r]
    for r in range(5, -1, -1):  # L^T x = y
        s = b[r]
        for t in range(r + 1, 6):
            s -= m[t, r] * b[t]
        b[r] = s / m[r, r]
    return True


def nearest_seed(indptr: np.ndarray, indices: np.ndarray, weights: np.ndarray,
                 labels: np.ndarray, seeds: np.ndarray) -> np.ndarray:
    """(N,) int64: the seed nearest to each point along the graph, -1 if none reaches it.

    The graph is CSR (``indptr``, ``indices``, ``weights`` >= 0, both directions of
    each edge); a search runs only through points of the seeds' label (``labels``, and
    the seeds must share one). Many searches on one graph: :class:`SeedGraph`.

    Examples
    --------
    >>> ip, ix = np.array([0, 1, 3, 5, 6]), np.array([1, 0, 2, 1, 3, 2])
    >>> nearest_seed(ip, ix, np.ones(6), np.zeros(4, np.int64), np.array([0, 3])).tolist()
    [0, 0, 3, 3]
    """
    return SeedGraph(indptr, indices, weights).nearest(labels, seeds)


class SeedGraph:
    """A CSR graph checked once for many :meth:`nearest` searches (see :func:`nearest_seed`).

    On a Kinect frame's 1.2 million edges, checking and converting the arrays at each of
    the segmentation's 36 searches cost as much as a third of the searches themselves.
    """

    def __init__(self, indptr: np.ndarray, indices: np.ndarray, weights: np.ndarray):
        n = len(indptr) - 1
        self.indptr = np.ascontiguousarray(indptr, dtype=np.int64)
        self.indices = np.ascontiguousarray(indices, dtype=np.int64)
        self.weights = np.ascontiguousarray(weights, dtype=np.float64)
        if (n < 0 or self.indptr[0] != 0 or self.indptr[-1] != len(self.indices)
                or len(self.weights) != len(self.indices) or np.any(np.diff(self.indptr) < 0)
                or (len(self.indices) and (self.indices.min() < 0 or self.indices.max() >= n))
                or not np.all(self.weights >= 0)):
            raise ValueError("nearest_seed: the graph does not hold together")
        self.n = n

    def nearest(self, labels: np.ndarray, seeds: np.ndarray) -> np.ndarray:
        """(N,) int64: each point's nearest seed along the graph, in the seeds' piece."""
        labels = np.ascontiguousarray(labels, dtype=np.int64)
        seeds = np.ascontiguousarray(seeds, dtype=np.int64)
        if len(labels) != self.n or (len(seeds) and (seeds.min() < 0 or seeds.max() >= self.n)):
            raise ValueError("nearest_seed: the graph, labels or seeds do not agree")
        source = np.full(self.n, -1, dtype=np.int64)
        if len(seeds) == 0:
            return source
        if np.any(labels[seeds] != labels[seeds[0]]):
            raise ValueError("nearest_seed: the seeds lie in more than one piece")
        _dijkstra(self.indptr, self.indices, self.weights, labels, labels[seeds[0]], seeds,
                  source)
        return source


@njit(cache=True, nogil=True)
def _dijkstra(indptr, indices, weights, labels, piece, seeds, source):
    n = len(indptr) - 1
    dist = np.full(n, np.inf)
    cap = len(indices) + len(seeds) + 1
    hd = np.empty(cap)  # a binary heap of (distance, point), stale entries skipped
    hp = np.empty(cap, dtype=np.int64)
    size = 0
    for s in seeds:
        if dist[s] > 0.0:
            dist[s] = 0.0
            source[s] = s
            size = _push(hd, hp, size, 0.0, s)
    while size > 0:
        d, u = hd[0], hp[0]
        size -= 1
        hd[0], hp[0] = hd[size], hp[size]
        _sift_down(hd, hp, size)
        if d > dist[u]:
            continue
        for t in range(indptr[u], indptr[u + 1]):
            v = indices[t]
            if labels[v] != piece:
                continue
            nd = d + weights[t]
            if nd < dist[v]:
                dist[v] = nd
                source[v] = source[u]
                size = _push(hd, hp, size, nd, v)
    return source


@njit(cache=True, nogil=True)
def _push(hd, hp, size, d, p):
    i = size
    hd[i], hp[i] = d, p
    while i > 0:
        parent = (i - 1) // 2
        if hd[parent] <= hd[i]:
            break
        hd[parent], hd[i] = hd[i], hd[parent]
        hp[parent], hp[i] = hp[i], hp[parent]
        i = parent
    return size + 1


@njit(cache=True, nogil=True)
def _sift_down(hd, hp, size):
    i = 0
    while True:
        left = 2 * i + 1
        if left >= size:
            break
        child = left
        if left + 1 < size and hd[left + 1] < hd[left]:
            child = left + 1
        if hd[i] <= hd[child]:
            break
        hd[i], hd[child] = hd[child], hd[i]
        hp[i], hp[child] = hp[child], hp[i]
        i = child
