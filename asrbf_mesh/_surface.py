"""Surface reconstruction: evaluate a network on a regular grid and triangulate it.

The grid lives in the frame's local physical (x, y), so a spacing is a length in
scan units. The whole normalized square can be meshed (with the network's
extrapolation at the margins, like the paper's Fig. 3), or only the scan's
footprint: the grid cells that hold data.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from . import _config
from ._footprint import Footprint
from ._frame import sampling_spacing
from ._io import Scan
from ._mesh import Mesh
from ._network import Network
from ._surface_gaps import Gaps, open_gaps
from ._validate import check_choice, check_float, check_int, check_points
from .errors import ConfigError, ScanError

__all__ = ["reconstruct", "grid_faces", "piece_grid_mesh", "FOOTPRINT_MODES"]

FOOTPRINT_MODES = _config.FOOTPRINT_MODES


def grid_faces(nx: int, ny: int, keep: np.ndarray | None = None) -> np.ndarray:
    """Triangles of a regular ``nx`` x ``ny`` vertex grid (row-major, x fastest).

    Two counter-clockwise triangles per cell; ``keep`` ((ny-1, nx-1) bool) selects cells.

    Examples
    --------
    >>> grid_faces(2, 2).tolist()
    [[0, 1, 3], [0, 3, 2]]
    """
    j, i = np.mgrid[0:ny - 1, 0:nx - 1]
    v00 = j * nx + i
    if keep is not None:
        v00 = v00[keep]
    v00 = v00.ravel()
    v10, v01, v11 = v00 + 1, v00 + nx, v00 + nx + 1
    tris = np.stack([np.column_stack([v00, v10, v11]), np.column_stack([v00, v11, v01])], 1)
    return tris.reshape(-1, 3).astype(np.int64)


def reconstruct(net: Network, *, resolution: int | None = None, spacing_abs: float | None = None,
                footprint: Scan | np.ndarray | None = None, mode: str | None = None,
                margin_rel: float = 0.0, coverage: str = "centre",
                max_wall: float | None = None) -> Mesh:
    """Mesh the network surface on a regular grid, in physical units.

    Parameters
    ----------
    net : Network
        The fitted network.
    resolution : int, optional
        Number of samples along the longer side of the area meshed: the scan's xy
        extent, with ``margin_rel`` of it added on both sides in mode ``full``.
    spacing_abs : float, optional
        Grid spacing in scan units (instead of ``resolution``); each axis takes the
        nearest whole number of steps, so the grid spans the extent exactly. Default: the
        scan's own sampling spacing if known, else 200 samples along the longer side of
        the area meshed.
    footprint : Scan or (N, 3) array, optional
        The scan whose footprint limits the mesh (modes ``surface``, ``scan``, ``hull``).
    mode : {"surface", "scan", "hull", "full"}, optional
        ``surface``: the grid cells on the scan's triangles (the scan's holes stay
        open); ``scan``: those and the cells inside its holes (so holes come out
        filled by the network, paper section 4.1); ``hull``: inside a concave hull of
        the points (bays and notches of the border bridged too); ``full``: the whole
        normalized square, extended by ``margin_rel`` (the network's extrapolation,
        paper Fig. 3). Default: ``surface`` with a footprint, else ``full``: a
        reconstruction stays on the scan unless asked to fill (the fill's distance to
        the scan is no error of the surface; on the face map, with its 23 natural holes,
        it held the mesh-to-scan 99.9th percentile at 2.0 % of the diagonal, 0.50 %
        without; BENCHMARKS "Piecewise model vs the single network").
    margin_rel : float
        Extend the full square by this fraction on every side (mode ``full``).
    coverage : {"centre", "any"}
        Modes ``surface``, ``scan`` and ``hull``: mesh the grid cells whose centre lies on the
        footprint (``centre``), or every cell that touches it (``any``: no fragment or
        strip narrower than a cell is lost, at the price of up to one cell beyond the
        border; coarse grids such as LOD levels want it, and their nodes past the border
        move onto the scan's nearest sample). With ``centre`` a node past the border
        keeps its place but not the network's extrapolation: its depth rises over the
        border's by at most its distance from it (a slope of 45 degrees).
    max_wall : float, optional
        With a footprint that has triangles: leave out the walls between pieces taller
        than this many grid spacings where the scan is open (an occlusion gap: no scan
        edge joins the two pieces near the wall and its middle is far from the scan's
        triangles; the mesh stays open across it, as the scan is), and tear the grid
        triangles as tall inside one piece that ramp across a slit (two sheets of the
        piece meeting at different depths) into their two sheets, each ending on its
        scan border (:mod:`~asrbf_mesh._surface_gaps`); a vertex moved onto a scan sample
        then takes the sample's depth where the network misses it by over
        :data:`SNAP_MISS` E. None: every wall and ramp, the network's depths.

    With a footprint that has triangles (every mode but ``full``), a grid vertex inside a
    scan triangle of its own piece where the network misses that triangle's depth by
    over :data:`SNAP_MISS` E takes the triangle's depth and normal (the network rings
    between steep scan rows there: on a synthetic airplane view 0.1-0.3 % of the
    vertices, the 99.9th percentile of the mesh's distances to the scan 0.89 -> 0.44 %
    of the diagonal, median of seeds 0-2; BENCHMARKS "(models)"), and one in no
    triangle of its piece, or on the border's shelf, whose depth is over
    :data:`GAP_MISS` E from that of every sample of its piece within :data:`GAP_REACH`
    grid steps (a slit's ramp) takes a shelf from the nearest of them. Elsewhere the
    vertices are the network's.

    Returns
    -------
    Mesh
        Vertices in world units, triangles counter-clockwise seen from the scanner
        (+depth), vertex normals from the analytic gradient.

    Raises
    ------
    ConfigError
        Bad ``mode``, ``resolution``, ``spacing_abs`` or ``margin_rel``, or a grid over
        50 million vertices.
    ScanError
        A footprint that is not (N >= 3, 3) finite points, or that selects no grid cell.

    Examples
    --------
    >>> import numpy as np
    >>> from asrbf_mesh._frame import Frame
    >>> from asrbf_mesh._config import FitConfig
    >>> net = Network(0.0, np.array([[0.5, 0.5]]), np.array([0.3]), np.array([1.0]),
    ...               Frame(np.eye(3), np.zeros(3), np.ones(3)), FitConfig())
    >>> m = reconstruct(net, resolution=11)
    >>> m.n_vertices, m.n_faces
    (121, 200)
    """
    if not isinstance(net, Network):
        raise ConfigError(f"net must be an asrbf_mesh.Network, got {type(net).__name__}")
    frame = net.frame
    span = frame.scale[:2]
    if mode is None:
        mode = "full" if footprint is None else "surface"
    mode = check_choice(mode, "mode", FOOTPRINT_MODES)
    if mode != "full" and footprint is None:
        raise ConfigError(f"mode {mode!r} needs the scan as footprint")
    if resolution is not None and spacing_abs is not None:
        raise ConfigError("give either resolution or spacing_abs, not both")
    if mode != "full":
        margin_rel = 0.0
    margin_rel = check_float(margin_rel, "margin_rel", low=0.0, high=10.0, high_open=True)
    # the longer side of the area meshed: the scan's extent and the margin on both sides
    longer = float(span.max()) * (1.0 + 2.0 * margin_rel)
    if resolution is not None:
        step = longer / (check_int(resolution, "resolution", 2) - 1)
    elif spacing_abs is not None:
        step = check_float(spacing_abs, "spacing_abs", low=0.0, low_open=True)
    elif "spacing" in net.info:
        step = float(net.info["spacing"]) * float(np.sqrt(span[0] * span[1]))
    else:
        step = longer / 199
    lo = frame.offset[:2] - margin_rel * span
    hi = frame.offset[:2] + (1 + margin_rel) * span
    # per axis: the nearest whole number of steps, so the grid ends exactly on the border
    nx = max(int(round((hi[0] - lo[0]) / step)) + 1, 2)
    ny = max(int(round((hi[1] - lo[1]) / step)) + 1, 2)
    if nx * ny > 50_000_000:
        raise ConfigError(f"a {nx} x {ny} grid is too large; raise spacing or lower "
                          "resolution")
    gx = np.linspace(lo[0], hi[0], nx)
    gy = np.linspace(lo[1], hi[1], ny)
    xy = np.stack(np.meshgrid(gx, gy), axis=-1).reshape(-1, 2)
    keep = None
    if mode != "full":
        pts = check_points(footprint, "footprint", min_points=3)
        local = pts @ frame.rotation
        local_xy = np.ascontiguousarray(local[:, :2])
        faces = footprint.faces if isinstance(footprint, Scan) else None
        spacing = sampling_spacing(local_xy)
        fp = Footprint.of_points(local_xy, faces, spacing, mode=mode)
        mid_x = 0.5 * (gx[:-1] + gx[1:])
        mid_y = 0.5 * (gy[:-1] + gy[1:])
        centres = np.stack(np.meshgrid(mid_x, mid_y), -1).reshape(-1, 2)
        keep = fp.inside(centres).reshape(ny - 1, nx - 1)
        if check_choice(coverage, "coverage", ("centre", "any")) == "any":
            keep |= fp.touching(gx, gy)

    # nodes past a cliff into another piece's territory move onto the scan, to samples on
    # its surface (a sample in no triangle is no surface); nodes reaching past the border
    # too with coverage "any" (up to a whole cell out), else (half a cell) they stay and
    # take a shelf from the border's depth (_SHELF_SLOPE); a move that would turn a
    # triangle over is not made (_snapped)
    snap = owner = edges = None
    if mode != "full":
        on = local_xy if faces is None or not len(faces) else local_xy[np.unique(faces)]
        rim = None
        if faces is not None and len(faces):
            from ._hole_find import boundary_edges

            edges = boundary_edges(faces)[0]
            rim = (local_xy[edges[:, 0]], local_xy[edges[:, 1]])
        snap = (on, fp, coverage == "any", rim)
        if net.n_pieces > 1:  # each cell's piece, for the grid mesh and its fragments
            owner = net.piece_at(centres).reshape(keep.shape)
    open_at, wall_max = None, None
    if max_wall is not None and mode != "full" and faces is not None and len(faces):
        step = float(gx[1] - gx[0])
        wall_max = check_float(max_wall, "max_wall", low=0.0) * step
        open_at = Gaps(net, local, faces, step, border=edges)
    on_scan = None
    if mode != "full" and faces is not None and len(faces):
        on_scan = (local, np.asarray(faces, dtype=np.int64),
                   net.piece_at(local_xy) if net.n_pieces > 1 else None, spacing)
    mesh, _, _ = piece_grid_mesh(net, xy, nx, ny, keep, snap=snap, owner=owner,
                                 wall_max=wall_max, open_at=open_at, on_scan=on_scan)
    if owner is not None:
        mesh = _with_fragments(net, mesh, on, gx, gy, np.where(keep, owner, -1))
    return mesh


def _with_fragments(net: Network, mesh: Mesh, on: np.ndarray, gx: np.ndarray,
                    gy: np.ndarray, cell_owner: np.ndarray) -> Mesh:
    """Add a patch for every piece of the scan that the grid's cells leave out.

    ``cell_owner`` holds the piece of each kept grid cell, -1 for a cell not kept.

    A fragment narrower than a cell of a coarse grid owns few cell centres or none, so
    the grid mesh drops most of it. A piece whose samples lie mostly outside its own
    kept cells gets a patch of those samples, thinned to one per grid cell (all of them
    if that leaves fewer than three), triangulated in the view plane without triangles
    longer than two cells (or two of the patch's own sample spacings, if wider), on the
    piece's own network.
    """
    step = float(max(gx[1] - gx[0], gy[1] - gy[0]))
    owner = net.piece_at(on)
    i = np.clip(np.searchsorted(gx, on[:, 0], side="right") - 1, 0, len(gx) - 2)
    j = np.clip(np.searchsorted(gy, on[:, 1], side="right") - 1, 0, len(gy) - 2)
    covered = cell_owner[j, i] == owner
    share = np.bincount(owner, covered, net.n_pieces) / np.maximum(
        np.bincount(owner, minlength=net.n_pieces), 1)
    verts, faces, normals = [mesh.vertices], [mesh.faces], [mesh.vertex_normals]
    n = mesh.n_vertices
    for p in np.flatnonzero(share < _FRAGMENT_SHARE):
        mine = (owner == p) & ~covered
        if not mine.any():
            continue
        pts = _fragment_samples(on[mine], step)
        tris = _delaunay(pts, 2.0 * max(step, sampling_spacing(pts) if len(pts) > 1 else 0.0))
        if len(tris) == 0:  # a sample or a row of samples: a strip one cell wide
            pts, tris = _ribbon(pts, step)
        verts.append(net.surface_points(pts, piece=int(p)))
        normals.append(net.normals(pts, piece=int(p)))
        faces.append(tris + n)
        n += len(pts)
    if len(verts) == 1:
        return mesh
    return Mesh(np.vstack(verts), np.vstack(faces), vertex_normals=np.vstack(normals))


def _ribbon(xy: np.ndarray, width: float) -> tuple[np.ndarray, np.ndarray]:
    """Make a strip ``width`` wide along points on a line (a square for one point).

    Returns the strip's corners (2 per point, in the line's order) and its
    counter-clockwise triangles.
    """
    xy = np.unique(xy, axis=0)
    if len(xy) == 1:
        d = np.array([1.0, 0.0])
    else:
        d = np.linalg.svd(xy - xy.mean(axis=0), full_matrices=False)[2][0]
    t = (xy - xy.mean(axis=0)) @ d
    xy = xy[np.argsort(t, kind="stable")]
    if len(xy) == 1:  # stretch one point into a square
        xy = np.vstack([xy - 0.5 * width * d, xy + 0.5 * width * d])
    n = np.array([-d[1], d[0]]) * (0.5 * width)
    corners = np.empty((2 * len(xy), 2))
    corners[0::2], corners[1::2] = xy - n, xy + n  # right and left of the line
    k = np.arange(len(xy) - 1)
    a, b, c, e = 2 * k, 2 * k + 2, 2 * k + 3, 2 * k + 1  # right, next right, next left, left
    tris = np.vstack([np.c_[a, b, c], np.c_[a, c, e]]).astype(np.int64)
    return corners, tris


#: A piece with less than this share of its samples in its own kept cells gets a patch.
_FRAGMENT_SHARE = 0.5


def _fragment_samples(xy: np.ndarray, step: float) -> np.ndarray:
    """One sample per grid cell of ``step`` (the first in index order), or all of them."""
    xy = np.unique(xy, axis=0)
    cell = np.floor((xy - xy.min(axis=0)) / step).astype(np.int64)
    _, first = np.unique(cell, axis=0, return_index=True)
    return xy[np.sort(first)] if len(first) >= 3 else xy


def _delaunay(xy: np.ndarray, longest: float) -> np.ndarray:
    """Return the counter-clockwise Delaunay triangles of distinct points in the plane.

    None has an edge over ``longest``; there are none at all for fewer than three points
    or points on a line.
    """
    from ._triangle import delaunay

    if len(xy) < 3 or np.linalg.matrix_rank(xy - xy.mean(axis=0), tol=1e-12 * longest) < 2:
        return np.zeros((0, 3), dtype=np.int64)
    return delaunay(xy, longest)


def piece_grid_mesh(net: Network, xy: np.ndarray, nx: int, ny: int, keep: np.ndarray | None,
                    *, walls: bool = True,
                    snap: tuple[Any, ...] | None = None,
                    owner: np.ndarray | None = None, wall_max: float | None = None,
                    open_at: Any = None, on_scan: tuple[Any, ...] | None = None
                    ) -> tuple[Mesh, np.ndarray, np.ndarray]:
    """Mesh each piece of ``net`` on the grid cells it owns, stitched by walls.

    ``xy`` holds the ``nx`` x ``ny`` grid nodes (row-major, local physical units) and
    ``keep`` ((ny-1, nx-1) bool, None for all) the cells to mesh. Each cell belongs to the
    piece owning its centre (:meth:`~asrbf_mesh.Network.piece_at`; ``owner``, (ny-1, nx-1),
    if the caller has it already); a node shared by cells
    of two pieces gets one vertex per piece, each on its own piece's surface. With
    ``walls``, the grid edge between two cells of different pieces becomes a wall of two
    triangles between the two pieces' vertices of its end nodes: no ramp across a depth
    jump, and no crack either; with ``wall_max`` (depth, local units), walls taller than
    that are left out where ``open_at`` (a :class:`~asrbf_mesh._surface_gaps.Gaps`; None:
    every such wall) says the scan is open, and one piece's grid triangles as tall
    across a slit are torn into its two sheets (:func:`~asrbf_mesh._surface_gaps.open_gaps`).
    A one-piece network gives the plain grid mesh.

    ``snap`` (the scan's view-plane points, its footprint and whether to snap border
    nodes): a vertex whose node lies in another piece's territory (a cell of one piece
    reaching past a cliff), or with the flag set beyond the footprint (a border cell
    reaching past the scan's border), moves to the nearest scan sample of its own piece,
    so the mesh ends on the scan instead of extrapolating a surface past it. Nodes over
    holes stay: they are the fill.

    ``on_scan`` (the scan's local xyz, its triangles, each point's piece (None for one
    piece) and its sampling spacing): a vertex inside a scan triangle of its own piece
    where the network misses the triangle's depth by over :data:`SNAP_MISS` E takes that
    depth and the triangle's normal (on a grid at most :data:`ONTO_STEPS` times as coarse
    as the scan), and one in no such triangle (or on a shelf) at a depth no sample of its
    piece nearby has takes a shelf from the nearest (:func:`_onto_triangles`).

    Returns
    -------
    mesh : Mesh
        World units, normals from each vertex's piece.
    vertex_xy : (V, 2) float64 array
        The grid node of each vertex (moved onto a scan sample: that sample's place;
        a torn ramp's new vertices: their samples').
    vertex_piece : (V,) int64 array
        The piece each vertex lies on.

    Raises
    ------
    ScanError
        No cell is kept.
    """
    keep = np.ones((ny - 1, nx - 1), bool) if keep is None else keep
    n_nodes = nx * ny
    if owner is not None:
        owner = np.asarray(owner, dtype=np.int64).reshape(keep.shape)
    elif net.n_pieces == 1:
        owner = np.zeros(keep.shape, dtype=np.int64)
    else:
        centres = 0.5 * (xy.reshape(ny, nx, 2)[:-1, :-1] + xy.reshape(ny, nx, 2)[1:, 1:])
        owner = net.piece_at(centres.reshape(-1, 2)).reshape(keep.shape)
    parts = [grid_faces(nx, ny, keep & (owner == p)) + int(p) * n_nodes  # key: piece, node
             for p in np.unique(owner[keep])]
    n_wall = 0
    if walls and net.n_pieces > 1:
        parts.append(_wall_keys(nx, ny, keep, owner, n_nodes))
        n_wall = len(parts[-1])
    keys = np.concatenate(parts) if parts else np.zeros((0, 3), np.int64)
    if keys.size == 0:
        raise ScanError("the footprint selects no grid cell (is the footprint the right scan?)")
    uniq, inverse = np.unique(keys.ravel(), return_inverse=True)
    node, piece = uniq % n_nodes, uniq // n_nodes
    pts = xy[node]
    faces = inverse.reshape(-1, 3)
    is_wall = np.zeros(len(faces), dtype=bool)
    is_wall[len(faces) - n_wall:] = True
    at, shelf = pts, None  # where each vertex takes its depth; past the scan's border
    vnode = node  # each vertex's grid node (-1: moved off it)
    if snap is not None:
        at, outside = _snap(net, pts, piece, *snap)
        # a vertex past the border moves onto the scan only with snap[2] (coverage "any")
        moves = ~outside | bool(snap[2])
        place, faces, is_wall, kept = _snapped(pts, faces, is_wall, piece,
                                               np.where(moves[:, None], at, pts),
                                               keep_order=not snap[2])
        at, piece = at[kept], piece[kept]
        # off the scan and left in its place (past the border with coverage "centre", or
        # put back there because the move would turn a triangle over): a shelf
        shelf = np.any(at != pts[kept], axis=1) & np.all(place == pts[kept], axis=1)
        onto = np.any(place != pts[kept], axis=1)  # moved onto a scan sample
        pts, at = place, np.where(shelf[:, None], at, place)
        vnode = np.where(onto | shelf, -1, node[kept])
    which = None if net.n_pieces == 1 else piece
    verts = net.surface_points(at, piece=which)
    if open_at is not None and snap is not None and onto.any():
        # on a sample where the network misses it (a slit's edge it ramps across): its depth
        R = net.frame.rotation
        verts[onto] = open_at.onto_samples(verts[onto] @ R, SNAP_MISS * float(
            net.config.error_threshold) * float(net.frame.scale[2])) @ R.T
    if shelf is not None and shelf.any():
        # the extrapolated depth, its rise over the border point's limited to a slope
        R = net.frame.rotation
        border = verts[shelf] @ R
        out = net.surface_points(pts[shelf], piece=None if which is None else which[shelf]) @ R
        run = np.linalg.norm(out[:, :2] - border[:, :2], axis=1)
        rise = np.clip(out[:, 2] - border[:, 2], -_SHELF_SLOPE * run, _SHELF_SLOPE * run)
        verts[shelf] = np.column_stack([out[:, :2], border[:, 2] + rise]) @ R.T
    snapped = None
    if on_scan is not None:  # where the network rings between scan samples: the scan
        verts, snapped, tri_normal = _onto_triangles(net, verts, vnode, piece,
                                                     xy[:nx, 0], xy[::nx, 1], *on_scan,
                                                     shelf=shelf)
    if wall_max is not None:
        R = net.frame.rotation
        faces, torn, torn_piece = open_gaps(verts @ R, faces, is_wall, piece, wall_max,
                                            open_at)
        if len(torn):  # slit ramps torn: their sheets end on scan samples
            verts = np.concatenate([verts, torn @ R.T])
            at, pts = np.concatenate([at, torn[:, :2]]), np.concatenate([pts, torn[:, :2]])
            piece = np.concatenate([piece, torn_piece])
            which = None if which is None else piece
    normals = net.normals(at, piece=which)
    if snapped is not None and len(snapped):
        normals[snapped] = tri_normal
    mesh = Mesh(verts, faces, vertex_normals=normals)
    return mesh, pts, piece


def _onto_triangles(net: Network, verts: np.ndarray, vnode: np.ndarray, piece: np.ndarray,
                    gx: np.ndarray, gy: np.ndarray, local: np.ndarray, faces: np.ndarray,
                    point_piece: np.ndarray | None, spacing: float,
                    shelf: np.ndarray | None = None
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Give vertices the depth of the scan triangle they lie in where the network misses it.

    ``verts`` (world xyz) stand on the grid nodes ``vnode`` (row-major indices into the
    ``gx`` x ``gy`` grid; -1: a vertex off its node, left as it is) on ``piece``;
    ``local`` and ``faces`` are the scan's (local xyz), ``point_piece`` each scan point's
    piece (None: one piece). A vertex inside a triangle whose three corners are of its
    piece (:func:`~asrbf_mesh._holes_kernels.grid_triangle_depths`), missing the
    triangle's depth there by over :data:`SNAP_MISS` E, takes that depth, where the grid
    is at most :data:`ONTO_STEPS` times the scan's sampling ``spacing``; a vertex in no
    triangle of its piece, or on a shelf past the border (``shelf``: its depth from the
    network's at the border, where it may ramp), at a depth that no sample around it has,
    a shelf from the nearest sample (:func:`_gap_shelves`). Returns the vertices, the
    indices of those that took a triangle's depth and those triangles' unit normals
    (world, facing the scanner).
    """
    from ._holes_kernels import grid_triangle_depths

    none = (verts, np.zeros(0, np.int64), np.zeros((0, 3)))
    if len(faces) == 0:
        return none
    if point_piece is None:
        face_piece = np.zeros(len(faces), np.int64)
    else:  # a triangle with its three corners on one piece is that piece's
        corner = point_piece[faces]
        face_piece = np.where((corner[:, 0] == corner[:, 1]) & (corner[:, 1] == corner[:, 2]),
                              corner[:, 0], -1)
    key = np.where(vnode >= 0, piece * (len(gx) * len(gy)) + vnode, -1)
    z, tri = grid_triangle_depths(gx, gy, local, faces, face_piece, key)
    R = net.frame.rotation
    miss = SNAP_MISS * float(net.config.error_threshold) * float(net.frame.scale[2])
    loc = verts @ R
    with np.errstate(invalid="ignore"):
        move = np.flatnonzero(np.abs(loc[:, 2] - z) > miss)
    if float(gx[1] - gx[0]) > ONTO_STEPS * spacing:  # a coarse vertex: the network's
        move = move[:0]
    c = local[faces[tri[move]]]
    n = np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0])  # not 0: the triangle has an area
    n *= np.where(n[:, 2] < 0, -1.0, 1.0)[:, None] / np.linalg.norm(n, axis=1)[:, None]
    loc[move, 2] = z[move]
    # in no triangle of its piece (a pinhole or slit the footprint keeps; the border):
    # at a depth no sample around has (a ramp between two sheets), a shelf
    off = (vnode >= 0) & (tri < 0)
    if shelf is not None:
        off |= shelf
    off = np.flatnonzero(off)
    gap, depth = _gap_shelves(loc[off], piece[off], local, faces, point_piece,
                              GAP_REACH * float(gx[1] - gx[0]), GAP_MISS / SNAP_MISS * miss)
    loc[off[gap], 2] = depth
    changed = np.concatenate([move, off[gap]])
    if len(changed) == 0:
        return none
    out = verts.copy()
    out[changed] = loc[changed] @ R.T
    return out, move, n @ R.T


def _gap_shelves(v: np.ndarray, piece: np.ndarray, local: np.ndarray, faces: np.ndarray,
                 point_piece: np.ndarray | None, reach: float, miss: float
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Shelves for vertices in a gap between depths: (which of ``v``, their new depths).

    ``v`` (local xyz, on ``piece``) lie in no scan triangle of their piece. One whose
    depth is farther than ``miss`` from that of every sample of its piece (used by a
    triangle) within ``reach`` in the view plane stands between sheets of the scan (a
    slit the footprint keeps as a pinhole): its depth rises over that of its nearest
    such sample by at most :data:`_SHELF_SLOPE` times its distance from it, as a node
    past the border does. Vertices with no such sample stay.
    """
    from scipy.spatial import cKDTree

    used = np.unique(faces)
    if len(v) == 0 or len(used) == 0:
        return np.zeros(0, np.int64), np.zeros(0)
    k = min(GAP_SAMPLES, len(used))
    d, j = cKDTree(local[used, :2]).query(v[:, :2], k=k, distance_upper_bound=reach)
    d, j = d.reshape(len(v), k), j.reshape(len(v), k)
    ok = np.isfinite(d)
    j = used[np.where(ok, j, 0)]
    if point_piece is not None:
        ok &= point_piece[j] == piece[:, None]
    dz = np.where(ok, np.abs(local[j, 2] - v[:, 2:3]), np.inf)
    gap = np.flatnonzero(ok.any(axis=1) & (dz.min(axis=1) > miss))
    near = j[gap, np.argmin(np.where(ok[gap], d[gap], np.inf), axis=1)]
    run = np.linalg.norm(local[near, :2] - v[gap, :2], axis=1)
    rise = np.clip(v[gap, 2] - local[near, 2], -_SHELF_SLOPE * run, _SHELF_SLOPE * run)
    return gap, local[near, 2] + rise


#: A grid vertex takes the depth of the scan triangle under it (where the network misses
#: that by over SNAP_MISS E) only on grids at most this many times the scan's sampling
#: spacing (the default reconstruction, the finer LOD levels): a vertex of a coarser grid
#: stands for many samples, and the scan's depth at one point is no better an estimate
#: of their surface than the network's (bun000 seed 9, level 3 at 8 times the spacing:
#: Metro RMS 0.180 -> 0.189 % of the diagonal and the scan -> level 99.9th percentile
#: 0.86 -> 0.90 with the rule there; airplane0 seed 1, level 2 at 1.5-2 times, the
#: rule takes level -> scan from 0.90 to 0.59 and the RMS from 0.078 to 0.060).
ONTO_STEPS = 2.0


#: A grid vertex in no scan triangle of its piece whose depth lies farther than
#: GAP_MISS E from every sample of its piece within GAP_REACH grid steps (the
#: GAP_SAMPLES nearest) takes a shelf from the nearest of them (:func:`_gap_shelves`): at
#: a slit the footprint keeps as a pinhole (two sheets of one piece, a cow's hind leg
#: before its body), the grid nodes between the sheets stood on the network's ramp,
#: up to 2.6 % of the diagonal off the scan (cow0, seeds 0-2: the default
#: reconstruction's mesh -> scan 99.9th percentile 0.70 / 0.62 / 0.77 -> 0.54 / 0.50 /
#: 0.52 %; with 2 E 0.64 / 0.58 / 0.64).
GAP_MISS = 1.0
GAP_REACH = 1.5
GAP_SAMPLES = 12


#: With ``max_wall`` (LOD levels), a vertex moved onto a scan sample takes the sample's
#: depth where the network misses it by over this many E (the fit's error threshold):
#: at a slit the network ramps across, cow0's level vertices stood 1.4 % of the
#: diagonal off the samples they were moved onto.
SNAP_MISS = 2.0


#: A grid node past the scan's border (up to half a cell with coverage "centre"; with
#: "any" where its move onto the scan would turn a triangle over) keeps its place in the
#: view plane, but its depth rises over that of the border's nearest point by at most
#: this slope times its distance from it: the network's extrapolation there is no
#: surface, and at a steep silhouette it ran far off the scan. Measured on the default
#: reconstruction (99.9th percentiles, % of the diagonal, seeds 0-2; mesh -> scan / scan
#: samples in triangles -> mesh) of a synthetic bunny view from 270 degrees: the
#: network's extrapolation 0.58-0.64 / 0.51-0.53, slope 1 0.48-0.53 / 0.51-0.54, slope 2
#: 0.52-0.56 / 0.51-0.53, slope 4 0.57-0.62 / 0.51-0.53, slope 0 (the border's depth)
#: 0.44-0.49 / 0.54-0.55 (the slopes other than 1 measured before a snap that would turn a
#: triangle over fell back to a shelf). On bun045 slope 0 took scan -> mesh from 0.51-0.55 to
#: 0.53-0.59 (slope 1: 0.51-0.55): the triangles from the last node inside to one at
#: the border's depth miss the scan's border samples; moving the nodes onto the border
#: in the view plane instead gave 0.53-0.60 (the mesh's border cut inside the scan's).
_SHELF_SLOPE = 1.0


def _snapped(pts: np.ndarray, faces: np.ndarray, is_wall: np.ndarray, piece: np.ndarray,
             moved: np.ndarray, *, keep_order: bool = True
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Apply the snap ``pts -> moved``; vertices snapped onto one sample merge.

    With ``keep_order``, a grid triangle the snap would turn over (or flatten) in the
    view plane keeps its vertices where they were. Vertices of one piece snapped onto
    the same sample become one, and the triangles that leaves without area are dropped.
    Returns the points, faces and wall flags after that, and the indices (into ``pts``)
    of the points kept.

    Coarse grids (coverage "any", LOD levels) move their border nodes up to a whole cell
    and keep every move: a node put back would stand a cell past the scan (the face
    map's LOD sets: mesh -> scan 99.9th percentile 1.60-1.66 % on seeds 2-3 with the
    moves put back, 0.59-0.71 % on seeds 0-2 with every move kept).
    """
    every = np.arange(len(pts))
    if np.array_equal(moved, pts):
        return pts, faces, is_wall, every
    from ._footprint import signed_areas

    moved = moved.copy()
    grid = faces[~is_wall]
    before = signed_areas(pts, grid)
    for _ in range(4 if keep_order else 0):
        after = signed_areas(moved, grid)
        # turned over, or flat with three distinct corners (two that met merge below)
        p = moved[grid]
        met = (np.all(p[:, 0] == p[:, 1], axis=1) | np.all(p[:, 1] == p[:, 2], axis=1)
               | np.all(p[:, 0] == p[:, 2], axis=1))
        bad = (after * before < 0) | ((after == 0) & (before != 0) & ~met)
        if not bad.any():
            break
        back = np.unique(grid[bad])
        moved[back] = pts[back]
    # one vertex per (piece, position): snapped nodes that met on a sample merge
    key = np.column_stack([piece.astype(np.float64), moved])
    _, first, inv = np.unique(key, axis=0, return_index=True, return_inverse=True)
    if len(first) == len(pts):
        return moved, faces, is_wall, every
    # new ids: the merged groups in the order of their first vertex
    order = np.argsort(first)
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    f = rank[inv.ravel()][faces]
    ok = (f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 0] != f[:, 2])
    kept = first[order]
    return moved[kept], f[ok], is_wall[ok], kept


def _snap(net: Network, pts: np.ndarray, piece: np.ndarray, scan_xy: np.ndarray,
          fp: Footprint, onto: bool, rim: tuple[np.ndarray, np.ndarray] | None = None
          ) -> tuple[np.ndarray, np.ndarray]:
    """Where each vertex off its piece or off the scan takes its depth: (points, off scan).

    A vertex past a cliff, in another piece's territory, goes to its piece's nearest
    sample. For a vertex past the footprint, with ``onto``, its piece's nearest sample
    (where :func:`piece_grid_mesh` moves it); else the nearest point of its piece's part
    of the scan's border (``rim``: the view-plane ends of the scan's boundary edges;
    without it, the nearest sample), whose depth its shelf starts from.
    """
    from scipy.spatial import cKDTree

    outside = ~fp.inside(pts)
    stray = outside.copy()
    if net.n_pieces > 1:
        stray |= net.piece_at(pts) != piece
    if not stray.any():
        return pts, outside
    pts = pts.copy()

    def owners(xy: np.ndarray) -> np.ndarray:
        return net.piece_at(xy) if net.n_pieces > 1 else np.zeros(len(xy), np.int64)

    owner = owners(scan_xy)
    rim_owner = owners(0.5 * (rim[0] + rim[1])) if rim is not None and not onto else None
    for p in np.unique(piece[stray]):
        to_rim = np.zeros(len(pts), dtype=bool)
        if rim is not None and rim_owner is not None:
            sel = rim_owner == p
            if sel.any():  # else (no border of its own) its nearest sample
                to_rim = outside & (piece == p)
                idx = np.flatnonzero(to_rim)
                pts[idx] = _nearest_on_segments(pts[idx], rim[0][sel], rim[1][sel])
        mine = scan_xy[owner == p]
        idx = np.flatnonzero(stray & (piece == p) & ~to_rim)
        if len(idx) and len(mine):
            pts[idx] = mine[cKDTree(mine).query(pts[idx])[1]]
    return pts, outside


def _nearest_on_segments(q: np.ndarray, a: np.ndarray, b: np.ndarray, k: int = 8
                         ) -> np.ndarray:
    """Return the nearest point to each ``q`` on the segments ``a``-``b``.

    Among the ``k`` segments with the nearest midpoints: the scan's boundary edges are
    about one spacing long, so the nearest is among them.
    """
    from scipy.spatial import cKDTree

    k = min(k, len(a))
    _, cand = cKDTree(0.5 * (a + b)).query(q, k=k)
    cand = cand.reshape(len(q), k)
    pa, pb = a[cand], b[cand]
    d = pb - pa
    t = np.einsum("ijk,ijk->ij", q[:, None] - pa, d) / np.maximum(
        np.einsum("ijk,ijk->ij", d, d), 1e-300)
    foot = pa + np.clip(t, 0.0, 1.0)[..., None] * d
    best = np.argmin(np.einsum("ijk,ijk->ij", foot - q[:, None], foot - q[:, None]), axis=1)
    return foot[np.arange(len(q)), best]


def _wall_keys(nx: int, ny: int, keep: np.ndarray, owner: np.ndarray,
               n_nodes: int) -> np.ndarray:
    """Wall triangles (vertex keys) along grid edges between kept cells of two pieces.

    For the cell A below (or left of) the edge, the edge runs a -> b in A's
    counter-clockwise triangles; the wall ``(bA, aA, aB), (bA, aB, bB)`` runs it b -> a,
    and B's side a -> b, opposite to B's own triangles: the mesh stays consistently
    oriented.
    """
    out = []
    # horizontal edges: cell (j, i) below, (j + 1, i) above; a = (j+1, i+1), b = (j+1, i)
    j, i = np.nonzero(keep[:-1] & keep[1:] & (owner[:-1] != owner[1:]))
    out.append(((j + 1) * nx + i + 1, (j + 1) * nx + i, owner[j, i], owner[j + 1, i]))
    # vertical edges: cell (j, i) left, (j, i + 1) right; a = (j, i+1), b = (j+1, i+1)
    j, i = np.nonzero(keep[:, :-1] & keep[:, 1:] & (owner[:, :-1] != owner[:, 1:]))
    out.append((j * nx + i + 1, (j + 1) * nx + i + 1, owner[j, i], owner[j, i + 1]))
    tris = [np.zeros((0, 3), np.int64)]
    for a, b, pa, pb in out:
        a_a, b_a = a + pa * n_nodes, b + pa * n_nodes
        a_b, b_b = a + pb * n_nodes, b + pb * n_nodes
        tris.append(np.column_stack([b_a, a_a, a_b]))
        tris.append(np.column_stack([b_a, a_b, b_b]))
    return np.concatenate(tris).astype(np.int64)
