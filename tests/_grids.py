"""The one builder of gridded test data: regular height-field grids and their triangles.

Every test that needs a range-grid-like surface builds it here, so that the grid, its
triangulation and the millimetre frame of the synthetic scans are written once:

- :func:`height_grid`: points ``(x, y, func(x, y))`` on an ``nx`` x ``ny`` grid (row by
  row, x fastest), optionally jittered, and two counter-clockwise triangles per cell
  (the library's own ``grid_faces``); cells can be left out (``keep``) and samples can
  be missing (``valid``, as in a range grid: only cells with four valid corners);
- :func:`mm_grid`: a height function of the unit square sampled on a regular grid and
  scaled to the millimetre frame of ``conftest.Synthetic`` (x in [100, 180], y in
  [20, 80], z = 5 + 20 func).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from asrbf_mesh._surface import grid_faces

__all__ = ["X0", "XS", "Y0", "YS", "Z0", "ZS", "grid_faces", "grid_xy", "height_grid", "mm_grid"]

X0, XS = 100.0, 80.0  # x in [100, 180] mm
Y0, YS = 20.0, 60.0  # y in [20, 80] mm
Z0, ZS = 5.0, 20.0  # depth offset and scale of the unit-square height functions

HeightFunc = Callable[[np.ndarray, np.ndarray], np.ndarray]


def grid_xy(nx: int, ny: int, *, x: tuple[float, float] = (0.0, 1.0),
            y: tuple[float, float] = (0.0, 1.0)) -> tuple[np.ndarray, np.ndarray]:
    """(x, y) of an ``nx`` x ``ny`` grid, row by row (x fastest), each (nx*ny,)."""
    gx, gy = np.meshgrid(np.linspace(x[0], x[1], nx), np.linspace(y[0], y[1], ny))
    return gx.ravel(), gy.ravel()


def height_grid(func: HeightFunc, nx: int, ny: int, *, x: tuple[float, float] = (0.0, 1.0),
                y: tuple[float, float] = (0.0, 1.0), jitter: float = 0.0, seed: int = 0,
                keep: np.ndarray | None = None, valid: np.ndarray | None = None
                ) -> tuple[np.ndarray, np.ndarray]:
    """Points and triangles of a height field sampled on a regular grid.

    Parameters
    ----------
    func : callable
        ``z = func(x, y)`` on the (jittered) coordinates, (nx*ny,) arrays.
    nx, ny : int
        Samples along x and y.
    x, y : (float, float)
        First and last sample of each axis (``np.linspace``).
    jitter : float
        Move each sample by a uniform offset in [-jitter, jitter] along x, then along y
        (``np.random.default_rng(seed)``); the faces stay those of the grid.
    keep : (ny-1, nx-1) bool array, optional
        Cells to triangulate (all by default).
    valid : (ny, nx) bool array, optional
        Samples present, as in a range grid: only the valid points are returned,
        renumbered, and only the cells whose four corners are valid are triangulated.

    Returns
    -------
    points : (M, 3) float64 array
    faces : (F, 3) int64 array
    """
    px, py = grid_xy(nx, ny, x=x, y=y)
    if jitter:
        rng = np.random.default_rng(seed)
        px = px + rng.uniform(-jitter, jitter, px.shape)
        py = py + rng.uniform(-jitter, jitter, py.shape)
    points = np.column_stack([px, py, func(px, py)])
    if valid is None:
        return points, grid_faces(nx, ny, keep)
    cells = valid[:-1, :-1] & valid[:-1, 1:] & valid[1:, :-1] & valid[1:, 1:]
    if keep is not None:
        cells &= keep
    index = np.full(nx * ny, -1, dtype=np.int64)
    flat = valid.ravel()
    index[flat] = np.arange(int(flat.sum()))
    return points[flat], index[grid_faces(nx, ny, cells)]


def mm_grid(func: HeightFunc, nx: int, ny: int, *, keep: np.ndarray | None = None
            ) -> tuple[np.ndarray, np.ndarray]:
    """A unit-square height function on a regular grid, in millimetres.

    ``(u, v)`` runs over an ``nx`` x ``ny`` grid of [0, 1]^2; the points are
    ``(X0 + XS u, Y0 + YS v, Z0 + ZS func(u, v))``, the faces two triangles per cell.
    """
    u, v = grid_xy(nx, ny)
    points = np.column_stack([X0 + XS * u, Y0 + YS * v, Z0 + ZS * func(u, v)])
    return points, grid_faces(nx, ny, keep)
