"""The scanner frame: view axis, normalization to the unit cube and back.

A range scan is a height field ``depth = f(x, y)`` seen along a view axis. The
paper normalizes each axis of the scan to [0, 1] (section 4.1) and learns in that
unit cube; :class:`Frame` holds the rotation and the per-axis offsets and spans
to go back to physical units.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import Literal

import numpy as np

from . import _config
from ._grid_knn import bounds, knn
from ._mesh import collinear_xy as _collinear_xy
from ._validate import check_points
from .errors import ConfigError, ScanError

__all__ = ["Frame", "HeightField", "HeightFieldWarning", "DuplicatePointsWarning",
           "to_height_field", "fold_fraction", "duplicate_fraction", "sampling_spacing",
           "VIEW_AXES"]

ViewAxis = Literal["z", "x", "y", "pca"]
VIEW_AXES = _config.VIEW_AXES

# local axes (columns) for the fixed view axes: right-handed, depth last
_AXES = {
    "z": np.eye(3),
    "x": np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]),  # (y, z, x)
    "y": np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]]),  # (z, x, y)
}


class HeightFieldWarning(UserWarning):
    """The data is far from a single-valued height field in the chosen frame."""


class DuplicatePointsWarning(UserWarning):
    """Many points are exact copies of others: they weigh more in the fit."""


@dataclass(frozen=True, eq=False)
class Frame:
    """Map between world coordinates and the normalized unit cube.

    ``local = world @ rotation``; ``unit = (local - offset) / scale``.

    Parameters
    ----------
    rotation : (3, 3) float64 array
        Orthonormal, right-handed; its columns are the local x, y and depth axes
        in world coordinates.
    offset : (3,) float64 array
        Minimum of the local coordinates.
    scale : (3,) float64 array
        Extent of the local coordinates (1 for a zero depth extent).
    view_axis : str
        How the rotation was chosen (``"z"``, ``"x"``, ``"y"`` or ``"pca"``).
    """

    rotation: np.ndarray
    offset: np.ndarray
    scale: np.ndarray
    view_axis: str = "z"

    def __post_init__(self) -> None:
        for name, shape in (("rotation", (3, 3)), ("offset", (3,)), ("scale", (3,))):
            arr = np.array(getattr(self, name), dtype=np.float64)
            if arr.shape != shape or not np.all(np.isfinite(arr)):
                raise ConfigError(f"Frame.{name} must be a finite array of shape {shape}")
            arr.flags.writeable = False
            object.__setattr__(self, name, arr)
        if np.any(self.scale <= 0):
            raise ConfigError("Frame.scale must be positive")

    def to_unit(self, world: np.ndarray) -> np.ndarray:
        """World (N, 3) points to unit-cube coordinates (N, 3)."""
        return (np.asarray(world, dtype=np.float64) @ self.rotation - self.offset) / self.scale

    def to_world(self, unit: np.ndarray) -> np.ndarray:
        """Unit-cube (N, 3) points back to world coordinates (N, 3)."""
        local = np.asarray(unit, dtype=np.float64) * self.scale + self.offset
        return local @ self.rotation.T

    def xy_to_unit(self, xy: np.ndarray) -> np.ndarray:
        """Local physical (x, y) (M, 2) to unit-square coordinates (M, 2)."""
        return (np.asarray(xy, dtype=np.float64) - self.offset[:2]) / self.scale[:2]

    def xy_from_unit(self, uv: np.ndarray) -> np.ndarray:
        """Unit-square (M, 2) to local physical (x, y) (M, 2)."""
        return np.asarray(uv, dtype=np.float64) * self.scale[:2] + self.offset[:2]

    def to_dict(self) -> dict:
        """Plain-JSON form."""
        return {"rotation": self.rotation.tolist(), "offset": self.offset.tolist(),
                "scale": self.scale.tolist(), "view_axis": self.view_axis}

    @classmethod
    def from_dict(cls, d: dict) -> Frame:
        """Inverse of :meth:`to_dict`."""
        return cls(np.array(d["rotation"]), np.array(d["offset"]), np.array(d["scale"]),
                   str(d["view_axis"]))


@dataclass(frozen=True, eq=False)
class HeightField:
    """Scan points in the unit cube, ready for learning.

    Parameters
    ----------
    xy : (N, 2) float64 array
        Network inputs in [0, 1]^2.
    z : (N,) float64 array
        Depths in [0, 1].
    frame : Frame
        The map back to world units.
    spacing : float
        Typical sampling spacing in the unit square (median xy nearest-neighbour
        distance); the automatic D_min is twice this value (paper, section 5.1).
    fold : float
        Fraction of the points on a fold along the view axis (:func:`fold_fraction`).
    """

    xy: np.ndarray
    z: np.ndarray
    frame: Frame
    spacing: float
    fold: float = 0.0

    @property
    def n_points(self) -> int:
        """Number of points N."""
        return int(len(self.z))


def _rotation(points: np.ndarray, view_axis: str) -> np.ndarray:
    if view_axis in _AXES:
        return _AXES[view_axis].copy()
    if view_axis != "pca":
        raise ScanError(f"view_axis must be one of {', '.join(VIEW_AXES)}; got {view_axis!r}")
    centred = points - points.mean(axis=0)
    _, vecs = np.linalg.eigh(centred.T @ centred)  # ascending eigenvalues
    depth, ax1, ax0 = vecs[:, 0], vecs[:, 1], vecs[:, 2]
    # deterministic signs: largest component of each axis positive
    ax0 = ax0 * np.sign(ax0[np.argmax(np.abs(ax0))])
    depth = depth * np.sign(depth[np.argmax(np.abs(depth))])
    ax1 = np.cross(depth, ax0)
    return np.column_stack([ax0, ax1, depth])


#: :func:`sampling_spacing`: points closer than this share of the larger extent are one
#: (copies written twice, once through float32; a cloud with half its points repeated
#: 1e-13 away made a spacing of 1e-13 and a footprint raster of 10^26 cells).
NEAR_COPY = 1e-9


def sampling_spacing(xy: np.ndarray, *, max_samples: int = 50_000, seed: int = 0) -> float:
    """Median nearest-neighbour distance of (N, 2) points (ignoring copies).

    Copies: points at the same place, or within :data:`NEAR_COPY` of the larger extent.

    Examples
    --------
    >>> g = np.stack(np.meshgrid(np.arange(5.0), np.arange(4.0)), -1).reshape(-1, 2)
    >>> round(sampling_spacing(g / 100), 12)
    0.01
    """
    if len(xy) > max_samples:
        rng = np.random.default_rng(seed)
        at = rng.choice(len(xy), max_samples, replace=False)
    else:
        at = np.arange(len(xy))
    d, _ = knn(xy, at, min(4, len(xy)))
    d = d[:, 1:]
    near = NEAR_COPY * float(np.ptp(xy, axis=0).max()) if len(xy) else 0.0
    d = np.where(d > near, d, np.inf).min(axis=1)
    if not np.isfinite(d).all():
        # some point has only copies among its nearest neighbours: measure the distinct
        # positions instead (a scan without such copies keeps its exact spacing)
        if near > 0:
            cells = np.floor((xy - xy.min(axis=0)) / near)
            distinct = xy[np.unique(cells, axis=0, return_index=True)[1]]
        else:
            distinct = np.unique(xy, axis=0)
        if len(distinct) < 2:
            raise ScanError("all points share the same (x, y): no sampling spacing")
        if len(distinct) < len(xy):
            return sampling_spacing(distinct, max_samples=max_samples, seed=seed)
        d = d[np.isfinite(d)]
    return float(np.median(d))


def duplicate_fraction(points: np.ndarray) -> float:
    """Fraction of the (N, D) rows that repeat an earlier row exactly.

    Examples
    --------
    >>> duplicate_fraction(np.array([[0.0, 1.0], [2.0, 3.0], [0.0, 1.0], [0.0, 1.0]]))
    0.5
    """
    if len(points) < 2:
        return 0.0
    rows = points[np.lexsort(points.T[::-1])]
    return float(np.all(rows[1:] == rows[:-1], axis=1).sum() / len(points))


def fold_fraction(local: np.ndarray, *, max_slope: float = 20.0, k: int = 6,
                  max_samples: int = 50_000, seed: int = 0) -> float:
    """Fraction of points that sit on a fold of the surface along the depth axis.

    A point is on a fold when one of its ``k`` nearest neighbours in (x, y) lies at a
    depth that no plausible surface slope explains: ``|dz| > max_slope * |dxy|`` (an
    87 degree wall) and ``|dz|`` above 2 % of the xy extent. Slopes are taken in
    physical units, so measurement noise on a flat scan does not count, while the
    front and back of an object seen through each other do.

    Parameters
    ----------
    local : (N, 3) array
        Points in the view frame, physical units, depth last.
    """
    xy = local[:, :2]
    z = local[:, 2]
    lo, hi = bounds(xy)
    extent = float(np.linalg.norm(hi - lo))
    idx = np.arange(len(xy))
    if len(xy) > max_samples:
        idx = np.random.default_rng(seed).choice(len(xy), max_samples, replace=False)
    d, nb = knn(xy, idx, min(k + 1, len(xy)))
    dz = np.abs(z[nb[:, 1:]] - z[idx, None])
    wall = (dz > max_slope * d[:, 1:]) & (dz > 0.02 * extent)
    return float(np.mean(wall.any(axis=1)))


def to_height_field(points: np.ndarray, *, view_axis: ViewAxis = "z",
                    warn_fraction: float = 0.05) -> HeightField:
    """Normalize scan points into the unit cube along a view axis.

    Parameters
    ----------
    points : (N, 3) float64 array
        Scan points in world units.
    view_axis : {"z", "x", "y", "pca"}
        Depth direction: a world axis, or the smallest principal axis.
    warn_fraction : float
        Emit :class:`HeightFieldWarning` when more than this fraction of the points
        lie on a fold of the surface in this frame (see :func:`fold_fraction`), and
        :class:`DuplicatePointsWarning` when more than this fraction are exact copies
        of other points (see :func:`duplicate_fraction`).

    Returns
    -------
    HeightField

    Raises
    ------
    ScanError
        If x or y has zero extent in the chosen frame, all points lie on one line in
        (x, y), or the points are not finite.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> p = rng.random((500, 3)) * [10, 20, 1] + [5, 0, -3]
    >>> hf = to_height_field(p)
    >>> bool(hf.xy.min() == 0.0 and hf.xy.max() == 1.0)
    True
    >>> bool(np.allclose(hf.frame.to_world(np.c_[hf.xy, hf.z]), p))
    True
    """
    pts = check_points(points, "points", min_points=0)
    rot = _rotation(pts, view_axis)
    local = pts @ rot
    lo, hi = bounds(local)
    frame = frame_from_bounds(rot, lo, hi, float(max(-lo.min(), hi.max())), view_axis,
                              local[:, :2])
    xy, z = unit_height_field(frame, local)
    spacing = sampling_spacing(xy)
    fold = check_height_field(local, pts, view_axis, warn_fraction, stacklevel=2)
    return HeightField(xy, z, frame, spacing, fold)


def frame_from_bounds(rot: np.ndarray, lo: np.ndarray, hi: np.ndarray, absmax: float,
                      view_axis: str, xy: np.ndarray | None = None) -> Frame:
    """Return the unit-cube frame of points whose view-frame coordinates span ``[lo, hi]``.

    Raises :class:`ScanError` for a zero x or y extent and, given the points' local
    ``xy`` (or a sample of them), for points all on one line; a zero depth extent
    (a flat scan) is valid and maps every depth to 0.
    """
    span = np.asarray(hi, dtype=np.float64) - lo
    tiny = 1e-12 * max(absmax, 1e-300)
    for axis, name in ((0, "x"), (1, "y")):
        if span[axis] <= tiny:
            raise ScanError(
                f"zero {name} extent in the {view_axis!r} view frame: a height field needs "
                "an x and a y extent (try another --view-axis)")
    if xy is not None and _collinear_xy(xy):
        raise ScanError(
            f"all points lie on one line in (x, y) of the {view_axis!r} view frame: a height "
            "field needs points spread over an area (try another --view-axis)")
    if span[2] <= tiny:
        span[2] = 1.0  # flat scan: valid, depth maps to 0
    return Frame(rot, lo, span, view_axis)


def unit_height_field(frame: Frame, local: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """View-frame points (N, 3) to the unit square inputs (N, 2) and unit depths (N,)."""
    unit = (local - frame.offset) / frame.scale
    return (np.ascontiguousarray(np.clip(unit[:, :2], 0.0, 1.0)),
            np.ascontiguousarray(np.clip(unit[:, 2], 0.0, 1.0)))


def other_axes(view_axis: str) -> str:
    """Return the view axes other than ``view_axis``, as advice: ``'x, y or pca'``.

    Examples
    --------
    >>> other_axes("pca")
    'z, x or y'
    """
    rest = [a for a in VIEW_AXES if a != view_axis]
    return f"{', '.join(rest[:-1])} or {rest[-1]}"


def check_height_field(local: np.ndarray, pts: np.ndarray, view_axis: str,
                       warn_fraction: float = 0.05, stacklevel: int = 2) -> float:
    """Warn when the points (or a sample) fold over along the view axis or repeat.

    Returns the fraction of the points on a fold (:func:`fold_fraction`).
    """
    bad = fold_fraction(local)
    if bad > warn_fraction:
        warnings.warn(
            f"{100 * bad:.0f}% of the points lie where the surface folds over itself along the "
            f"{view_axis!r} axis (several depths at one x, y): the data is not a height field "
            f"in this frame; try --view-axis {other_axes(view_axis)}",
            HeightFieldWarning, stacklevel=stacklevel + 1)
    dup = duplicate_fraction(pts)
    if dup > warn_fraction:
        warnings.warn(
            f"{100 * dup:.0f}% of the points are exact copies of other points: each copy "
            "counts again in the fit and in E-bar (remove duplicates to weigh every sample "
            "once)", DuplicatePointsWarning, stacklevel=stacklevel + 1)
    return bad
