"""Closing the boundary loops the view-plane fills leave open, in a plane that suits each.

The view-plane fills (:mod:`asrbf_mesh._hole_patch`, :mod:`asrbf_mesh._hole_layers`) see a
hole as a region of the scan's footprint. Some enclosed holes have no region of their own
there: where the surface folds over itself or turns edge-on, the hole's region runs into
the outside in the projection, and a rim that crosses itself in the view plane cannot be
triangulated in it. Topology still tells them apart: every boundary loop of the repaired
mesh but each connected part's outer border (its longest loop) is an enclosed hole.

Each such loop is filled in the best-fit plane of its rim (principal axes): when the rim
is a simple polygon there, it is triangulated there with interior vertices at the scan's
spacing, whose heights over the plane come from a thin-plate spline of the scan points
around the rim (the surface continues its surroundings). A rim that is not simple in its
own plane either (it winds around a fold) is mapped to a circle by arc length, which is
always simple: the disk is triangulated with interior vertices at the rim's edge length,
and the interior's 3D positions minimize the biharmonic energy with the rim fixed (a
thin-plate membrane spanning the loop, libigl's ``harmonic`` with k = 2).
"""

from __future__ import annotations

import numpy as np
from scipy.interpolate import RBFInterpolator
from scipy.spatial import cKDTree

from . import _holes_kernels as _hk
from ._hole_find import used_once
from ._hole_patch import away_from, grid_samples, triangulate

__all__ = ["open_loops", "outer_loops", "split_loops", "boundary_cycles", "fill_loop",
           "rim_plane", "segments_cross", "simple_cycles"]


def boundary_cycles(faces: np.ndarray) -> list[np.ndarray]:
    """Return the closed loops of boundary half-edges (in their faces' direction).

    A boundary edge belongs to one face; taken in that face's direction, the boundary
    half-edges of a consistently oriented mesh leave every vertex as often as they enter
    it, so they fall into cycles. At a pinch (a vertex on two stretches of boundary) the
    walk takes the first unused way out, so every cycle is made of true boundary edges
    (libigl's loops can cross a pinch through an interior edge). Walks that end at a
    vertex with no way out (an inconsistently oriented patch) are dropped.
    """
    he = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    bnd = he[used_once(he)]
    if len(bnd) == 0:
        return []
    order = np.lexsort((bnd[:, 1], bnd[:, 0]))
    return _hk.walk_cycles(bnd[order])


def split_loops(faces: np.ndarray, n_vertices: int, loops: list[np.ndarray] | None = None
                ) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Split boundary loops into the outer borders of the mesh's connected parts and the rest.

    The outer border of a part is its longest loop (by vertex count). ``loops`` defaults
    to :func:`boundary_cycles`. Returns the outer borders in ``loops`` order and the other
    loops, largest first.
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    loops = boundary_cycles(faces) if loops is None else loops
    if not loops:
        return [], []
    a = faces.ravel()
    b = faces[:, [1, 2, 0]].ravel()
    graph = coo_matrix((np.ones(len(a), dtype=np.int8), (a, b)),
                       shape=(n_vertices, n_vertices))
    _, part = connected_components(graph, directed=False)
    longest: dict[int, int] = {}
    for i, loop in enumerate(loops):
        p = int(part[loop[0]])
        if p not in longest or len(loop) > len(loops[longest[p]]):
            longest[p] = i
    outer = set(longest.values())
    rest = [loop for i, loop in enumerate(loops) if i not in outer]
    return [loops[i] for i in sorted(outer)], sorted(rest, key=len, reverse=True)


def simple_cycles(loop: np.ndarray) -> list[np.ndarray]:
    """Split a boundary cycle that passes a vertex more than once into simple cycles.

    At a pinch (a vertex where two stretches of boundary meet) :func:`boundary_cycles`
    walks on, so one cycle can hold the outer border and a gap pinched off it. Each time
    the walk comes back to a vertex it already holds, the stretch since then is cut off
    as a cycle of its own; what remains at the end is the last one. Every edge of
    ``loop`` is in one of the cycles, in its direction, but the slits (a stretch out to a
    vertex and straight back: no area to fill).
    """
    stack: list[int] = []
    at: dict[int, int] = {}
    out = []
    for v in loop.tolist():
        i = at.get(v)
        if i is None:
            at[v] = len(stack)
            stack.append(v)
            continue
        cut = stack[i:]
        for w in cut[1:]:
            del at[w]
        del stack[i + 1:]
        if len(cut) >= 3:
            out.append(np.array(cut, dtype=np.int64))
    if len(stack) >= 3:
        out.append(np.array(stack, dtype=np.int64))
    return out


def open_loops(faces: np.ndarray, n_vertices: int) -> list[np.ndarray]:
    """Boundary loops of a mesh that are not the outer border of their connected part.

    The outer border of a part is its longest loop (by vertex count). Loops are ordered
    vertex index arrays, largest first.
    """
    return split_loops(faces, n_vertices)[1]


def segments_cross(q: np.ndarray) -> bool:
    """Whether the closed polygon ``q`` (n, 2) has two non-adjacent edges that meet."""
    n = len(q)
    if n < 4:
        return False
    a, b = q, np.roll(q, -1, axis=0)
    for i in range(n):
        j = np.arange(i + 2, n if i > 0 else n - 1)
        if not len(j):
            continue
        p, r = a[i], b[i] - a[i]
        s, t = a[j], b[j] - a[j]
        den = r[0] * t[:, 1] - r[1] * t[:, 0]
        qp = s - p
        with np.errstate(divide="ignore", invalid="ignore"):
            u = (qp[:, 0] * t[:, 1] - qp[:, 1] * t[:, 0]) / den
            v = (qp[:, 0] * r[1] - qp[:, 1] * r[0]) / den
        hit = (den != 0) & (u >= 0) & (u <= 1) & (v >= 0) & (v <= 1)
        if hit.any():
            return True
        # collinear overlaps count as crossings too
        col = (den == 0) & (np.abs(qp[:, 0] * r[1] - qp[:, 1] * r[0]) == 0)
        if col.any():
            return True
    return False


def outer_loops(faces: np.ndarray, n_vertices: int) -> list[np.ndarray]:
    """Return the longest boundary cycle of each connected part: the outer borders."""
    return split_loops(faces, n_vertices)[0]


def fill_loop(loop: np.ndarray, points: np.ndarray, spacing: float,
              scan_points: np.ndarray, scan_tree: cKDTree, *, disk: bool = False
              ) -> tuple[np.ndarray, np.ndarray, str | None]:
    """Fill one boundary loop in its rim's best-fit plane.

    Parameters
    ----------
    loop : (n,) int array
        The loop's vertex indices in its faces' direction, as :func:`boundary_cycles`
        walks it (the mesh runs ``loop[0] -> loop[1]``; the fill runs the other way).
    points : (V, 3) array
        The mesh's vertices (world units).
    spacing : float
        Sampling spacing (world units): interior vertices are this far apart.
    scan_points, scan_tree : (N, 3) array and its cKDTree
        The scan's own points: the thin-plate spline's data around the rim.
    disk : bool
        Go straight to the disk fill (the plane fill's triangles were refused).

    Returns
    -------
    new_vertices : (M, 3) float64 array
    triangles : (T, 3) int64 array
        Mesh vertex ids for the rim (>= 0) and ``-1 - k`` for new vertex ``k``.
    reason : str or None
        Why the loop was left open (then no triangle).
    """
    if len(loop) < 3:
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64), "a loop of fewer than 3 vertices"
    rim = points[loop]
    plane = None if disk else rim_plane(rim, spacing)
    if plane is None:  # the plane cannot hold the rim: a disk can
        return _fill_by_disk(loop, rim)
    centre, axes, normal, q = plane
    n = len(q)
    seg = np.column_stack([np.arange(n), np.roll(np.arange(n), -1)])
    tris, extra = triangulate(q, seg, "pYQ")
    if len(extra) or len(tris) == 0:
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64), "the rim could not be triangulated"
    g = grid_samples(q.min(0), q.max(0), spacing)
    if len(g):
        _, cand = cKDTree(q[tris].mean(axis=1)).query(g, k=min(8, len(tris)))
        g = g[_hk.inside_any(g, q, tris, cand)]
        g = away_from(g, q, seg, 0.6 * spacing)
    pts = np.vstack([q, g])
    if len(g):
        tris, extra = triangulate(pts, seg, "pYQ")
        if len(extra) or len(tris) == 0:
            return (np.zeros((0, 3)), np.zeros((0, 3), np.int64),
                    "the rim could not be triangulated with interior vertices")
    heights = _heights(g, centre, axes, normal, rim, spacing, scan_points, scan_tree)
    new = centre + g @ axes + heights[:, None] * normal
    ids = np.concatenate([loop, -1 - np.arange(len(g))])
    out = ids[tris]
    return new, _oriented(out, loop), None


def rim_plane(rim: np.ndarray, spacing: float
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
    """Return a rim's best-fit plane (centre, axes, normal, rim in it), or None.

    None when the plane cannot hold the rim: two rim points coincide there (to a
    millionth of ``spacing``) or the rim crosses itself.
    """
    centre = rim.mean(axis=0)
    _, _, vt = np.linalg.svd(rim - centre, full_matrices=False)
    q = (rim - centre) @ vt[:2].T
    coincide = np.unique(np.round(q / max(spacing, 1e-300), 6), axis=0).shape[0] < len(q)
    return None if coincide or segments_cross(q) else (centre, vt[:2], vt[2], q)


#: At most about this many interior vertices in a disk fill (:func:`_fill_by_disk`).
_DISK_SAMPLES = 20_000


def _fill_by_disk(loop: np.ndarray, rim: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray, str | None]:
    """Fill a loop through a disk: rim on a circle by arc length, interior by fairing."""
    from ._igl import k_harmonic

    n = len(loop)
    edge = np.linalg.norm(np.roll(rim, -1, axis=0) - rim, axis=1)
    if not np.all(edge > 0):
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64), "the rim has repeated points"
    arc = np.concatenate([[0.0], np.cumsum(edge)[:-1]])
    length = float(edge.sum())
    radius = length / (2 * np.pi)
    angle = 2 * np.pi * arc / length
    q = radius * np.column_stack([np.cos(angle), np.sin(angle)])
    # interior samples at the rim's median edge, but at most about _DISK_SAMPLES of
    # them: a loop with one edge hundreds of times its median (37 vertices, a rim
    # 3,700 median edges long) asked for 630,000 and kept libigl's fairing busy for
    # minutes on gigabytes
    h = max(float(np.median(edge)), length / np.sqrt(4.0 * np.pi * _DISK_SAMPLES))
    seg = np.column_stack([np.arange(n), np.roll(np.arange(n), -1)])
    try:
        tris, extra = triangulate(q, seg, "pYQ")
        g = grid_samples(np.full(2, -radius), np.full(2, radius), h)
        if len(g) and len(tris):  # inside the polygon (a long rim edge cuts a chord off)
            _, cand = cKDTree(q[tris].mean(axis=1)).query(g, k=min(8, len(tris)))
            g = away_from(g[_hk.inside_any(g, q, tris, cand)], q, seg, 0.6 * h)
        pts = np.vstack([q, g])
        if len(g):
            tris, extra = triangulate(pts, seg, "pYQ")
    except Exception as exc:  # noqa: BLE001 - triangle signals bad input by exceptions
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64), f"triangulation failed: {exc}"
    if len(extra) or len(tris) == 0:
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64), "the rim could not be closed"
    unused = np.setdiff1d(np.arange(len(pts)), tris)
    if len(unused):  # a vertex in no triangle would make the fairing singular
        return (np.zeros((0, 3)), np.zeros((0, 3), np.int64),
                "the rim could not be closed (a vertex fell outside the disk's triangles)")
    if len(g):
        try:
            flat = np.column_stack([pts, np.zeros(len(pts))])  # libigl wants 3D positions
            pos = k_harmonic(flat, tris, np.arange(n), rim, 2)
        except (ValueError, RuntimeError) as exc:
            return np.zeros((0, 3)), np.zeros((0, 3), np.int64), f"fairing failed: {exc}"
        new = pos[n:]
        if not np.all(np.isfinite(new)):
            return np.zeros((0, 3)), np.zeros((0, 3), np.int64), "fairing failed"
    else:
        new = np.zeros((0, 3))
    ids = np.concatenate([loop, -1 - np.arange(len(g))])
    return new, _oriented(ids[tris], loop), None


def _heights(g: np.ndarray, centre: np.ndarray, axes: np.ndarray, normal: np.ndarray,
             rim: np.ndarray, spacing: float, scan_points: np.ndarray,
             scan_tree: cKDTree) -> np.ndarray:
    """Height over the plane of interior points: a thin plate of the points around the rim."""
    if len(g) == 0:
        return np.zeros(0)
    size = float(np.linalg.norm(np.ptp(rim, axis=0)))
    reach = max(6.0 * spacing, 0.25 * size)
    near = np.unique(np.concatenate(scan_tree.query_ball_point(rim, reach))).astype(np.int64)
    data = scan_points[near] if len(near) >= 3 else rim
    uv = (data - centre) @ axes.T
    h = (data - centre) @ normal
    if len(uv) > 600:  # keep the spline small: an even subsample, no randomness
        step = int(np.ceil(len(uv) / 600))
        uv, h = uv[::step], h[::step]
    try:
        spline = RBFInterpolator(uv, h, kernel="thin_plate_spline",
                                 smoothing=1e-6 * len(uv), degree=1)
        return spline(g)
    except (np.linalg.LinAlgError, ValueError):
        return np.zeros(len(g))


def _oriented(tris: np.ndarray, loop: np.ndarray) -> np.ndarray:
    """Flip the fill so that it runs each rim edge against the mesh (``loop[1] -> loop[0]``)."""
    a, b = int(loop[0]), int(loop[1])
    f = np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]])
    return tris[:, [0, 2, 1]] if bool(np.any((f[:, 0] == a) & (f[:, 1] == b))) else tris
