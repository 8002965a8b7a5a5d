"""Surface reconstruction: evaluate a network on a regular grid and triangulate it.

The grid lives in the frame's local physical (x, y), so a spacing is a length in
scan units. The whole normalized square can be meshed (with the network's
extrapolation at the margins, like the paper's Fig. 3), or only the scan's
footprint: the grid cells that hold data.
"""

from __future__ import annotations

import numpy as np

from . import _config
from ._footprint import Footprint
from ._frame import sampling_spacing
from ._io import Scan
from ._mesh import Mesh
from ._network import Network
from ._validate import check_choice, check_float, check_int, check_points
from .errors import ConfigError, ScanError

__all__ = ["reconstruct", "grid_faces", "FOOTPRINT_MODES"]

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
                margin_rel: float = 0.0) -> Mesh:
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
        The scan whose footprint limits the mesh (modes ``scan`` and ``hull``).
    mode : {"scan", "hull", "full"}, optional
        ``scan``: the grid cells on the scan's triangles or inside its holes (so holes
        come out filled); ``hull``: inside a concave hull of the points (bays and
        notches of the border bridged too); ``full``: the whole normalized square,
        extended by ``margin_rel`` (the network's extrapolation, paper Fig. 3).
        Default: ``scan`` with a footprint, else ``full``.
    margin_rel : float
        Extend the full square by this fraction on every side (mode ``full``).

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
        mode = "full" if footprint is None else "scan"
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
        local_xy = np.ascontiguousarray((pts @ frame.rotation)[:, :2])
        faces = footprint.faces if isinstance(footprint, Scan) else None
        fp = Footprint.of_points(local_xy, faces, sampling_spacing(local_xy), mode=mode)
        mid_x = 0.5 * (gx[:-1] + gx[1:])
        mid_y = 0.5 * (gy[:-1] + gy[1:])
        centres = np.stack(np.meshgrid(mid_x, mid_y), -1).reshape(-1, 2)
        keep = fp.inside(centres).reshape(ny - 1, nx - 1)
    faces = grid_faces(nx, ny, keep)
    used = np.unique(faces)
    if used.size == 0:
        raise ScanError("the footprint selects no grid cell (is the footprint the right scan?)")
    remap = np.full(nx * ny, -1, dtype=np.int64)
    remap[used] = np.arange(used.size)
    xy = xy[used]
    verts = net.surface_points(xy)
    normals = net.normals(xy)
    return Mesh(verts, remap[faces], vertex_normals=normals)
