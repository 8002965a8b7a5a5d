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
from scipy.linalg.lapack import dgesv

from . import _jit_cache  # noqa: F401 (first: where numba caches the kernels below)


@njit(cache=True)
def _orient(ax, ay, bx, by, cx, cy):
    return (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)


@njit(cache=True, inline="always")
def _corners(xy, faces, t):
    """Return the view-plane corners of triangle ``t``: ax, ay, bx, by, cx, cy."""
    a = faces[t, 0]
    b = faces[t, 1]
    c = faces[t, 2]
    return xy[a, 0], xy[a, 1], xy[b, 0], xy[b, 1], xy[c, 0], xy[c, 1]


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
               cand: np.ndarray, *, closed: bool = False) -> np.ndarray:
    """For each point, whether it lies strictly inside one of its candidate triangles.

    ``cand`` holds each point's candidate triangle indices, (M, k) or (M,) as a
    ``cKDTree.query`` returns them for ``k`` = 1; an index past the last triangle
    (``cKDTree``'s "no neighbour") or below 0 is skipped. With ``closed``, a point on a
    triangle's edge or corner counts as inside too (within 1e-9 of its doubled area):
    the centroid of a patch triangle laid over scan triangles on a lattice can fall
    exactly on one of their corners.
    """
    points = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 2)
    xy, faces = _faces_in(xy, faces, "inside_any")
    cand = np.asarray(cand, dtype=np.int64).reshape(len(points), -1)
    cand = np.where((cand >= 0) & (cand < len(faces)), cand, -1)
    return _inside_any(points, xy, faces, np.ascontiguousarray(cand), closed)


@njit(cache=True, nogil=True)
def _coverage(xy, faces, lo, cell, nx, ny):
    """Raster (ny, nx) of cells whose centre lies in (or on) some triangle, in xy."""
    out = np.zeros((ny, nx), np.bool_)
    for t in range(faces.shape[0]):
        ax, ay, bx, by, cx, cy = _corners(xy, faces, t)
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
def _inside_any(points, xy, faces, cand, closed):
    """For each point p, whether it lies inside one of the candidate triangles cand[p].

    Strictly inside, or with ``closed`` on its boundary too.
    """
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
            eps = -1e-9 * abs(area) if closed else 1e-9 * abs(area)
            w0 = s * _orient(xy[b, 0], xy[b, 1], xy[c, 0], xy[c, 1], px, py)
            w1 = s * _orient(xy[c, 0], xy[c, 1], xy[a, 0], xy[a, 1], px, py)
            w2 = s * _orient(xy[a, 0], xy[a, 1], xy[b, 0], xy[b, 1], px, py)
            if w0 > eps and w1 > eps and w2 > eps:
                out[p] = True
                break
    return out


def grid_triangle_depths(gx: np.ndarray, gy: np.ndarray, xyz: np.ndarray,
                         faces: np.ndarray, face_piece: np.ndarray,
                         vertex_key: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Depth of a triangle mesh under grid vertices, each from a triangle of its piece.

    ``gx``, ``gy`` are the grid's increasing node coordinates (nodes row-major, x
    fastest), ``xyz`` (V, 3) the triangles' corners (view-plane place and depth),
    ``face_piece`` each triangle's piece (-1: none), ``vertex_key`` each grid vertex's
    ``piece * len(gx) * len(gy) + node`` (-1: skipped). A vertex whose node lies inside a
    triangle of its piece (on its boundary too) takes the depth of that triangle's plane
    there, the first such triangle's where several overlap. Each triangle visits only
    the nodes of its bounding box. Returns each vertex's depth and triangle (NaN, -1
    where none holds it).
    """
    gx = np.ascontiguousarray(gx, dtype=np.float64).ravel()
    gy = np.ascontiguousarray(gy, dtype=np.float64).ravel()
    xyz = np.ascontiguousarray(xyz, dtype=np.float64)
    if xyz.ndim != 2 or xyz.shape[1] != 3:
        raise ValueError(f"grid_triangle_depths: corners must have shape (V, 3), got "
                         f"{xyz.shape}")
    if len(gx) < 2 or len(gy) < 2 or np.any(np.diff(gx) <= 0) or np.any(np.diff(gy) <= 0):
        raise ValueError("grid_triangle_depths: the grid needs increasing nodes, 2+ per axis")
    xy, faces = _faces_in(xyz[:, :2], faces, "grid_triangle_depths")
    face_piece = np.ascontiguousarray(face_piece, dtype=np.int64).ravel()
    key = np.ascontiguousarray(vertex_key, dtype=np.int64).ravel()
    if len(face_piece) != len(faces):
        raise ValueError("grid_triangle_depths: one piece per triangle")
    order = np.argsort(key, kind="stable")
    return _grid_triangle_depths(gx, gy, xy, np.ascontiguousarray(xyz[:, 2]), faces,
                                 face_piece, key[order], order)


@njit(cache=True, nogil=True)
def _grid_triangle_depths(gx, gy, xy, z, faces, face_piece, keys, vertex):
    """Depth and triangle under each vertex (``keys`` sorted, ``vertex`` their owners)."""
    nx, ny = gx.shape[0], gy.shape[0]
    n = keys.shape[0]
    depth = np.full(n, np.nan)
    which = np.full(n, -1, np.int64)
    for t in range(faces.shape[0]):
        p = face_piece[t]
        if p < 0:
            continue
        ax, ay, bx, by, cx, cy = _corners(xy, faces, t)
        area = _orient(ax, ay, bx, by, cx, cy)
        if area == 0.0 or not np.isfinite(area):
            continue
        i0 = np.searchsorted(gx, min(ax, bx, cx))
        i1 = np.searchsorted(gx, max(ax, bx, cx), side="right")
        j0 = np.searchsorted(gy, min(ay, by, cy))
        j1 = np.searchsorted(gy, max(ay, by, cy), side="right")
        base = p * nx * ny
        for j in range(j0, j1):
            py = gy[j]
            for i in range(i0, i1):
                key = base + j * nx + i
                k = np.searchsorted(keys, key)
                if k >= n or keys[k] != key:
                    continue
                v = vertex[k]
                if which[v] >= 0:
                    continue
                px = gx[i]
                w0 = _orient(bx, by, cx, cy, px, py) / area
                w1 = _orient(cx, cy, ax, ay, px, py) / area
                w2 = 1.0 - w0 - w1
                if w0 >= -1e-9 and w1 >= -1e-9 and w2 >= -1e-9:
                    depth[v] = (w0 * z[faces[t, 0]] + w1 * z[faces[t, 1]]
                                + w2 * z[faces[t, 2]])
                    which[v] = t
    return depth, which


def walk_cycles(half_edges: np.ndarray) -> list[np.ndarray]:
    """Walk boundary half-edges (E, 2), sorted by (start, end), into closed cycles.

    From each half-edge not yet walked, follow the first unused half-edge out of each
    vertex reached until the walk comes back to its start (a cycle, kept with 3 or more
    vertices) or finds no way out (dropped). See
    :func:`asrbf_mesh._hole_loops.boundary_cycles`.
    """
    e = np.ascontiguousarray(half_edges, dtype=np.int64).reshape(-1, 2)
    if len(e) == 0:
        return []
    if e.min() < 0 or np.any(np.diff(e[:, 0]) < 0):
        raise ValueError("walk_cycles: half-edges must be sorted, with vertex ids >= 0")
    starts = np.searchsorted(e[:, 0], np.arange(int(e.max()) + 2)).astype(np.int64)
    verts, ends = _walk_cycles(e, starts)
    return [verts[a:b].copy() for a, b in zip(np.r_[0, ends][:-1], ends, strict=True)]


@njit(cache=True)
def _walk_cycles(e, starts):
    """Vertices of the closed walks, concatenated, and each walk's end offset."""
    m = e.shape[0]
    used = np.zeros(m, np.bool_)
    verts = np.empty(m, np.int64)
    ends = np.empty(m, np.int64)
    n_out = 0
    n_cyc = 0
    for first in range(m):
        if used[first]:
            continue
        length = 1
        verts[n_out] = e[first, 0]
        cur = first
        closed = False
        while True:
            used[cur] = True
            nxt = e[cur, 1]
            if nxt == verts[n_out]:
                closed = True
                break
            k = starts[nxt]
            while k < starts[nxt + 1] and used[k]:
                k += 1
            if k == starts[nxt + 1]:
                break
            verts[n_out + length] = nxt
            length += 1
            cur = k
        if closed and length >= 3:
            n_out += length
            ends[n_cyc] = n_out
            n_cyc += 1
    return verts[:n_out], ends[:n_cyc]


def once(edges: np.ndarray) -> np.ndarray:
    """Whether each of the (E, 2) vertex pairs occurs once in ``edges``, either way round.

    The pairs are bucketed by their smaller vertex (a counting sort) and counted within
    each bucket: linear in E (0.05 s on a filled Kinect frame's 1.8 million half-edges,
    where ``np.unique`` over one key per pair took 0.35 s).
    """
    e = np.ascontiguousarray(edges, dtype=np.int64).reshape(-1, 2)
    if len(e) == 0:
        return np.zeros(0, dtype=bool)
    if e.min() < 0:
        raise ValueError("once: vertex ids must be >= 0")
    return _once(e, int(e.max()) + 1)


@njit(cache=True, nogil=True)
def _buckets(key, n):
    """Sort ``key`` (values in [0, n)) by counting: (bucket starts, entries in order)."""
    start = np.zeros(n + 1, np.int64)
    for t in range(key.shape[0]):
        start[key[t] + 1] += 1
    for v in range(n):
        start[v + 1] += start[v]
    fill = start[:n].copy()
    entry = np.empty(key.shape[0], np.int64)
    for t in range(key.shape[0]):
        entry[fill[key[t]]] = t
        fill[key[t]] += 1
    return start, entry


@njit(cache=True, nogil=True)
def _once(e, n):
    m = e.shape[0]
    small = np.empty(m, np.int64)
    big = np.empty(m, np.int64)
    for t in range(m):
        small[t] = min(e[t, 0], e[t, 1])
        big[t] = max(e[t, 0], e[t, 1])
    start, entry = _buckets(small, n)
    other = big[entry]  # in bucket order: each bucket's larger ends side by side
    out = np.zeros(m, np.bool_)
    for v in range(n):
        for i in range(start[v], start[v + 1]):
            c = 0
            for j in range(start[v], start[v + 1]):
                if other[j] == other[i]:
                    c += 1
            out[entry[i]] = c == 1
    return out


def face_faults(faces: np.ndarray) -> tuple[np.ndarray, int, int]:
    """Find copies among (F, 3) faces of distinct vertices, and edges whose faces disagree.

    Returns whether each face repeats the vertices of an earlier one (any order), how
    many edges shared by exactly two faces (copies counted) run the same way in both, and
    how many edges have more than two faces.
    Faces bucketed by their smallest vertex, half-edges by their smaller one (counting
    sorts, as :func:`once`): linear in F (``np.unique`` over keys took 0.14 s on the face
    map's 166 thousand faces, 0.40 s on a Kinect frame's 391 thousand).
    """
    f = np.ascontiguousarray(faces, dtype=np.int64).reshape(-1, 3)
    if len(f) == 0:
        return np.zeros(0, dtype=bool), 0, 0
    if f.min() < 0:
        raise ValueError("face_faults: vertex ids must be >= 0")
    copy, turned, over = _face_faults(f, int(f.max()) + 1)
    return copy, int(turned), int(over)


@njit(cache=True, nogil=True)
def _face_faults(f, n):
    m = f.shape[0]
    lo = np.empty(m, np.int64)
    mid = np.empty(m, np.int64)
    hi = np.empty(m, np.int64)
    for t in range(m):
        a, b, c = f[t, 0], f[t, 1], f[t, 2]
        lo[t] = min(a, min(b, c))
        hi[t] = max(a, max(b, c))
        mid[t] = a + b + c - lo[t] - hi[t]
    start, entry = _buckets(lo, n)
    copy = np.zeros(m, np.bool_)
    for v in range(n):
        for i in range(start[v], start[v + 1]):
            t = entry[i]  # entries of a bucket in face order: the first copy stays
            for j in range(start[v], i):
                u = entry[j]
                if mid[u] == mid[t] and hi[u] == hi[t]:
                    copy[t] = True
                    break
    # half-edges: (from, to) of face t's edge k, bucketed by the smaller end
    e_from = np.empty(3 * m, np.int64)
    e_to = np.empty(3 * m, np.int64)
    small = np.empty(3 * m, np.int64)
    for t in range(m):
        for k in range(3):
            a, b = f[t, k], f[t, (k + 1) % 3]
            e_from[3 * t + k] = a
            e_to[3 * t + k] = b
            small[3 * t + k] = min(a, b)
    start, entry = _buckets(small, n)
    turned = 0
    over = 0
    for v in range(n):
        for i in range(start[v], start[v + 1]):
            p = entry[i]
            big = max(e_from[p], e_to[p])
            count = 0
            first = -1
            for j in range(start[v], start[v + 1]):
                q = entry[j]
                if max(e_from[q], e_to[q]) == big:
                    count += 1
                    if first < 0:
                        first = j
            if count > 2 and first == i:
                over += 1
            # each shared edge once (at its first half-edge), when exactly two share it
            if count == 2 and first == i:
                for j in range(i + 1, start[v + 1]):
                    q = entry[j]
                    if max(e_from[q], e_to[q]) == big:
                        if e_from[q] == e_from[p]:
                            turned += 1
                        break
    return copy, turned, over


def distance_to_false(mask: np.ndarray) -> np.ndarray:
    """Euclidean distance (in cells) of each cell of a 2D bool raster to its nearest False.

    The same values as ``scipy.ndimage.distance_transform_edt(mask)`` (0 on False cells),
    by Felzenszwalb and Huttenlocher's two passes of exact squared distances (columns,
    then the lower envelope of parabolas along rows): 0.37 s on a Kinect frame's 16
    million cells, where scipy's feature transform took 0.8-1.6 s.
    A raster with no False cell raises (its distances are not defined).
    """
    mask = np.ascontiguousarray(mask, dtype=np.bool_)
    if mask.ndim != 2:
        raise ValueError(f"distance_to_false: a 2D raster is needed, got {mask.ndim}D")
    if mask.all():
        raise ValueError("distance_to_false: the raster has no False cell")
    return _edt(mask)


@njit(cache=True, nogil=True)
def _edt(mask):
    ny, nx = mask.shape
    big = float(ny + nx) ** 2 + 1.0  # above any squared distance inside the raster
    d2 = np.empty((ny, nx))
    for j in range(nx):  # pass 1: squared distance along each column
        last = -1
        for i in range(ny):
            if not mask[i, j]:
                last = i
            d2[i, j] = big if last < 0 else float(i - last) ** 2
        last = -1
        for i in range(ny - 1, -1, -1):
            if not mask[i, j]:
                last = i
            elif last >= 0:
                d2[i, j] = min(d2[i, j], float(last - i) ** 2)
    f = np.empty(nx)
    v = np.empty(nx, np.int64)
    z = np.empty(nx + 1)
    for i in range(ny):  # pass 2: the lower envelope of the parabolas along each row
        for j in range(nx):
            f[j] = d2[i, j]
        k = -1
        for q in range(nx):
            if f[q] >= big:
                continue
            if k < 0:
                k = 0
                v[0] = q
                z[0] = -np.inf
                z[1] = np.inf
                continue
            s = ((f[q] + q * q) - (f[v[k]] + v[k] * v[k])) / (2.0 * (q - v[k]))
            while s <= z[k]:
                k -= 1
                s = ((f[q] + q * q) - (f[v[k]] + v[k] * v[k])) / (2.0 * (q - v[k]))
            k += 1
            v[k] = q
            z[k] = s
            z[k + 1] = np.inf
        if k < 0:  # no column of this row sees a False cell: none in the raster
            continue
        k = 0
        for q in range(nx):
            while z[k + 1] < q:
                k += 1
            d2[i, q] = float(q - v[k]) ** 2 + f[v[k]]
    return np.sqrt(d2)


def thin_plate(centres: np.ndarray, values: np.ndarray, smoothing: float = 0.0,
               cubic: float = 0.0, quintic: bool = False) -> tuple[np.ndarray, ...] | None:
    """Thin-plate spline in 2D, linear term (or its mean with a cubic one, or a quintic), or None.

    ``s(x) = sum_j w_j phi(|x - y_j|) + a_0 + a . (x - shift) / scale``, ``phi(r) = r^2
    log r``, the polynomial on the centres' box mapped to [-1, 1] (as scipy's
    ``RBFInterpolator`` does); interpolating, or with ``smoothing`` added to the kernel
    matrix's diagonal (scipy's ``smoothing``) a smoothing spline. With ``cubic`` > 0 the
    result is ``(1 - cubic)`` times that spline plus ``cubic`` times the same spline of
    the kernel ``r^3`` (scipy's ``"cubic"``): both fitted to the data, their values
    averaged. With ``quintic``, instead, the one spline of the kernel ``-r^5`` with a
    quadratic term (scipy's ``"quintic"``, degree 2): it follows a curvature the data hold
    (a quadratic exactly), where the thin plate flattens. Returns (centres, weights (n, 3):
    thin plate's, cubic's and quintic's, a (6: 1, x, y, x^2, xy, y^2), shift, scale) for
    :func:`ray_depths`, None when the centres are fewer than 3 (6 for ``quintic``) or on
    one line (for ``quintic``, on one conic), or a system is singular (points repeated).
    """
    y = np.ascontiguousarray(centres, dtype=np.float64).reshape(-1, 2)
    d = np.ascontiguousarray(values, dtype=np.float64).ravel()
    n = len(y)
    if n < 3 or len(d) != n or not (np.all(np.isfinite(y)) and np.all(np.isfinite(d))):
        return None
    lo, hi = y.min(axis=0), y.max(axis=0)
    shift = 0.5 * (lo + hi)
    scale = 0.5 * (hi - lo)
    scale[scale == 0.0] = 1.0
    x = (y - shift) / scale
    P = np.column_stack([np.ones(n), x])
    if quintic:
        P = np.column_stack([P, x[:, 0] ** 2, x[:, 0] * x[:, 1], x[:, 1] ** 2])
    m = P.shape[1]
    if n < m or np.linalg.matrix_rank(P) < m:
        return None
    w = np.zeros((n, 3))
    a = np.zeros(6)
    for kernel, share in ((2, 1.0),) if quintic else ((0, 1.0 - cubic), (1, cubic)):
        if share <= 0.0:
            continue
        A = np.zeros((n + m, n + m))
        A[:n, :n] = _gram(y, kernel)
        if smoothing > 0.0:
            A[np.arange(n), np.arange(n)] += smoothing
        A[:n, n:] = P
        A[n:, :n] = P.T
        # scipy's LAPACK, as its RBFInterpolator does (numpy's solve: two fills side by
        # side, a batch's or the benchmark's workers, ran 2x slower in its OpenBLAS threads)
        _, _, sol, info = dgesv(A, np.r_[d, np.zeros(m)])
        if info != 0 or not np.all(np.isfinite(sol)):
            return None
        w[:, kernel] = share * sol[:n]
        a[:m] += share * sol[n:]
    return y, w, a, shift, scale


def ray_depths(q: np.ndarray, c: np.ndarray, axes: np.ndarray, normal: np.ndarray,
               size: float, spline: tuple[np.ndarray, ...], done: float,
               ok: float) -> np.ndarray:
    """Depth where the view ray (along z) through each xy point ``q`` meets a surface.

    The surface is the points ``c + size (u axes_0 + v axes_1) + size s(u, v) normal``
    with ``s`` a :func:`thin_plate` spline (or the mean of two). Secant iterations along
    the ray, from its meeting with the plane (s = 0) and 0.01 x ``size`` beyond, stop once
    the ray is ``done`` x ``size`` from the surface (at most 8 steps); a ray still farther
    than ``ok`` x ``size`` gives NaN. (Newton's iterations met more rays, but on a plane seen
    obliquely a fifth of them at another crossing of the surface, up to 0.4 x ``size``
    away: the fill takes the view plane where the secant finds no crossing near the
    plane.)
    """
    from ._network_kernels import in_threads, threads_for

    q = np.ascontiguousarray(q, dtype=np.float64).reshape(-1, 2)
    y, w, a, shift, scale = spline
    out = np.empty(len(q))
    # each ray costs a spline's worth of terms per step: the threads pay from few rays on
    in_threads(_ray_depths, len(q), threads_for(len(q) * len(y) // 64), q,
               np.ascontiguousarray(c, dtype=np.float64),
               np.ascontiguousarray(axes, dtype=np.float64),
               np.ascontiguousarray(normal, dtype=np.float64), float(size),
               y, w, a, shift, scale, float(done), float(ok), out)
    return out


@njit(cache=True)
def _gram(y, kernel):
    """Kernel matrix of the centres: ``r^2 log r`` (kernel 0), ``r^3`` (1) or ``-r^5`` (2)."""
    n = y.shape[0]
    K = np.zeros((n, n))
    w0 = 1.0 if kernel == 0 else 0.0
    w1 = 1.0 if kernel == 1 else 0.0
    w2 = 1.0 if kernel == 2 else 0.0
    for i in range(n):
        for j in range(i + 1, n):
            dx = y[i, 0] - y[j, 0]
            dy = y[i, 1] - y[j, 1]
            v = _phi(dx * dx + dy * dy, w0, w1, w2)
            K[i, j] = v
            K[j, i] = v
    return K


@njit(cache=True, nogil=True, inline="always")
def _phi(r2, w_plate, w_cubic, w_quintic):
    """``w_plate r^2 log r + w_cubic r^3 - w_quintic r^5`` at squared distance ``r2``."""
    out = 0.0
    if r2 > 0.0:
        if w_plate != 0.0:
            out += w_plate * 0.5 * r2 * np.log(r2)
        if w_cubic != 0.0:
            out += w_cubic * r2 * np.sqrt(r2)
        if w_quintic != 0.0:
            out -= w_quintic * r2 * r2 * np.sqrt(r2)
    return out


@njit(cache=True, nogil=True)
def _tps_value(u, v, y, w, a, shift, scale):
    s = a[0] + a[1] * (u - shift[0]) / scale[0] + a[2] * (v - shift[1]) / scale[1]
    if a[3] != 0.0 or a[4] != 0.0 or a[5] != 0.0:  # the quintic's quadratic term
        x0 = (u - shift[0]) / scale[0]
        x1 = (v - shift[1]) / scale[1]
        s += a[3] * x0 * x0 + a[4] * x0 * x1 + a[5] * x1 * x1
    for j in range(y.shape[0]):
        dx = u - y[j, 0]
        dy = v - y[j, 1]
        s += _phi(dx * dx + dy * dy, w[j, 0], w[j, 1], w[j, 2])
    return s


@njit(cache=True, nogil=True)
def _ray_gap(px, py, z, axes, nrm, size, y, w, a, shift, scale):
    """Signed distance along the normal from the ray's point (px, py, z) to the surface."""
    u = (px * axes[0, 0] + py * axes[0, 1] + z * axes[0, 2]) / size
    v = (px * axes[1, 0] + py * axes[1, 1] + z * axes[1, 2]) / size
    return (px * nrm[0] + py * nrm[1] + z * nrm[2]
            - size * _tps_value(u, v, y, w, a, shift, scale))


@njit(cache=True, nogil=True)
def _ray_depths(q, c, axes, nrm, size, y, w, a, shift, scale, done, ok, out, i0, i1):
    for p in range(i0, i1):
        px = q[p, 0] - c[0]
        py = q[p, 1] - c[1]
        z0 = -(px * nrm[0] + py * nrm[1]) / nrm[2]  # on the plane, relative to c
        z1 = z0 + 0.01 * size
        f0 = _ray_gap(px, py, z0, axes, nrm, size, y, w, a, shift, scale)
        f1 = _ray_gap(px, py, z1, axes, nrm, size, y, w, a, shift, scale)
        for _ in range(8):
            if abs(f1) <= done * size:
                break
            den = f1 - f0
            z2 = z1 - f1 * (z1 - z0) / den if abs(den) > 1e-300 else z1
            z0, f0 = z1, f1
            z1 = z2
            f1 = _ray_gap(px, py, z1, axes, nrm, size, y, w, a, shift, scale)
        out[p] = c[2] + z1 if abs(f1) <= ok * size else np.nan


def touching(pts: np.ndarray, seg: np.ndarray, tol: float) -> tuple[np.ndarray, ...]:
    """Vertices within ``tol`` of a segment's inside (not one of its ends).

    Returns (segment, vertex, t) per hit, ``t`` in (0, 1) the vertex's place along the
    segment; ``pts`` (n, 2) float64 and ``seg`` (m, 2) int64 indexing them.
    """
    pts = np.ascontiguousarray(pts, dtype=np.float64).reshape(-1, 2)
    seg = np.ascontiguousarray(seg, dtype=np.int64).reshape(-1, 2)
    if len(seg) and (seg.min() < 0 or seg.max() >= len(pts)):
        raise ValueError("touching: a segment indexes no point")
    order = np.argsort(pts[:, 0], kind="stable")
    return _touching(pts, seg, float(tol), order, np.ascontiguousarray(pts[order, 0]))


@njit(cache=True, nogil=True)
def _touching(pts, seg, tol, order, xs):
    hits_s, hits_v, hits_t = [], [], []
    for s in range(seg.shape[0]):
        a, b = seg[s, 0], seg[s, 1]
        ax, ay, bx, by = pts[a, 0], pts[a, 1], pts[b, 0], pts[b, 1]
        dx, dy = bx - ax, by - ay
        L2 = dx * dx + dy * dy
        if L2 == 0.0:
            continue
        lo = np.searchsorted(xs, min(ax, bx) - tol)
        hi = np.searchsorted(xs, max(ax, bx) + tol, side="right")
        ylo, yhi = min(ay, by) - tol, max(ay, by) + tol
        for k in range(lo, hi):
            v = order[k]
            if v == a or v == b:
                continue
            px, py = pts[v, 0], pts[v, 1]
            if py < ylo or py > yhi:
                continue
            t = ((px - ax) * dx + (py - ay) * dy) / L2
            if t <= 0.0 or t >= 1.0:
                continue
            ex, ey = ax + t * dx - px, ay + t * dy - py
            if ex * ex + ey * ey <= tol * tol:
                hits_s.append(s)
                hits_v.append(v)
                hits_t.append(t)
    n = len(hits_s)
    out_s = np.empty(n, np.int64)
    out_v = np.empty(n, np.int64)
    out_t = np.empty(n, np.float64)
    for i in range(n):
        out_s[i] = hits_s[i]
        out_v[i] = hits_v[i]
        out_t[i] = hits_t[i]
    return out_s, out_v, out_t


def crossings(pts: np.ndarray, seg: np.ndarray) -> np.ndarray:
    """Return the points (k, 2) where two segments sharing no end cross inside both."""
    pts = np.ascontiguousarray(pts, dtype=np.float64).reshape(-1, 2)
    seg = np.ascontiguousarray(seg, dtype=np.int64).reshape(-1, 2)
    if len(seg) and (seg.min() < 0 or seg.max() >= len(pts)):
        raise ValueError("crossings: a segment indexes no point")
    xmin = np.minimum(pts[seg[:, 0], 0], pts[seg[:, 1], 0])
    order = np.argsort(xmin, kind="stable")
    return _crossings(pts, np.ascontiguousarray(seg[order]), np.ascontiguousarray(xmin[order]))


@njit(cache=True, nogil=True)
def _crossings(pts, seg, xmin):
    out = []
    m = seg.shape[0]
    for i in range(m):
        a, b = seg[i, 0], seg[i, 1]
        ax, ay, bx, by = pts[a, 0], pts[a, 1], pts[b, 0], pts[b, 1]
        xmax = max(ax, bx)
        for j in range(i + 1, m):
            if xmin[j] > xmax:
                break
            c, d = seg[j, 0], seg[j, 1]
            if c == a or c == b or d == a or d == b:
                continue
            cx, cy, dx, dy = pts[c, 0], pts[c, 1], pts[d, 0], pts[d, 1]
            if max(cy, dy) < min(ay, by) or min(cy, dy) > max(ay, by):
                continue
            o1 = _orient(ax, ay, bx, by, cx, cy)
            o2 = _orient(ax, ay, bx, by, dx, dy)
            o3 = _orient(cx, cy, dx, dy, ax, ay)
            o4 = _orient(cx, cy, dx, dy, bx, by)
            if o1 * o2 > 0.0 or o3 * o4 > 0.0:
                continue
            den = o1 - o2
            if den == 0.0:  # on one line: where they overlap, the nearer end inside both
                continue
            t = o1 / den
            out.append((cx + t * (dx - cx), cy + t * (dy - cy)))
    res = np.empty((len(out), 2))
    for k in range(len(out)):
        res[k, 0] = out[k][0]
        res[k, 1] = out[k][1]
    return res
