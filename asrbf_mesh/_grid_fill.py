"""Filling the no-data cells of a range grid directly on the grid (issue 16).

The mesh hole filler (:func:`~asrbf_mesh.fill_holes`) finds holes in a triangulation's
footprint, triangulates each one and sets depths. A :class:`~asrbf_mesh._range.RangeGrid`
already tells where data is missing, so :func:`fill_grid` skips the mesh machinery:

* **holes** are the 8-connected components of the grid's no-data mask
  (:func:`scipy.ndimage.label`) that do not touch the grid's border; no-data regions open
  to the border are outside the scan and stay no-data (counted in ``border_cells``);
* each hole's cells get ``z = substrate(x, y) + s(x, y)``: the network's low-frequency
  substrate (its neurons at least as wide as the hole, :func:`~asrbf_mesh._hole_patch.
  _lowpass`) plus a thin-plate spline ``s`` of the residuals ``z - substrate`` of the valid
  cells within :func:`~asrbf_mesh._hole_patch.ring_reach` of the hole (its rim cells all
  kept, the rest thinned evenly to at most ``_GRID_RING_MAX`` cells in all), the rule of
  the mesh filler, so there is no step at the
  seam and the slope and curvature of the surroundings carry into the fill;
* **depth-edge shadows** (depth images only). A Kinect-type sensor leaves no data beside
  the near side of a depth edge: the hole belongs to the far surface, which continues
  behind the near object. When the depths of a hole's rim (the valid cells touching
  it) are bimodal, i.e. their sorted values have a gap wider than the largest step the
  grid's jump rule (:data:`~asrbf_mesh._range.DEFAULT_JUMP` times the lateral footprint
  of a diagonal pixel edge, ``Z hypot(1/fx, 1/fy)``) allows between two neighbouring
  cells, the ring is split at that gap and the hole is filled from the far side's cells
  alone, without the substrate (the network smooths across the edge): a thin plate
  through the far ring's depths, extrapolated under the near surface's silhouette
  (``side="far"``). The hole's cells inside the convex hull of the near side's rim cells,
  where the near surface itself runs into the hole (a hole across an object's edge), are
  filled from the near side's ring (``side="both"``). A fill that fails (behind the
  camera, beyond twice its ring's range) becomes a harmonic membrane of the values
  around the hole (``side="membrane"``).

Cell positions: an elevation grid's cell centres and a depth image's pixels have fixed
(x, y) in the frame the fill works in: a depth image is fitted and filled over its pixels
even with intrinsics (sizes and ``max_hole_size`` stay in world units). Only with a given
network fitted in metric camera coordinates does a pixel's (x, y) depend on its unknown
depth: the fill then solves ``depth = F(x(depth), y(depth))`` by fixed-point iteration
(it contracts where the surface is not grazing to the ray: ``|grad F . ray| < 1``).

Without a network the grid's valid cells are fitted here, as ``fit(grid.to_scan())``:
the triangles feed the piece segmentation; on the SRTM tile of ``scripts/bench_range.py``
(138k cells) it gave the same network as the faceless ``Scan(grid.points()[0])`` (same
neurons, same fill) in 7.6 s instead of 10.8 s, and 0.30-0.49 s instead of 0.36-0.50 s
on a 10k-cell sub-grid. Only the substrate of the network is used in a hole, never
its fine neurons, so a large grid is fitted on a regular sub-grid (``_FIT_MAX_CELLS``).

Measured on that benchmark (6 voids of 3-6 % of the tile's side per seed, seeds 0-9):
the fill's RMS is 7.5 % of the elevation range on average against 8.8 % for GDAL
FillNodata and 9.3-10.8 % for OpenCV inpainting and scipy ``griddata``, lowest on 9 of
10 seeds, in 0.15-0.5 s with the fit (5,000-cell sub-grid). There the voids (2-5 km)
are wider than nearly all neurons of the rough terrain, the substrate is almost flat,
and the fill is in effect the thin plate of the ring: without the substrate the RMS
changes in the third digit; with the whole network instead (every neuron, fitted on 5k
cells) it is worse on 6 of 10 seeds and on average (8.5 %).
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import ndimage
from scipy.interpolate import RBFInterpolator

from ._fit import check_pieces, fit
from ._hole_patch import _lowpass, _thin_out, ring_reach
from ._mesh import Scan
from ._network import Network
from ._range import DEFAULT_JUMP, NOMINAL_FOCAL, RangeGrid
from ._validate import check_seed, parse_length
from .errors import ConfigError, ScanError

__all__ = ["GridFillResult", "GridHoleInfo", "fill_grid", "grid_holes"]

#: Without a network, grids with more valid cells than this are fitted on a regular
#: sub-grid (every k-th row and column) of at most about this many cells: the fill uses
#: only the network's neurons at least as wide as the hole (the substrate), which a
#: coarser sampling learns as well, and the fit's cost grows with the points. Measured
#: on the SRTM benchmark (seeds 0-9): the whole 138k-cell tile fitted in 6.6-10.1 s, the
#: 4th-row-and-column sub-grid (8.6k cells) in 0.30-0.49 s, fill RMS equal to 3 digits;
#: caps of 2,500 to 40,000 cells gave the same RMS to 2 digits (seeds 0-1). 5,000 cells
#: (every 6th row and column, 3.9k cells): the same RMS to 2 digits on seeds 0-9, the fit
#: in 0.12-0.39 s instead of 0.42-0.58 s.
_FIT_MAX_CELLS = 5_000
#: Neurons at least this many times as wide as the hole make the substrate (as the
#: mesh filler's default ``lowpass_rel``).
_LOWPASS = 1.0
#: Iterations of the ray fixed point for depth pixels with intrinsics.
_RAY_ITER = 30
#: A hole's ring is thinned to at most this many cells for its thin plate (a dense
#: solve, cubic in the cells), its rim cells kept first. Measured with
#: ``scripts/bench_range.py`` (seeds 0-9): evenly thinned to 1,500 cells, the SRTM mean
#: RMS was 7.55 % and the Kinect pooled RMS 48.4 mm, 1.9-2.2 s per frame; rim first, 600
#: cells: 7.19 % and 47.2 mm, 1.3-1.5 s (1,000 and 1,500 cells rim first: 7.21 / 7.16 %).
_GRID_RING_MAX = 600
_EIGHT = np.ones((3, 3), dtype=bool)


@dataclass(frozen=True)
class GridHoleInfo:
    """One hole of a grid and what was done with it.

    Attributes
    ----------
    index : int
        Hole number (largest first).
    cells : int
        No-data cells in the hole.
    size_abs : float
        Diagonal of the bounding box, in the view plane, of the valid cells bordering
        the hole (its rim), world units (as :class:`~asrbf_mesh.HoleInfo`).
    size_pct : float
        The same, in % of the valid cells' xy bounding-box diagonal.
    centre : (float, float)
        Mean (row, column) of the hole's cells.
    filled : bool
        Whether its cells got values.
    reason : str or None
        Why it was not filled.
    ring_cells : int
        Valid cells the residual spline was fitted to (after thinning).
    side : str or None
        ``"far"`` when the rim straddled a depth edge and only its far side was used;
        ``"both"`` when part of the hole (inside the hull of the near side's rim) was
        filled from the near side and the rest from the far side;
        ``"membrane"`` when the network and the ring's thin plate failed (a fill behind
        the camera or far outside the ring's values) and a harmonic membrane of the
        values around the hole filled it.
    """

    index: int
    cells: int
    size_abs: float
    size_pct: float
    centre: tuple[float, float]
    filled: bool
    reason: str | None = None
    ring_cells: int = 0
    side: str | None = None


@dataclass(frozen=True, eq=False)
class GridFillResult:
    """Outcome of :func:`fill_grid`.

    Attributes
    ----------
    z_filled : (H, W) float64 array
        The grid's ``z`` with the filled holes' cells set (same units as ``grid.z``:
        depth in metres for depth images, elevation for elevation grids); ``NaN``
        elsewhere where there is no data (border regions, holes not filled).
    filled_mask : (H, W) bool array
        The cells that were no data and got a value.
    holes : tuple of GridHoleInfo
        Every hole (no-data region not touching the border), filled or not.
    border_cells : int
        No-data cells in regions open to the grid's border (left no-data).
    seconds : float
        Wall time, the fit included when the network was fitted here.
    fit_seconds : float
        Of which the fit (0 when a network was given).
    network : Network
        The network that gave the substrate.
    """

    z_filled: np.ndarray
    filled_mask: np.ndarray
    holes: tuple[GridHoleInfo, ...]
    border_cells: int
    seconds: float
    fit_seconds: float
    network: Network = field(repr=False)

    @property
    def holes_filled(self) -> int:
        """Number of holes filled."""
        return sum(h.filled for h in self.holes)

    @property
    def cells_filled(self) -> int:
        """Number of cells filled."""
        return int(self.filled_mask.sum())

    def to_dict(self) -> dict[str, Any]:
        """Summary for ``--json``."""
        return {"holes_found": len(self.holes), "holes_filled": self.holes_filled,
                "cells_filled": self.cells_filled, "border_cells": self.border_cells,
                "seconds": self.seconds, "fit_seconds": self.fit_seconds,
                "holes": [h.__dict__ | {"centre": list(h.centre)} for h in self.holes]}


def grid_holes(nodata: np.ndarray) -> tuple[np.ndarray, list[np.ndarray], int]:
    """Label the holes of a no-data mask.

    Returns the label image (0 = not in a hole), each hole's flat cell indices (largest
    hole first) and the number of no-data cells in components touching the border.
    """
    labels, n = ndimage.label(nodata, structure=_EIGHT)
    if n == 0:
        return labels, [], 0
    edge = np.unique(np.concatenate([labels[0], labels[-1], labels[:, 0], labels[:, -1]]))
    open_ = np.zeros(n + 1, dtype=bool)
    open_[edge] = True
    open_[0] = False
    flat = labels.ravel()
    order = np.argsort(flat, kind="stable")
    counts = np.bincount(flat, minlength=n + 1)
    starts = np.concatenate([[0], np.cumsum(counts)])
    holes = [order[starts[k]:starts[k + 1]] for k in range(1, n + 1) if not open_[k]]
    holes.sort(key=len, reverse=True)
    labels = np.where(open_[labels], 0, labels)
    return labels, holes, int(counts[open_].sum())


class _Cells:
    """World positions of grid cells, given their depth values (``grid.z`` units)."""

    def __init__(self, grid: RangeGrid) -> None:
        self.grid = grid
        self.width = grid.shape[1]

    def world(self, flat: np.ndarray, z: np.ndarray) -> np.ndarray:
        """(N, 3) world points of cells ``flat`` holding ``z`` (as :meth:`RangeGrid.points`)."""
        g = self.grid
        rows, cols = np.divmod(flat, self.width)
        if g.kind == "elevation":
            dx, dy = g.cell  # type: ignore[misc]
            return np.column_stack((g.origin[0] + cols * dx, g.origin[1] - rows * dy, z))
        if g.intrinsics is not None:
            fx, fy, cx, cy = g.intrinsics
            return np.column_stack(((cols - cx) * z / fx, -(rows - cy) * z / fy, -z))
        return np.column_stack((cols.astype(np.float64), -rows.astype(np.float64), -z))

    def z_of(self, world_z: np.ndarray) -> np.ndarray:
        """``grid.z`` values from world z."""
        return world_z if self.grid.kind == "elevation" else -world_z

    def pixel(self, z_ref: float) -> tuple[float, float]:
        """World size (along rows, along columns) of one cell at depth ``z_ref``."""
        g = self.grid
        if g.kind == "elevation":
            return g.cell[1], g.cell[0]  # type: ignore[index]
        if g.intrinsics is not None:
            return z_ref / g.intrinsics[1], z_ref / g.intrinsics[0]
        return 1.0, 1.0


def _jump_gap(grid: RangeGrid, z_ref: float) -> float:
    """Largest step of ``grid.z`` the jump rule allows between two neighbouring cells."""
    fx, fy = grid.intrinsics[:2] if grid.intrinsics is not None else (NOMINAL_FOCAL,) * 2
    return DEFAULT_JUMP * z_ref * math.hypot(1.0 / fx, 1.0 / fy)


def _far_side(grid: RangeGrid, zr: np.ndarray) -> float | None:
    """Return the depth splitting a hole's rim into a near and a far surface, or None.

    ``zr`` are the depths of the rim, the valid cells touching the hole: a hole beside a
    depth edge has both surfaces on its rim. (Deciding on the wider ring of the spline
    misfired where the ring reached across an edge near a hole whose rim lies on one
    surface: on the Kinect benchmark such holes were filled at the far depth, 380 mm
    off.)
    """
    if grid.kind != "depth" or len(zr) < 6:
        return None
    s = np.sort(zr)
    gaps = np.diff(s)
    k = int(np.argmax(gaps))
    mid = 0.5 * (s[k] + s[k + 1])
    n_near = k + 1
    least = max(3, int(0.05 * len(s)))
    if gaps[k] <= _jump_gap(grid, mid) or min(n_near, len(s) - n_near) < least:
        return None
    return float(mid)


def _ring(hole: np.ndarray, valid: np.ndarray, cells: _Cells, spacing_at: Any
          ) -> tuple[np.ndarray, np.ndarray, float]:
    """Return the valid cells within the ring reach of a hole, its rim cells and its size.

    Returns the ring's flat indices, the rim's flat indices (valid cells 8-adjacent to
    the hole) and the size (bbox diagonal of the rim's world xy).
    """
    H, W = valid.shape
    rows, cols = np.divmod(hole, W)
    r0, r1, c0, c1 = rows.min(), rows.max() + 1, cols.min(), cols.max() + 1
    # the rim: one cell around
    a0, a1, b0, b1 = max(r0 - 1, 0), min(r1 + 1, H), max(c0 - 1, 0), min(c1 + 1, W)
    box = np.zeros((a1 - a0, b1 - b0), dtype=bool)
    box[rows - a0, cols - b0] = True
    rim_box = ndimage.binary_dilation(box, structure=_EIGHT) & valid[a0:a1, b0:b1]
    rr, rc = np.nonzero(rim_box)
    rim = (rr + a0) * W + (rc + b0)
    size, spacing, z_ref, (py, px) = spacing_at(rim)
    reach = ring_reach(size, spacing)
    pad_r, pad_c = int(math.ceil(reach / py)) + 1, int(math.ceil(reach / px)) + 1
    a0, a1, b0, b1 = max(r0 - pad_r, 0), min(r1 + pad_r, H), max(c0 - pad_c, 0), \
        min(c1 + pad_c, W)
    box = np.ones((a1 - a0, b1 - b0), dtype=bool)
    box[rows - a0, cols - b0] = False
    dist = ndimage.distance_transform_edt(box, sampling=(py, px))
    # within ``reach`` of the rim, as the mesh filler's ring (rim = one cell from the hole)
    near = (dist <= reach + max(py, px)) & valid[a0:a1, b0:b1]
    nr, nc = np.nonzero(near)
    return (nr + a0) * W + (nc + b0), rim, size


def fill_grid(grid: RangeGrid, net: Network | None = None, *,
              max_hole_size: str | float | None = None, seed: int = 0,
              pieces: str | int = "auto", progress: bool | None = False) -> GridFillResult:
    """Fill the no-data holes of a range grid from a fitted network and the hole's ring.

    Parameters
    ----------
    grid : RangeGrid
        The grid (:func:`~asrbf_mesh._range.read_range`); ``NaN`` = no data.
    net : Network, optional
        A network fitted to this grid's points (:meth:`RangeGrid.points` or
        :meth:`RangeGrid.to_scan`); fitted here when omitted.
    max_hole_size : float or str, optional
        Fill only holes whose size (the bounding-box diagonal of their rim in the view
        plane) is at most this length in world units, or a percentage of the valid
        cells' xy bounding-box diagonal such as ``"5%"``. Default: every hole.
    seed : int
        Seed of the fit when ``net`` is omitted.
    pieces : "auto" or 1
        The fit made when ``net`` is omitted (see :func:`~asrbf_mesh.fit`).
    progress : bool, optional
        Progress bar of the fit.

    Returns
    -------
    GridFillResult
        The filled ``z`` (grid units), the mask of filled cells and a report per hole.

    Raises
    ------
    ScanError
        If ``grid`` is not a RangeGrid or holds too few valid cells to fit.
    ConfigError
        If ``net`` is not a Network, ``max_hole_size`` is not a finite positive length
        or a percentage in (0, 100], ``seed`` is not an integer >= 0 or ``pieces`` is
        not ``"auto"`` or 1.
    """
    t0 = time.perf_counter()
    if not isinstance(grid, RangeGrid):
        raise ScanError(f"grid must be a RangeGrid (read it with read_range), got "
                        f"{type(grid).__name__}")
    if net is not None and not isinstance(net, Network):
        raise ConfigError(f"net must be a Network (or None: fitted here), "
                          f"got {type(net).__name__}")
    seed = check_seed(seed)
    check_pieces(pieces)
    where = f"{grid.source}: " if grid.source else ""
    world, index = grid.points()
    if len(index) == 0:
        raise ScanError(f"{where}no cell holds a measurement (all no-data)")
    xy_span = np.ptp(world[:, :2], axis=0)
    diag = float(np.hypot(*xy_span))
    limit = parse_length(max_hole_size, diag, "max_hole_size")
    # A depth image is a height field over its pixels: fitted and filled there, each cell
    # evaluated once. In metric camera coordinates a cell's (x, y) depends on its depth,
    # which took a fixed-point iteration per hole (about 23 network evaluations: 5.5 of
    # the 9.3 s of a Kinect frame). Sizes and max_hole_size stay in world units.
    work = grid
    if net is None and grid.kind == "depth" and grid.intrinsics is not None:
        work = dataclasses.replace(grid, intrinsics=None)
    pts = world if work is grid else work.points()[0]
    fit_seconds = 0.0
    if net is None:
        t_fit = time.perf_counter()
        net = _fit_grid(work, seed, pieces, progress)
        fit_seconds = time.perf_counter() - t_fit

    valid = np.isfinite(grid.z)
    _, holes, border_cells = grid_holes(~valid)
    cells = _Cells(work)
    R = net.frame.rotation
    row_of = np.full(valid.size, -1, dtype=np.int64)
    row_of[index] = np.arange(len(index))
    local = pts @ R
    zflat = grid.z.ravel()

    def spacing_at(rim: np.ndarray) -> tuple[float, float, float, tuple[float, float]]:
        z_ref = float(np.median(np.abs(zflat[rim])))
        py, px = cells.pixel(z_ref)
        rl = local[row_of[rim], :2]
        return float(np.hypot(*np.ptp(rl, axis=0))), min(py, px), z_ref, (py, px)

    z_out = np.array(grid.z, dtype=np.float64)
    out_flat = z_out.ravel()
    infos: list[GridHoleInfo] = []
    for i, hole in enumerate(holes):
        ring, rim, size = _ring(hole, valid, cells, spacing_at)
        rows, cols = np.divmod(hole, grid.shape[1])
        size_world = size if work is grid else float(np.hypot(*np.ptp(
            world[row_of[rim], :2], axis=0)))
        base = {"index": i, "cells": int(len(hole)), "size_abs": size_world,
                "size_pct": 100.0 * size_world / diag if diag > 0 else 0.0,
                "centre": (float(rows.mean()), float(cols.mean()))}
        if limit is not None and size_world > limit:
            infos.append(GridHoleInfo(**base, filled=False,
                                      reason=f"larger than max_hole_size ({size_world:.4g} > "
                                             f"{limit:.4g} world units)"))
            continue
        z, n_ring, side, reason = _fill_hole(hole, ring, rim, work, cells, net, local, row_of,
                                             zflat, size)
        if reason is not None:  # the spline failed or left the ring's range: a membrane
            split = _far_side(work, zflat[rim]) if side in ("far", "both") else None
            far_ring = ring[zflat[ring] > split] if split is not None else None
            z, why = _membrane(hole, far_ring, valid, zflat), reason
            reason = None if z is not None else why
            side = "membrane" if z is not None else side
        if reason is not None:
            infos.append(GridHoleInfo(**base, filled=False, reason=reason, ring_cells=n_ring,
                                      side=side))
            continue
        out_flat[hole] = z
        infos.append(GridHoleInfo(**base, filled=True, ring_cells=n_ring, side=side))
    filled = np.isnan(grid.z) & np.isfinite(z_out)
    return GridFillResult(z_out, filled, tuple(infos), border_cells,
                          time.perf_counter() - t0, fit_seconds, net)


def _fit_grid(grid: RangeGrid, seed: int, pieces: str | int, progress: bool | None) -> Network:
    """Fit the grid's valid cells (on a regular sub-grid when there are many)."""
    n = int(np.isfinite(grid.z).sum())
    step = 1
    if _FIT_MAX_CELLS is not None and n > _FIT_MAX_CELLS:
        step = int(math.ceil(math.sqrt(n / _FIT_MAX_CELLS)))
    if step > 1:
        sub = RangeGrid(grid.z[::step, ::step], grid.kind, intrinsics=_sub_intrinsics(
            grid.intrinsics, step), cell=None if grid.cell is None else
            (grid.cell[0] * step, grid.cell[1] * step), origin=grid.origin, source=grid.source)
    else:
        sub = grid
    scan: Scan = sub.to_scan()
    return fit(scan, seed=seed, pieces=pieces, progress=progress)


def _sub_intrinsics(k: tuple[float, float, float, float] | None, step: int
                    ) -> tuple[float, float, float, float] | None:
    """Intrinsics of the sub-grid of every ``step``-th row and column (same world points)."""
    if k is None:
        return None
    fx, fy, cx, cy = k
    return fx / step, fy / step, cx / step, cy / step


def _fill_hole(hole: np.ndarray, ring: np.ndarray, rim: np.ndarray, grid: RangeGrid,
               cells: _Cells,
               net: Network, local: np.ndarray, row_of: np.ndarray, zflat: np.ndarray,
               size: float) -> tuple[np.ndarray, int, str | None, str | None]:
    """Values (grid units) for one hole's cells; ring cells used, side, reason if none.

    A hole whose rim spans a depth jump is filled from the far side, except its cells
    inside the convex hull of the near side's rim cells: there the near surface itself
    runs into the hole (a hole across an object's edge), and they are filled from the
    near side. Beside a silhouette (a Kinect's projector shadow) the near rim is a thin
    curve whose hull holds next to no cell, so the shadow continues the background.
    """
    args = (grid, cells, net, local, row_of, zflat, size, rim)
    split = _far_side(grid, zflat[rim])
    if split is None:
        z, n, reason = _solve(hole, ring, True, *args)
        return z, n, None, reason
    rows, cols = np.divmod(hole, grid.shape[1])
    nr, nc = np.divmod(rim[zflat[rim] <= split], grid.shape[1])
    inside = _in_hull(np.column_stack([nr, nc]), np.column_stack([rows, cols]))
    z = np.empty(len(hole))
    used = 0
    # no substrate beside a depth edge: the network blends the near and far surfaces there
    for part, side_ring in ((~inside, ring[zflat[ring] > split]),
                            (inside, ring[zflat[ring] <= split])):
        if part.any():
            zz, n, reason = _solve(hole[part], side_ring, False, *args)
            if reason is not None:
                return np.zeros(0), n, "far", reason
            z[part] = zz
            used += n
    return z, used, "both" if inside.any() else "far", None


def _in_hull(pts: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Which points ``q`` lie in the convex hull of ``pts`` (none if it has no area)."""
    from scipy.spatial import Delaunay, QhullError

    if len(pts) < 3 or len(q) == 0:
        return np.zeros(len(q), dtype=bool)
    try:
        return Delaunay(pts.astype(np.float64)).find_simplex(q.astype(np.float64)) >= 0
    except (QhullError, ValueError):  # collinear: a straight silhouette
        return np.zeros(len(q), dtype=bool)


def _thin_ring(ring: np.ndarray, xy: np.ndarray, rim: np.ndarray) -> np.ndarray:
    """Return indices into ``ring`` of at most :data:`_GRID_RING_MAX` cells, rim cells first.

    The cells bordering the hole decide how the fill meets it: all of them are kept and
    the rest of the ring is thinned evenly to the remaining budget (a rim of more than
    half the budget is thinned evenly with the rest).
    """
    every = np.arange(len(ring))
    if len(ring) <= _GRID_RING_MAX:
        return every
    on_rim = np.isin(ring, rim)
    n_rim = int(on_rim.sum())
    if n_rim >= _GRID_RING_MAX // 2:
        return _thin_out(every, xy, _GRID_RING_MAX)
    rest = np.flatnonzero(~on_rim)
    return np.sort(np.concatenate([np.flatnonzero(on_rim),
                                   _thin_out(rest, xy, _GRID_RING_MAX - n_rim)]))


def _solve(hole: np.ndarray, ring: np.ndarray, substrate: bool, grid: RangeGrid,
           cells: _Cells, net: Network, local: np.ndarray, row_of: np.ndarray,
           zflat: np.ndarray, size: float, rim: np.ndarray
           ) -> tuple[np.ndarray, int, str | None]:
    """Values for cells ``hole`` from ``ring``: substrate + thin plate; cells used, reason."""
    fnet = _lowpass(net, size, _LOWPASS if substrate else np.inf)
    rl = local[row_of[ring]]
    rl = rl[_thin_ring(ring, rl[:, :2], rim)]
    if len(rl) < 3:
        return np.zeros(0), len(rl), f"only {len(rl)} valid cells around it"
    res = rl[:, 2] - fnet.evaluate(rl[:, :2])
    centre = rl[:, :2].mean(axis=0)
    scale = size if size > 0 else 1.0
    try:
        spline = RBFInterpolator((rl[:, :2] - centre) / scale, res,
                                 kernel="thin_plate_spline", neighbors=None)
    except (np.linalg.LinAlgError, ValueError):  # ring on one line: no plane through it
        mean = float(res.mean())

        def spline(q: np.ndarray) -> np.ndarray:
            return np.full(len(q), mean)

    def depth(q_local_xy: np.ndarray) -> np.ndarray:
        return fnet.evaluate(q_local_xy) + spline((q_local_xy - centre) / scale)

    # start every cell at the ring's median depth, then follow each cell's ray
    z = np.full(len(hole), float(np.median(zflat[ring])))
    R = net.frame.rotation
    fixed = grid.kind == "elevation" or grid.intrinsics is None
    exact = fixed and np.allclose(R[:2, 2], 0.0) and np.allclose(R[2, :2], 0.0)
    for _ in range(1 if exact else _RAY_ITER):
        q = cells.world(hole, z) @ R
        q[:, 2] = depth(q[:, :2])
        z_new = cells.z_of((q @ R.T)[:, 2])
        if not np.all(np.isfinite(z_new)):
            return np.zeros(0), len(rl), "the fill is not finite"
        moved = float(np.max(np.abs(z_new - z))) if len(z) else 0.0
        z = z_new
        if exact or moved <= 1e-9 * max(float(np.max(np.abs(z))), 1e-300):
            break
    if grid.kind == "depth" and np.any(z <= 0):
        return np.zeros(0), len(rl), "the fill reaches behind the camera (depth <= 0)"
    zr = zflat[ring]
    lo, hi = float(zr.min()), float(zr.max())
    if np.any(z < lo - (hi - lo)) or np.any(z > hi + (hi - lo)):
        return np.zeros(0), len(rl), "the fill leaves its ring's range"
    return z, len(rl), None


def _membrane(hole: np.ndarray, allowed: np.ndarray | None, valid: np.ndarray,
              zflat: np.ndarray) -> np.ndarray | None:
    """Harmonic interpolation over a hole's cells of its valid 4-neighbours' values.

    The fallback when the network and the ring's thin plate fail (a one-sided ring
    extrapolated behind the camera or far beyond its range): a discrete Laplace equation
    whose solution stays within the values around the hole. ``allowed`` limits the
    boundary to those cells (a depth edge's far side: the near side is left free).
    """
    import scipy.sparse as sp
    from scipy.sparse.linalg import spsolve

    H, W = valid.shape
    n = len(hole)
    at = np.full(H * W, -1, dtype=np.int64)
    at[hole] = np.arange(n)
    rows, cols = np.divmod(hole, W)
    ok_boundary = valid.ravel().copy()
    if allowed is not None:
        ok_boundary[:] = False
        ok_boundary[allowed] = True
    diag = np.zeros(n)
    rhs = np.zeros(n)
    ii: list[np.ndarray] = []
    jj: list[np.ndarray] = []
    for dr, dc in ((-1, 0), (1, 0), (0, -1), (0, 1)):
        r, c = rows + dr, cols + dc
        inside = (r >= 0) & (r < H) & (c >= 0) & (c < W)
        nb = np.where(inside, r * W + c, 0)
        inner = inside & (at[nb] >= 0)
        ii.append(np.flatnonzero(inner))
        jj.append(at[nb[inner]])
        edge = inside & ~inner & ok_boundary[nb]
        diag += inner + edge
        np.add.at(rhs, np.flatnonzero(edge), zflat[nb[edge]])
    known = zflat[ok_boundary & valid.ravel()]
    if len(known) == 0:
        return None
    eps = 1e-9  # keeps parts of the hole without a boundary cell at the boundary's median
    i, j = np.concatenate(ii), np.concatenate(jj)
    A = sp.coo_matrix((np.r_[diag + eps, -np.ones(len(i))], (np.r_[np.arange(n), i],
                                                            np.r_[np.arange(n), j])),
                      shape=(n, n)).tocsc()
    z = spsolve(A, rhs + eps * float(np.median(known)))
    return z if np.all(np.isfinite(z)) else None
