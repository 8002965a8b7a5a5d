"""Surface reconstruction: evaluate a network on a regular grid and triangulate it.

The grid lives in the frame's local physical (x, y), so a spacing is a length in
scan units. The whole normalized square can be meshed (with the network's
extrapolation at the margins, like the paper's Fig. 3), or only the scan's
footprint: the grid cells that hold data.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from .errors import AsrbfError
from .io import Scan
from .mesh import Mesh
from .network import Network

__all__ = ["reconstruct", "footprint_mask", "grid_faces"]


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


def footprint_mask(uv_points: np.ndarray, uv_cells: np.ndarray, spacing: float) -> np.ndarray:
    """Which query points lie on the scan's footprint.

    The footprint is the occupancy of a grid of cell ``1.5 * spacing`` (unit square)
    by the scan points, closed by one cell to bridge sampling gaps; real holes,
    wider than a couple of samples, stay open.

    Parameters
    ----------
    uv_points : (N, 2) array
        Scan points in the unit square.
    uv_cells : (M, 2) array
        Query points in the unit square.
    spacing : float
        Sampling spacing of the scan in the unit square.

    Returns
    -------
    (M,) bool array
    """
    cell = 1.5 * spacing
    n = int(np.ceil(1.0 / cell)) + 3
    ij = np.clip(np.floor(uv_points / cell).astype(np.int64) + 1, 0, n - 1)
    occ = np.zeros((n, n), dtype=bool)
    occ[ij[:, 1], ij[:, 0]] = True
    occ = ndimage.binary_closing(occ, structure=np.ones((3, 3), bool), border_value=0) | occ
    q = np.floor(np.asarray(uv_cells) / cell).astype(np.int64) + 1
    inside = (q >= 0).all(axis=1) & (q < n).all(axis=1)
    out = np.zeros(len(q), dtype=bool)
    out[inside] = occ[q[inside, 1], q[inside, 0]]
    return out


def reconstruct(net: Network, *, resolution: int | None = None, spacing_abs: float | None = None,
                footprint: Scan | np.ndarray | None = None, margin_rel: float = 0.0) -> Mesh:
    """Mesh the network surface on a regular grid, in physical units.

    Parameters
    ----------
    net : Network
        The fitted network.
    resolution : int, optional
        Number of samples along the longer side of the scan's xy extent.
    spacing_abs : float, optional
        Grid spacing in scan units (instead of ``resolution``); each axis takes the
        nearest whole number of steps, so the grid spans the extent exactly. Default: the
        scan's own sampling spacing if known, else 200 samples along the longer side.
    footprint : Scan or (N, 3) array, optional
        Keep only the grid cells that hold scan data (the scan's footprint);
        ``None`` meshes the whole normalized square.
    margin_rel : float
        Extend the full square by this fraction on every side (extrapolation).

    Returns
    -------
    Mesh
        Vertices in world units, triangles counter-clockwise seen from the scanner
        (+depth), vertex normals from the analytic gradient.

    Raises
    ------
    AsrbfError
        Bad resolution or spacing, or a grid over 50 million vertices.

    Examples
    --------
    >>> import numpy as np
    >>> from asrbf_mesh.frame import Frame
    >>> from asrbf_mesh.config import FitConfig
    >>> net = Network(0.0, np.array([[0.5, 0.5]]), np.array([0.3]), np.array([1.0]),
    ...               Frame(np.eye(3), np.zeros(3), np.ones(3)), FitConfig())
    >>> m = reconstruct(net, resolution=11)
    >>> m.n_vertices, m.n_faces
    (121, 200)
    """
    frame = net.frame
    span = frame.scale[:2]
    if resolution is not None and spacing_abs is not None:
        raise AsrbfError("give either resolution or spacing_abs, not both")
    if resolution is not None:
        if not (isinstance(resolution, (int, np.integer)) and resolution >= 2):
            raise AsrbfError(f"resolution must be an integer >= 2, got {resolution!r}")
        step = float(span.max()) / (resolution - 1)
    elif spacing_abs is not None:
        if not (np.isfinite(spacing_abs) and spacing_abs > 0):
            raise AsrbfError(f"spacing_abs must be a positive length, got {spacing_abs!r}")
        step = float(spacing_abs)
    elif "spacing" in net.info:
        step = float(net.info["spacing"]) * float(np.sqrt(span[0] * span[1]))
    else:
        step = float(span.max()) / 199
    if not (0.0 <= margin_rel < 10.0):
        raise AsrbfError(f"margin_rel must lie in [0, 10), got {margin_rel!r}")
    lo = frame.offset[:2] - margin_rel * span
    hi = frame.offset[:2] + (1 + margin_rel) * span
    # per axis: the nearest whole number of steps, so the grid ends exactly on the border
    nx = max(int(round((hi[0] - lo[0]) / step)) + 1, 2)
    ny = max(int(round((hi[1] - lo[1]) / step)) + 1, 2)
    if nx * ny > 50_000_000:
        raise AsrbfError(f"a {nx} x {ny} grid is too large; raise spacing_abs or lower resolution")
    gx = np.linspace(lo[0], hi[0], nx)
    gy = np.linspace(lo[1], hi[1], ny)
    xy = np.stack(np.meshgrid(gx, gy), axis=-1).reshape(-1, 2)
    keep = None
    if footprint is not None:
        pts = footprint.points if isinstance(footprint, Scan) else np.asarray(footprint, float)
        if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) == 0:
            raise AsrbfError("footprint must be a Scan or an (N, 3) array of points")
        uv_scan = frame.to_unit(pts)[:, :2]
        spacing = float(net.info.get("spacing") or 0.0)
        if spacing <= 0:
            from .frame import sampling_spacing

            spacing = sampling_spacing(uv_scan)
        mid_x = 0.5 * (gx[:-1] + gx[1:])
        mid_y = 0.5 * (gy[:-1] + gy[1:])
        centres = np.stack(np.meshgrid(mid_x, mid_y), -1).reshape(-1, 2)
        keep = footprint_mask(uv_scan, frame.xy_to_unit(centres), spacing).reshape(ny - 1, nx - 1)
    faces = grid_faces(nx, ny, keep)
    used = np.unique(faces)
    if used.size == 0:
        raise AsrbfError("the footprint selects no grid cell (is the footprint the right scan?)")
    remap = np.full(nx * ny, -1, dtype=np.int64)
    remap[used] = np.arange(used.size)
    xy = xy[used]
    verts = net.surface_points(xy)
    normals = net.normals(xy)
    return Mesh(verts, remap[faces], vertex_normals=normals)
