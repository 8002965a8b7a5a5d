"""The data's shape at a piece's points, for its tails: slopes and border directions.

The tail refinement (:func:`~asrbf_mesh._pieces.refine_tails`) measures a point's error
across the surface, not along the view (:func:`across`), from the data's slope at the
point and, on the piece's border, the border's outward direction (:func:`data_shape`);
:class:`DataShapes` measures them beside the learning, on a core it leaves idle.
"""

from __future__ import annotations

import numpy as np

from ._frame import HeightField
from ._grid_knn import point_grid
from ._piece import Piece

__all__ = ["BORDER_GAP", "SHAPE_CHUNK", "SLOPE_NEIGHBOURS", "DataShapes", "across",
           "data_shape", "past_border"]

#: The data's slope at a point is a plane through this many samples.
SLOPE_NEIGHBOURS = 8
#: A point whose 8 nearest samples leave a gap of directions wider than this (radians)
#: lies on its piece's border: 180 degrees on a straight border of a range grid, 45
#: inside it (:func:`data_shape`).
BORDER_GAP = np.deg2rad(160.0)
#: :class:`DataShapes` measures this many points between two looks at whether to stop.
SHAPE_CHUNK = 4096


def across(piece: Piece, sub: HeightField, res: np.ndarray, at: np.ndarray,
            scale: np.ndarray, support: float, grid: tuple, shape: np.ndarray,
            loose: np.ndarray | None = None) -> np.ndarray:
    """Return the error across the surface at points ``at``, not along the view.

    A steep point whose depth is off by 5 E may lie within E of the surface: the depth
    error times the cosine of the slope, the slope taken in physical proportions. The
    slope is the smaller of the network's and the data's (a plane through the point's
    eight nearest samples, ``grid`` the piece's points binned): a network that swings
    steeply where the scan does not is off by its whole depth error. So is a point on
    the piece's border whose perpendicular onto the surface would land past the border
    (its foot moves by ``r grad f / (1 + |grad f|^2)`` in the view plane, ``r`` the depth
    error): the surface ends there, and the point is as far from it as its depth error
    (at the silhouettes of two cow views the pieces' networks missed such points by
    0.7-1.3 E, all on one side, and the reconstruction's 99.9th percentile of scan ->
    mesh distances stood at 0.62-0.66 % of the diagonal). ``shape`` holds per point the
    data's squared slope and the outward direction of the border (zero inside; NaN rows
    not yet measured, filled here: the data do not change between rounds). A point in no
    scan triangle (``loose``: a flying pixel, a lone return) is no surface's border: on
    the face map half the points the rule took were such.
    """
    if len(at) == 0:
        return np.zeros(0)
    grad = piece.eval_unit(sub.xy[at], support, True)[1]
    net = grad * (scale[2] / scale[:2])
    new = at[np.isnan(shape[at, 0])]
    if len(new):
        shape[new] = data_shape(sub, grid, new, scale)
    s2 = np.minimum(np.einsum("ij,ij->i", net, net), shape[at, 0])
    past = past_border(grad, res[at], shape[at, 1:], scale,
                        None if loose is None else loose[at])
    return np.abs(res[at]) / np.sqrt(1.0 + np.where(past, 0.0, s2))


def past_border(grad: np.ndarray, res: np.ndarray, outward: np.ndarray, scale: np.ndarray,
                 loose: np.ndarray | None) -> np.ndarray:
    """Whether each point's perpendicular onto the surface lands past its piece's border.

    ``grad``: the network's gradient at the points (unit square), ``res`` their depth
    errors, ``outward`` the border's outward direction (zero inside, :func:`data_shape`);
    ``loose`` points (in no scan triangle) never.
    """
    past = np.einsum("ij,ij->i", grad * (scale[2] / scale[:2]), outward) * res > 0.0
    return past if loose is None else past & ~loose


class DataShapes:
    """:func:`data_shape` at every point of a piece, measured beside its learning.

    :meth:`run` (on a core the learning leaves idle: sequential learning runs on one)
    measures the points in chunks of :data:`SHAPE_CHUNK`; :meth:`take` (by
    :func:`~asrbf_mesh._pieces.refine_tails`, when its first round starts) stops it after
    the chunk in hand and returns the piece's point grid and the shapes measured so far
    (rows not reached NaN, which the rounds measure as they need them: the same numbers
    either way), or None if it had not started. The face map's main piece (83,000
    points): about 80 ms beside a learning of 155 ms, where its tails measured 13 ms of
    it point by point.
    """

    def __init__(self, sub: HeightField):
        import threading

        self.sub = sub
        self._lock = threading.Lock()
        self._stop = False
        self._got: tuple[tuple, np.ndarray] | None = None

    def run(self) -> None:
        """Measure every point's shape, chunk by chunk, until done or :meth:`take` stops it.

        A failure stops it quietly: the rows not measured are measured by the tails, which
        raise the same error where the fit can report it.
        """
        from ._network_kernels import numba_threads

        sub = self.sub
        scale = np.asarray(sub.frame.scale, dtype=np.float64)
        try:
            with numba_threads(1), self._lock:  # (its kernels are serial: no team of threads)
                if self._stop:
                    return
                grid = point_grid(sub.xy)
                self._got = grid, np.full((sub.n_points, 3), np.nan)
            for c0 in range(0, sub.n_points, SHAPE_CHUNK):
                with numba_threads(1), self._lock:
                    if self._stop:
                        return
                    at = np.arange(c0, min(c0 + SHAPE_CHUNK, sub.n_points))
                    self._got[1][at] = data_shape(sub, grid, at, scale)
        except Exception:  # noqa: BLE001 - see above
            self._stop = True

    def take(self) -> tuple[tuple, np.ndarray] | None:
        """Stop :meth:`run` and return (grid, shapes so far), or None if it never began."""
        self._stop = True
        with self._lock:  # waits for the chunk in hand
            return self._got


def data_shape(sub: HeightField, grid: tuple, at: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """Return the data's squared slope at points ``at`` and the border's outward direction.

    The slope: a plane through the point's nearest samples. The border: where the
    directions to the point's 8 nearest other samples (physical proportions) leave a gap
    wider than :data:`BORDER_GAP`, the unit vector halving it; zero elsewhere. ``grid`` is
    :func:`~asrbf_mesh._grid_knn.point_grid` of the piece's points.
    """
    from ._grid_knn import knn, plane_slopes

    ratio = scale[2] / scale[:2]
    out = np.zeros((len(at), 3))
    k = min(SLOPE_NEIGHBOURS, sub.n_points)
    out[:, 0] = plane_slopes(sub.xy, sub.z, at, k, float(ratio[0]), float(ratio[1]), *grid)
    if sub.n_points < 4:
        return out
    _, nb = knn(sub.xy, at, min(9, sub.n_points), grid)
    d = (sub.xy[nb[:, 1:]] - sub.xy[at, None]) * scale[:2]
    ang = np.sort(np.arctan2(d[..., 1], d[..., 0]), axis=1)
    gaps = np.diff(np.concatenate([ang, ang[:, :1] + 2.0 * np.pi], axis=1), axis=1)
    j = np.argmax(gaps, axis=1)
    rows = np.arange(len(at))
    wide = gaps[rows, j] > BORDER_GAP
    mid = ang[rows, j] + 0.5 * gaps[rows, j]
    out[wide, 1], out[wide, 2] = np.cos(mid[wide]), np.sin(mid[wide])
    return out
