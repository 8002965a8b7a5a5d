"""A mesh made from a depth frame, recognised as its frame: fill-holes on the pixel lattice.

A depth camera's frame converted to PLY (Open3D, PCL, :meth:`RangeGrid.to_scan`) keeps the
frame's structure: every vertex is a pixel's ray ``(u, v) * d`` at depth ``d`` along the
camera axis, so ``x / d`` and ``y / d`` lie on two evenly spaced lattices (``1 / fx`` and
``1 / fy`` apart), and every triangle joins pixels of one 2 x 2 block. Filled as a mesh,
such a frame is a poor height field: the metric view plane is an orthographic projection
of a perspective frame, the far surfaces' samples spread out, and every shadow behind a
near object becomes a "hole" of the footprint (a TUM desk frame: 110 thousand vertices
added in 6-7 s, slower than screened Poisson). On its own lattice the frame is what the
depth image was: :func:`find_lattice` finds the lattice back (or says there is none),
:func:`lattice_grid` makes the :class:`~asrbf_mesh._range.RangeGrid` that
:func:`~asrbf_mesh._grid_fill.fill_grid` fills (enclosed no-data cells, depth-edge shadows
from the far side), and :func:`merge_fill` returns the input mesh, unchanged, with the
filled cells as new vertices and the triangles of the blocks they complete.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ._mesh import Mesh, Scan
from ._range import DEFAULT_JUMP, RangeGrid, _block_faces

__all__ = ["Lattice", "find_lattice", "frame_faces", "lattice_grid", "merge_fill"]

#: A vertex is on the lattice when ``x / d`` and ``y / d`` are within this share of a
#: lattice step of a lattice line (float32 coordinates are good to about 1e-4 of a step).
_ON_LATTICE = 0.02
#: Grids of more cells than this (or than this many times the vertices) are not made.
_MAX_CELLS = 30_000_000
_MAX_CELLS_PER_POINT = 16
#: A bare point cloud's lattice steps are measured between this many points, spread over
#: it, and their 8 nearest (:func:`_near_pairs`).
_PAIR_SAMPLE = 4096


@dataclass(frozen=True)
class Lattice:
    """Where each vertex of a depth frame's mesh sits on the frame's pixel lattice.

    ``x / d = u0 + col * su`` and ``sign * y / d = v0 + row * sv`` with ``d = sign * z
    > 0`` the depth along the camera axis (``sign`` -1 for OpenGL camera coordinates,
    where +y is up, +1 for OpenCV's, where +y is down: row 0 is the image's top either
    way); ``rows`` and ``cols`` per vertex, from 0; ``shape`` = (rows, cols) of the
    lattice's bounding box.
    """

    rows: np.ndarray
    cols: np.ndarray
    shape: tuple[int, int]
    u0: float
    su: float
    v0: float
    sv: float
    sign: float

    @property
    def intrinsics(self) -> tuple[float, float, float, float]:
        """(fx, fy, cx, cy) of a pinhole camera with this lattice, in lattice pixels."""
        return 1.0 / self.su, 1.0 / self.sv, -self.u0 / self.su, -self.v0 / self.sv


def _near_pairs(t: np.ndarray) -> np.ndarray:
    """Pairs (i, j) of :data:`_PAIR_SAMPLE` points spread over the cloud and their 8 nearest.

    On a pixel lattice (about square pixels) a point's 8 nearest are its 8 neighbours
    where the frame has them: 6 of the 8 pairs lie one step apart along each axis, so the
    median of their differences is one step there, as it is over a frame's edges.
    """
    from scipy.spatial import cKDTree

    pick = np.unique(np.linspace(0, len(t) - 1, min(len(t), _PAIR_SAMPLE)).astype(np.int64))
    with np.errstate(all="ignore"):
        ok = np.isfinite(t).all(axis=1)
    if not ok.all():
        return np.zeros((0, 2), np.int64)
    _, near = cKDTree(t).query(t[pick], k=9)
    return np.column_stack([np.repeat(pick, 8), near[:, 1:].ravel()])


def _axis(t: np.ndarray, edges: np.ndarray) -> tuple[np.ndarray, float, float] | None:
    """Integer lattice coordinates of ``t`` (one per vertex), its origin and step, or None.

    The step is first the median of ``|dt|`` over the mesh's edges: in a frame's
    triangulation two edges of three cross a column (or a row), so the median is one
    step; then origin and step by least squares over the rounded coordinates.
    """
    if len(edges) == 0:
        return None
    dt = np.abs(t[edges[:, 0]] - t[edges[:, 1]])
    step = float(np.median(dt))
    if not (np.isfinite(step) and step > 0):
        return None
    lo = float(t.min())
    f = (t - lo) / step
    if not f.max() <= _MAX_CELLS:  # more lattice lines than any grid made here
        return None
    k = np.rint(f)
    if np.abs(f - k).max() > 0.25:  # not even near a lattice: stop early
        return None
    A = np.column_stack([np.ones_like(k), k])
    (t0, step), *_ = np.linalg.lstsq(A, t, rcond=None)
    if not step > 0:
        return None
    f = (t - t0) / step
    k = np.rint(f)
    if np.abs(f - k).max() > _ON_LATTICE:
        return None
    first = k.min()  # the first lattice line is 0
    return (k - first).astype(np.int64), float(t0 + first * step), float(step)


def find_lattice(scan: Scan) -> Lattice | None:
    """Find the pixel lattice of a mesh made from one depth frame (None if it is not one).

    A frame's mesh: every vertex has depth ``d = |z| > 0`` of one sign, ``x / d`` and
    ``y / d`` on two evenly spaced lattices (each vertex within
    :data:`_ON_LATTICE` of a step of a lattice point, one vertex per point), and every
    triangle within one 2 x 2 block of lattice points. A frame's bare point cloud (no
    triangles: a depth image turned into points by Open3D or PCL, saved as PLY, XYZ or
    NPY) is found by the same test on its points alone, the lattice's steps measured
    between near points (:func:`_near_pairs`); :func:`frame_faces` meshes it.
    """
    faces = scan.faces
    p = scan.points
    if len(p) < 16:
        return None
    z = p[:, 2]
    sign = 1.0 if z[0] > 0 else -1.0
    d = sign * z
    if not np.all(d > 0):
        return None
    bare = faces is None or len(faces) == 0
    if bare:
        edges = _near_pairs(np.column_stack([p[:, 0] / d, p[:, 1] / d]))
    else:
        edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    found = []
    # rows run down the image: along -y in OpenGL camera coordinates (z < 0), along +y
    # in OpenCV's (z > 0), so both give the frame as the camera saw it
    for t in (p[:, 0] / d, sign * p[:, 1] / d):
        axis = _axis(t, edges)
        if axis is None:
            return None
        found.append(axis)
    (cols, u0, su), (rows, v0, sv) = found
    shape = (int(rows.max()) + 1, int(cols.max()) + 1)
    cells = shape[0] * shape[1]
    if cells > min(_MAX_CELLS, _MAX_CELLS_PER_POINT * len(p)):
        return None
    if np.bincount(rows * shape[1] + cols, minlength=cells).max() > 1:
        return None  # two vertices on one lattice point
    if bare:
        lat = Lattice(rows, cols, shape, u0, su, v0, sv, sign)
        # a cloud with no 2 x 2 block of three points (every other pixel) has no
        # triangle of its own: no frame to mesh, a cloud like any other
        return lat if len(frame_faces(scan, lat)) else None
    r, c = rows[faces], cols[faces]
    if (r.max(1) - r.min(1)).max() > 1 or (c.max(1) - c.min(1)).max() > 1:
        return None  # a triangle across more than one block
    return Lattice(rows, cols, shape, u0, su, v0, sv, sign)


def frame_faces(scan: Scan, lat: Lattice) -> np.ndarray:
    """Triangles of a frame's bare point cloud on its lattice, as vertex ids of the cloud.

    Those of its depth image (:meth:`RangeGrid.to_scan`: 2 x 2 blocks, depth jumps cut),
    so the cloud is meshed as the frame it came from.
    """
    H, W = lat.shape
    vid = np.full(H * W, -1, dtype=np.int64)
    vid[lat.rows * W + lat.cols] = np.arange(len(scan.points))
    ok = lattice_grid(scan, lat)._edge_ok(DEFAULT_JUMP)
    return _block_faces(vid.reshape(H, W), ok, scan.points)


def lattice_grid(scan: Scan, lat: Lattice) -> RangeGrid:
    """Make the depth grid of a frame's mesh (depth along the camera axis, NaN = none)."""
    z = np.full(lat.shape, np.nan)
    z[lat.rows, lat.cols] = lat.sign * scan.points[:, 2]
    return RangeGrid(z, "depth", intrinsics=lat.intrinsics, source=scan.source)


def merge_fill(scan: Scan, lat: Lattice, z_filled: np.ndarray,
               filled: np.ndarray) -> Mesh:
    """Return the input mesh with its lattice's filled cells as new vertices and triangles.

    The scan's vertices and triangles are kept as they are (new vertices after them, in
    row-major order, quality 1). New triangles are those of the filled grid's
    triangulation (:meth:`RangeGrid.to_scan`, depth jumps cut) that use a filled cell, but
    in a block where the scan already has a triangle (three of its corners, the fourth
    filled) only the triangle of the filled corner and its two neighbours, so no
    triangle overlaps the scan's. Oriented as the scan's triangles in the lattice.
    These choices see the scan's triangles as :func:`~asrbf_mesh._hole_find.usable_faces`
    mends them (a copied face made its edges look taken: a TUM desk frame with 2 % of its
    faces copied got 7,606 new triangles instead of 7,643).
    """
    from ._hole_find import usable_faces

    faces, _ = usable_faces(scan.faces)
    H, W = lat.shape
    n = len(scan.points)
    flat_new = np.flatnonzero(filled)
    vid = np.full(H * W, -1, dtype=np.int64)
    vid[lat.rows * W + lat.cols] = np.arange(n)
    vid[flat_new] = n + np.arange(len(flat_new))
    r_new, c_new = np.divmod(flat_new, W)
    dep = z_filled.ravel()[flat_new]
    new_pts = np.column_stack([(lat.u0 + c_new * lat.su) * dep,
                               lat.sign * (lat.v0 + r_new * lat.sv) * dep, lat.sign * dep])
    grid = RangeGrid(z_filled, "depth", intrinsics=lat.intrinsics)
    ok = grid._edge_ok(DEFAULT_JUMP)
    vgrid = vid.reshape(H, W)
    # positions only choose a block's diagonal: the grid's own points, in cell order
    pts = np.zeros((n + len(flat_new), 3))
    pts[vgrid[np.isfinite(z_filled)]] = grid.points()[0]
    tris = _block_faces(vgrid, ok, pts)
    tris = tris[(tris >= n).any(axis=1)]
    # blocks where the scan has a triangle: only the filled corner's triangle
    block_of = _blocks(lat, faces, W)
    cell = np.empty(n + len(flat_new), dtype=np.int64)
    cell[:n] = lat.rows * W + lat.cols
    cell[n:] = flat_new
    tr, tc = np.divmod(cell[tris], W)
    tb = tr.min(axis=1) * W + tc.min(axis=1)
    taken = np.isin(tb, block_of)
    tris = np.vstack([tris[~taken], _corner_tris(np.unique(tb[taken]), vgrid, ok, n)])
    tris = _orient(tris, faces, cell, W)
    tris = _manifold(tris, faces)
    quality = np.r_[np.zeros(n), np.ones(len(flat_new))]
    return Mesh(np.vstack([scan.points, new_pts]), np.vstack([scan.faces, tris]),
                vertex_quality=quality)


def _blocks(lat: Lattice, faces: np.ndarray, W: int) -> np.ndarray:
    """Flat index of each triangle's block (its top-left lattice point)."""
    return lat.rows[faces].min(axis=1) * W + lat.cols[faces].min(axis=1)


def _corner_tris(blocks: np.ndarray, vgrid: np.ndarray, ok: dict[str, np.ndarray],
                 n: int) -> np.ndarray:
    """In each block (flat index of its top-left point), the triangle of its filled corner.

    Corners 0 (r, c), 1 (r, c + 1), 2 (r + 1, c), 3 (r + 1, c + 1); the filled one (id
    >= ``n``) with its two neighbours in the block, when none of its edges crosses a jump.
    """
    W = vgrid.shape[1]
    r, c = np.divmod(blocks, W)
    v = np.column_stack([vgrid[r, c], vgrid[r, c + 1], vgrid[r + 1, c], vgrid[r + 1, c + 1]])
    k = np.argmax(v >= n, axis=1)
    nb = np.array([[1, 2], [0, 3], [0, 3], [1, 2]])[k]
    # the two edges from the filled corner: horizontal and vertical
    h_ok = np.where(k < 2, ok["h"][r, c], ok["h"][r + 1, c])
    v_ok = np.where(k % 2 == 0, ok["v"][r, c], ok["v"][r, c + 1])
    d_ok = np.where((k == 0) | (k == 3), ok["d12"][r, c], ok["d03"][r, c])
    good = h_ok & v_ok & d_ok & (v.min(axis=1) >= 0)
    rows = np.arange(len(blocks))
    out = np.column_stack([v[rows, k], v[rows, nb[:, 0]], v[rows, nb[:, 1]]])
    return out[good]


def _orient(tris: np.ndarray, faces: np.ndarray, cell: np.ndarray, W: int) -> np.ndarray:
    """Flip new triangles to turn as most of the scan's do, in (column, row)."""
    def turn(t: np.ndarray) -> np.ndarray:
        r, c = np.divmod(cell[t], W)
        return np.sign((c[:, 1] - c[:, 0]) * (r[:, 2] - r[:, 0])
                       - (c[:, 2] - c[:, 0]) * (r[:, 1] - r[:, 0]))
    if len(tris) == 0:
        return tris.reshape(0, 3)
    want = 1 if np.sum(turn(faces)) >= 0 else -1
    flip = turn(tris) != want
    tris = tris.copy()
    tris[flip] = tris[flip][:, [0, 2, 1]]
    return tris


def _manifold(tris: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Drop new triangles on an edge that would then have more than two triangles.

    Only the scan's triangles with two vertices of a new triangle can share its edges.
    """
    if len(tris) == 0:
        return tris
    mark = np.zeros(int(max(faces.max(), tris.max())) + 1, dtype=bool)
    mark[tris] = True
    near = faces[mark[faces].sum(axis=1) >= 2]
    every = np.vstack([near, tris])
    e = np.sort(np.concatenate([every[:, [0, 1]], every[:, [1, 2]], every[:, [2, 0]]]), axis=1)
    key = e[:, 0] * (int(every.max()) + 1) + e[:, 1]
    _, inv, count = np.unique(key, return_inverse=True, return_counts=True)
    over = (count[inv] > 2).reshape(3, -1).T[len(near):].any(axis=1)
    return tris[~over]
