"""Which piece of a piecewise network owns a point of the view plane.

A :class:`PieceMap` is a raster over the unit square (extended to the data) whose cells
hold the piece of the nearest scan point, so every point of the plane, on the scan,
in a hole or beyond the border, has exactly one piece: the surface a piecewise network
evaluates there. Cells are one sampling spacing wide, or a half or a third of it where
the pieces' samples interleave at a cliff: the coarsest of these at which at least
:data:`MIN_AGREEMENT` of the points fall in cells of their own piece (on bun090, the
Stanford bunny seen from the side, 98.9 % at one spacing, 99.94 % at a half).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ._grid_knn import bounds, nearest_feature
from ._validate import readonly
from .errors import ConfigError

__all__ = ["PieceMap", "MAX_MAP_CELLS", "MIN_AGREEMENT"]

#: Upper bound on the raster's cells; a finer spacing coarsens the cells to fit.
MAX_MAP_CELLS = 4_000_000
#: Share of the points whose own piece the map must give back (see the module text).
MIN_AGREEMENT = 0.999
_CELL_FACTORS = (1.0, 0.5, 1.0 / 3.0)


@dataclass(frozen=True, eq=False)
class PieceMap:
    """Raster of piece labels over the unit square (the network's frame).

    Parameters
    ----------
    lo : (2,) float64 array
        Unit-square coordinates of the raster's lower corner.
    cell : float
        Cell size, unit square.
    labels : (ny, nx) integer array
        Piece of each cell; row ``j``, column ``i`` covers
        ``lo + (i, j) * cell .. lo + (i + 1, j + 1) * cell``.
    """

    lo: np.ndarray
    cell: float
    labels: np.ndarray

    def __post_init__(self) -> None:
        lo = np.asarray(self.lo, dtype=np.float64).reshape(-1)
        labels = np.asarray(self.labels)
        if (lo.shape != (2,) or not np.all(np.isfinite(lo)) or not np.isfinite(self.cell)
                or self.cell <= 0 or labels.ndim != 2 or labels.size == 0
                or labels.dtype.kind not in "iu" or labels.min() < 0):
            raise ConfigError("a piece map needs a finite corner, a positive cell and a "
                              "non-empty 2D raster of piece indices >= 0")
        object.__setattr__(self, "lo", readonly(lo))
        object.__setattr__(self, "cell", float(self.cell))
        object.__setattr__(self, "labels", readonly(labels))

    @property
    def n_pieces(self) -> int:
        """One more than the largest piece index in the raster."""
        return int(self.labels.max()) + 1

    def piece_at(self, uv: np.ndarray) -> np.ndarray:
        """Piece of each (M, 2) unit-square point; points beyond the raster take its edge."""
        ny, nx = self.labels.shape
        ij = np.floor((np.asarray(uv, dtype=np.float64) - self.lo) / self.cell)
        i = np.clip(ij[:, 0], 0, nx - 1).astype(np.int64)
        j = np.clip(ij[:, 1], 0, ny - 1).astype(np.int64)
        return self.labels[j, i].astype(np.int64)

    @classmethod
    def of_points(cls, uv: np.ndarray, labels: np.ndarray, spacing: float) -> PieceMap:
        """Map of labelled unit-square points: each cell takes its nearest point's piece.

        Cells ``spacing`` wide, else a half or a third of it: the coarsest whose map
        gives at least :data:`MIN_AGREEMENT` of the points their own piece (the finest
        tried when none does). A point's own cell is occupied, so the share is measured
        before the empty cells are filled, and only the chosen raster is filled (a
        Kinect frame tried all three: 0.86 s, mostly in filling them).
        """
        uv = np.asarray(uv, dtype=np.float64)
        best, best_share = None, -1.0
        for factor in _CELL_FACTORS:
            lo, cell, raster, occupied, ij = cls._occupied(uv, labels, spacing * factor)
            share = float(np.mean(raster[ij[:, 1], ij[:, 0]] == labels)) if len(uv) else 1.0
            if share > best_share:
                best, best_share = (lo, cell, raster, occupied), share
            if share >= MIN_AGREEMENT:
                break
        return cls._filled(*best)  # type: ignore[misc]

    @classmethod
    def _raster(cls, uv: np.ndarray, labels: np.ndarray, spacing: float) -> PieceMap:
        """Return the map at one cell size (see :meth:`_occupied`), empty cells filled."""
        return cls._filled(*cls._occupied(uv, labels, spacing)[:4])

    @classmethod
    def _filled(cls, lo: np.ndarray, cell: float, raster: np.ndarray,
                occupied: np.ndarray) -> PieceMap:
        """Return the map whose empty cells take the nearest occupied cell's piece."""
        if not occupied.all():
            near = nearest_feature(occupied)  # scipy's feature transform, bit for bit
            raster = raster[near[0], near[1]]
        return cls(lo, cell, raster)

    @staticmethod
    def _occupied(uv: np.ndarray, labels: np.ndarray, spacing: float):
        """Return the raster at one cell size, occupied cells only (lo, cell, raster, occ, ij).

        Cells ``spacing`` wide (coarser if that would exceed :data:`MAX_MAP_CELLS`),
        spanning the unit square and the points plus two cells. A cell holding points of
        several pieces takes the piece of the last of them in input order
        (deterministic); ``occ`` marks the occupied cells and ``ij`` is each point's cell
        (column, row).
        """
        lo, hi = bounds(uv)
        lo, hi = np.minimum(lo, 0.0), np.maximum(hi, 1.0)
        cell = max(float(spacing), float(np.sqrt(np.prod(hi - lo) / MAX_MAP_CELLS)))
        lo = lo - 2 * cell
        nx, ny = (np.ceil((hi - lo) / cell).astype(np.int64) + 2)
        ij = np.floor((uv - lo) / cell).astype(np.int64)
        top = int(labels.max(initial=0))
        dtype = np.uint8 if top < 255 else np.uint16 if top < 65535 else np.int32
        raster = np.zeros((ny, nx), dtype=dtype)
        occupied = np.zeros((ny, nx), dtype=bool)
        raster[ij[:, 1], ij[:, 0]] = labels
        occupied[ij[:, 1], ij[:, 0]] = True
        return lo, cell, raster, occupied, ij
