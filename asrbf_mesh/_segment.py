"""Segmentation of a scan into pieces that are each a smooth height field in the view frame.

The first building block of piecewise networks: a scan seen from one view is cut where
the surface is not a smooth height field, at the triangles seen nearly edge-on (walls)
and across depth jumps (occlusion cliffs), and the rest falls apart into connected
pieces, each of which a network can fit on its own.

The rule, on triangles (the scan's own, or for a bare point cloud a tight Delaunay
triangulation of its footprint in the view plane, :func:`point_cloud_faces`, or for
points on a regular lattice, a range grid saved as points, the lattice's cells,
:func:`~asrbf_mesh._footprint.lattice_faces`):

1. a triangle is *cut* when it is seen nearly edge-on, ``|n . view| < cos(wall_angle)``
   (its slope exceeds ``tan(wall_angle)``; 80 degrees is ``|n . view| < 0.17``), when its
   longest edge exceeds ``jump_factor`` times the median edge length of the scan, or when
   it has no area; but a triangle (or, in rule 4, a pair) whose depth extent is below the
   *minimum step* is never cut: 1 % of the scan's depth extent (between its 1st and
   99th percentiles; the default fit's error threshold E, so a smaller step is within
   what the network smooths anyway), or 2.5 depth quanta where the depths come in
   levels (a depth camera's disparity steps, read from the gaps between the distinct
   depth values around the triangle's depth). Angles and lengths are measured in the
   scan's own units, rotated into
   the view frame: the axes share one unit, so a slope is a physical slope (the unit cube
   of :func:`~asrbf_mesh.to_height_field` scales depth and plane differently);
   (1b) nor is a triangle on a smooth surface, however steep: when a quadratic height
   field through the 16 points around it misses them by less than ``SMOOTH_FIT`` (0.1)
   of the triangle's depth extent (RMS), or (by default, where depths do not come in
   levels) by less than ``NOISE_SMOOTH`` (3) times the scan's noise scale, the median
   RMS of the same fits at a sample of points (:meth:`_Smooth.noise`). Across a cliff the
   points around hold both levels; on a steep slope of a smooth surface (a synthetic
   grid z = sin(3 pi x) cos(3 pi y) on the unit square has slopes up to 13) the
   quadratic fits them to the noise, and noise of 1 % of the depth range makes
   triangles steep that the surface is not (465 pieces without the noise scale);
2. the pieces are the connected components of the kept triangles' edges;
3. a point used by cut triangles only (or by none) joins the piece of its nearest kept
   vertex in 3D, so every point has a piece;
4. a piece that still holds two points close in the view plane (within two sampling
   spacings there) but apart in depth by a jump (steeper than the wall angle and
   longer than ``jump_factor`` median edges, the points around them no quadratic
   height field by rule 1b's test) wraps around the end of a cliff: its upper
   and lower sides are joined only by a detour around the cliff's end, and no smooth
   height field can take both. When the longest such cliff (jump pairs chained within
   three pair radii) has at least ``_MIN_CLIFF_PAIRS`` pairs, the piece is split along
   the geodesic bisector between the two sides (each point goes to the side of its
   nearest jump point along the triangles' edges within the piece, the wall's too, so
   the cut runs through the wall), and the parts are checked again, at most
   ``_SPLIT_ROUNDS`` times;
5. pieces are numbered by their smallest point index (same input, same labels), and a
   piece with fewer than ``min_piece_points`` points is flagged ``small`` (to be fitted by
   a plane or a constant later, not a network).

On a bare cloud a cliff shows up as Delaunay triangles bridging two depths: steep (cut
by the wall rule, the slope ``|dz| / |dxy|`` of a jump of ten spacings is about 10) and
long in 3D (cut by the jump rule).

Defaults, measured with ``scripts/bench_segment.py``: the prototype's 72.5 degrees and 3
median edges cut the grazing borders of every scan into fragments (19 to 69 small pieces
per scan, 60 to 85 pieces on the bunny scans) and split the face map's one surface in
three large pieces; 80 degrees and 5 median edges give the face map its own 17 connected
parts (one of 83,000 points, 97 %), each bunny scan 8 to 13 pieces with 1 to 3 large ones,
and still split bun090 at its occlusion cliffs (17,259, 9,366 and 3,217 points). Wider
settings (85 degrees, 8 edges) merge two of bun090's pieces across a cliff.

The minimum step was added for depth-camera frames in metric coordinates (TUM RGB-D,
meshed with their intrinsics): the Kinect's depth quantum grows with the square of the
depth (about 3 cm at 3 m), its one-level risers are steeper than the wall angle and
longer than 5 median edges, and they cut a frame into 1,189 pieces (866 small) with
64,885 of its 397,101 triangles cut; with the minimum step, 95 pieces and 1 cut
(rule 4 still splits 36 pieces at its real cliffs).
It changes no piece of the five dev scans (their steps are far above it).

Rule 4 was added when the reconstruction's tails were traced (``scripts/bench_pieces.py``):
bun090's 9,366-point piece held 125 such jump pairs, its worst residuals (up to 0.15 of
the unit depth) sat on the ramp the network put across the cliff, and the mesh's 99.9th
percentile distance to the scan was 1.5 % of the diagonal (0.5 % with rule 4 and the
tail refinement of :mod:`asrbf_mesh._pieces`). A cliff of fewer than 15 pairs splits no
piece: on the face map, shorter ones split off slivers that cost neurons and no error.
"""

from __future__ import annotations

import math
from concurrent.futures import FIRST_COMPLETED, ThreadPoolExecutor, wait
from dataclasses import dataclass
from typing import Any

import numpy as np

from . import _config
from ._validate import check_choice, check_float, check_int, check_points, plural, readonly
from .errors import ScanError

__all__ = ["Segmentation", "segment", "WALL_ANGLE_DEG", "JUMP_FACTOR", "MIN_PIECE_POINTS",
           "MIN_STEP_REL"]

#: Triangles steeper than this (degrees between the normal and the view axis) are cut.
WALL_ANGLE_DEG = 80.0
#: Triangles whose longest edge exceeds this multiple of the median edge length are cut.
JUMP_FACTOR = 5.0
#: Pieces with fewer points are flagged small.
MIN_PIECE_POINTS = 30
#: Default minimum step: depth steps below this fraction of the robust depth extent are
#: never cut (the default fit's E).
MIN_STEP_REL = 0.01
#: Where depths come in levels, steps below this many depth quanta are never cut.
_QUANTA = 2.5
#: Depths come in levels (quanta) when there are at least this many distinct values and
#: at most one per two points.
_MIN_LEVELS = 64
#: The depth quantum at a level: the median gap over this many neighbouring levels.
_QUANTUM_WINDOW = 9
#: Depths come in levels only when at least this share of the gaps between neighbouring
#: levels lie within half a quantum of it (the TUM Kinect frames: 99.4 % and 99.7 %; a
#: 100 x 100 grid of sin(3 pi x) cos(3 pi y), whose values repeat by symmetry, 3.1 points
#: a level: 64 %, and it took the camera's rules: its tails gave back 13 % of E-bar).
_REGULAR_GAPS = 0.8
#: Jump pairs are looked for within this many view-plane sampling spacings (rule 4).
_PAIR_SPACINGS = 2.0
#: Rule 4: points sampled for the view-plane spacing (its median, to 1 % on any scan here).
_SPACING_SAMPLES = 8192
#: Jump pairs closer than this many pair radii belong to one cliff (rule 4).
_CLIFF_GAP = 3.0
#: A cliff of fewer jump pairs does not split a piece (rule 4).
_MIN_CLIFF_PAIRS = 15
#: A piece is split and its parts checked again at most this many times (rule 4).
_SPLIT_ROUNDS = 8
#: Rule 1b: a triangle the wall and jump rules would cut stays when a quadratic height
#: field through the points around it misses them by less than this share of the
#: triangle's depth extent (RMS). Measured with ``scripts/bench_segment.py`` and on
#: synthetic grids (100 x 100 on the unit square, z = sin(k pi x) cos(k pi y), k = 2, 3,
#: 4, noise 0 and 0.005): on the grids that share is 0.002-0.010 without noise and
#: 0.03-0.08 (10th-90th percentile) with it, where the slopes of 6-13 cut 2,566-16,705
#: triangles into up to 180 pieces and raised the fit's E-bar by up to 2x; on the five
#: dev scans' cut triangles it is 0.05-0.16 on the face map and 0.09-0.50 on the bunnies.
#: With 0.1 every grid is one piece and the dev scans keep their pieces (on triangles
#: alone bun045 17 -> 16, bun090 36 -> 33; E-bar and K within 3 %). Rule 4's jump pairs
#: take the same test: on a grid of eight Gaussian bumps (sigma 7 spacings, height 1:
#: slopes up to 8.6) every flank held jump pairs, and the splits cut it into 36 pieces at
#: 2.2x the single network's E-bar; with both, the face map has 17 pieces (was 20),
#: bun045 14, bun090 33 (``scripts/bench_segment.py``).
SMOOTH_FIT = 0.1
#: ... or under this many times the scan's noise scale (:meth:`_Smooth.noise`).
NOISE_SMOOTH = 3.0
#: Points sampled for the noise scale.
_NOISE_SAMPLE = 2048
#: Rule 1b: points around a triangle that the quadratic is fitted to.
_SMOOTH_NEIGHBOURS = 16


@dataclass(frozen=True, eq=False)
class Segmentation:
    """A scan cut into pieces that are each a smooth height field in the view frame.

    Parameters
    ----------
    labels : (N,) int64 array
        Piece index of each point, in ``[0, n_pieces)``; pieces are numbered by their
        smallest point index.
    sizes : (n_pieces,) int64 array
        Points per piece.
    small : (n_pieces,) bool array
        Pieces with fewer than ``min_piece_points`` points.
    view_axis : str
        The view axis the scan was seen along.
    wall_angle_deg, jump_factor : float
        The cut rules used (see :func:`segment`).
    min_piece_points : int
        The small-piece threshold used.
    source : str
        ``"faces"`` (the scan's triangles) or ``"cloud"`` (a triangulation in the view
        plane of a bare point cloud).
    n_triangles, n_cut : int
        Triangles considered and triangles cut.
    n_split : int
        Pieces split because they wrapped around the end of a cliff (rule 4).
    min_step : float
        The minimum step used (scan units; depth quanta may raise it locally).
    """

    labels: np.ndarray
    sizes: np.ndarray
    small: np.ndarray
    view_axis: str
    wall_angle_deg: float
    jump_factor: float
    min_piece_points: int
    source: str
    n_triangles: int
    n_cut: int
    n_split: int = 0
    min_step: float = 0.0

    def __post_init__(self) -> None:
        """Freeze the arrays and check that they agree."""
        labels = readonly(np.array(self.labels, dtype=np.int64))
        sizes = readonly(np.array(self.sizes, dtype=np.int64))
        small = readonly(np.array(self.small, dtype=bool))
        if labels.ndim != 1 or sizes.shape != small.shape or sizes.sum() != len(labels):
            raise ScanError("labels, sizes and small of a Segmentation disagree")
        object.__setattr__(self, "labels", labels)
        object.__setattr__(self, "sizes", sizes)
        object.__setattr__(self, "small", small)

    @property
    def n_pieces(self) -> int:
        """Number of pieces."""
        return int(len(self.sizes))

    @property
    def n_points(self) -> int:
        """Number of points N."""
        return int(len(self.labels))

    def indices(self, piece: int) -> np.ndarray:
        """Point indices of one piece, ascending."""
        piece = check_int(piece, "piece", 0, self.n_pieces - 1)
        return np.flatnonzero(self.labels == piece)

    def to_dict(self) -> dict[str, Any]:
        """Return a JSON-ready summary: counts, sizes and the parameters used."""
        n = max(self.n_points, 1)
        return {
            "n_points": self.n_points,
            "n_pieces": self.n_pieces,
            "sizes": self.sizes.tolist(),
            "largest_fraction": float(self.sizes.max() / n) if self.n_pieces else 0.0,
            "n_small": int(self.small.sum()),
            "points_in_small": int(self.sizes[self.small].sum()),
            "source": self.source,
            "n_triangles": self.n_triangles,
            "n_cut": self.n_cut,
            "n_split": self.n_split,
            "min_step": self.min_step,
            "view_axis": self.view_axis,
            "wall_angle_deg": self.wall_angle_deg,
            "jump_factor": self.jump_factor,
            "min_piece_points": self.min_piece_points,
        }

    def __repr__(self) -> str:
        return (f"Segmentation({plural(self.n_points, 'point')} in "
                f"{plural(self.n_pieces, 'piece')}, {int(self.small.sum())} small)")


class DepthQuanta:
    """The gap between a depth camera's neighbouring depth levels, at any depth.

    Depths come in levels (a disparity camera's quanta, growing with the square of the
    depth) when there are at least ``_MIN_LEVELS`` distinct values, at most one per
    two points, and their gaps are even (``_REGULAR_GAPS``); the quantum at a level is
    the median gap over ``_QUANTUM_WINDOW`` neighbouring levels. :func:`depth_quanta`
    returns None for depths that do not come in levels (a Stanford range scan, an
    elevation grid in floats).
    """

    def __init__(self, levels: np.ndarray, gaps: np.ndarray) -> None:
        self.levels, self.gaps = levels, gaps

    def at(self, depth: np.ndarray) -> np.ndarray:
        """Return the quantum at each of ``depth`` (the gap above the level at or above it)."""
        i = np.minimum(np.searchsorted(self.levels, depth), len(self.gaps) - 1)
        return self.gaps[i]


def depth_quanta(depth: np.ndarray) -> DepthQuanta | None:
    """Return the depth quanta of ``depth`` (:class:`DepthQuanta`), None without levels.

    Examples
    --------
    >>> q = depth_quanta(np.repeat(np.arange(100) * 0.5, 3))
    >>> float(q.at(np.array([10.0]))[0])
    0.5
    >>> depth_quanta(np.linspace(0.0, 1.0, 300)) is None
    True
    """
    levels = np.unique(depth)
    # a few levels are the scene's own (a cliff between two flat terraces), not quanta
    if len(levels) < _MIN_LEVELS or len(levels) > len(depth) // 2:
        return None
    from scipy.ndimage import median_filter

    gaps = np.diff(levels)
    quantum = median_filter(gaps, size=_QUANTUM_WINDOW, mode="nearest")
    # a camera's levels are evenly spaced where they are close: most gaps are the local
    # quantum; values that merely repeat (a symmetric synthetic surface on a grid) are not
    if np.mean((gaps > 0.5 * quantum) & (gaps < 1.5 * quantum)) < _REGULAR_GAPS:
        return None
    return DepthQuanta(levels, quantum)


class _Steps:
    """The minimum depth step that may be cut, at any depth (see the module text)."""

    def __init__(self, depth: np.ndarray, min_step: float | None) -> None:
        self.quanta: DepthQuanta | None = None
        if min_step is not None:  # the caller's step, exactly
            self.floor = float(min_step)
            return
        lo, hi = np.percentile(depth, [1.0, 99.0]) if len(depth) else (0.0, 0.0)
        self.floor = MIN_STEP_REL * float(hi - lo)
        self.quanta = depth_quanta(depth)

    def at(self, depth: np.ndarray) -> np.ndarray | float:
        """Return the minimum step for a step starting at ``depth`` (its lower end)."""
        if self.quanta is None:
            return self.floor
        return np.maximum(self.floor, _QUANTA * self.quanta.at(depth))

    def keep(self, za: np.ndarray, zb: np.ndarray) -> np.ndarray:
        """Whether each step from ``za`` to ``zb`` is large enough to be cut."""
        return np.abs(za - zb) > self.at(np.minimum(za, zb))


def _cut_triangles(local: np.ndarray, faces: np.ndarray, wall_angle_deg: float,
                   jump_factor: float, steps: _Steps | None = None,
                   smooth: _Smooth | None = None) -> tuple[np.ndarray, float]:
    """Return the cut triangles, (F,) bool, and the median edge length.

    A triangle is cut when it is seen nearly edge-on or too long, and its depth extent
    is a step (``steps``), or when it has no area.
    """
    from ._segment_kernels import triangle_shapes

    length, area2, nz = triangle_shapes(np.ascontiguousarray(local, np.float64),
                                        np.ascontiguousarray(faces, np.int64))
    with np.errstate(invalid="ignore", divide="ignore"):
        facing = np.abs(nz) / area2
    median = float(np.median(length)) if length.size else 0.0
    cut = ~(facing >= math.cos(math.radians(wall_angle_deg)))
    if median > 0:
        # the longest edge (numpy's max over a short axis is 10x slower than this)
        longest = np.maximum(np.maximum(length[:, 0], length[:, 1]), length[:, 2])
        cut |= longest > jump_factor * median
    if steps is not None and cut.any():
        at = np.flatnonzero(cut)
        z = local[faces[at], 2]
        cut[at] = steps.keep(z.min(axis=1), z.max(axis=1))
    cut &= area2 > 0
    if cut.any():  # rule 1b: a steep triangle on a smooth surface is no wall
        at = np.flatnonzero(cut)
        cut[at] = ~(smooth or _Smooth(local)).across(faces[at])
    return cut | ~(area2 > 0), median


class _Smooth:
    """Rule 1b's test on one scan: its points binned once for every fit, and its floor.

    :meth:`across`: whether a quadratic height field fits the points around each
    triangle. The :data:`_SMOOTH_NEIGHBOURS` points nearest to the triangle's centroid in
    the view plane get a least-squares quadratic ``z(x, y)``; the triangle lies on a
    smooth surface when that fit's RMS residual is under :data:`SMOOTH_FIT` times the
    triangle's own depth extent, or under ``floor``. Across a cliff the neighbours hold
    both levels and a quadratic misses them by a good part of the step; on a steep but
    smooth slope it misses by the noise. Rows may be pairs of points too (rule 4's jump
    pairs). Compiled (``_segment_kernels.smooth_fits``): numpy's batched 6 x 6 solves and
    a k-d tree took 31 ms of the face map's cut as a cloud, holding the interpreter's lock
    while the frame's measures ran beside it.

    With ``noisy``, ``floor`` is ``NOISE_SMOOTH`` times :meth:`noise`, else 0.
    """

    def __init__(self, local: np.ndarray, noisy: bool = False) -> None:
        self.xy = np.ascontiguousarray(local[:, :2])
        self.z = local[:, 2]
        self.k = min(_SMOOTH_NEIGHBOURS, len(local))  # under 6 points: none smooth
        self._grid: tuple | None = None
        self.floor = NOISE_SMOOTH * self.noise() if noisy else 0.0

    @property
    def grid(self) -> tuple:
        """The points binned for the nearest-neighbour searches (made on first use)."""
        if self._grid is None:
            from ._grid_knn import point_grid

            self._grid = point_grid(self.xy)
        return self._grid

    def across(self, tris: np.ndarray) -> np.ndarray:
        """(M,) bool: whether each row (2 or 3 point indices) lies on a smooth surface."""
        from ._segment_kernels import smooth_fits

        if len(tris) == 0:  # (no grid to build)
            return np.zeros(0, dtype=bool)
        return smooth_fits(self.xy, self.z, tris, self.k, SMOOTH_FIT, self.grid, self.floor)

    def noise(self) -> float:
        """Return the scan's noise scale: the median RMS of the fits at sampled points.

        The quadratic through a point's neighbours misses them by the noise where the
        surface is smooth, most of any scan: so a triangle whose own fit misses by no more
        than a few times that is on a smooth, noisy surface (0 for fewer than 6 points).
        """
        from ._segment_kernels import smooth_fits

        n = len(self.xy)
        if self.k < 6:
            return 0.0
        at = np.unique(np.linspace(0, n - 1, min(n, _NOISE_SAMPLE)).astype(np.int64))
        rms = np.empty(len(at))
        smooth_fits(self.xy, self.z, np.repeat(at[:, None], 3, axis=1), self.k, SMOOTH_FIT,
                    self.grid, rms=rms)
        rms = rms[np.isfinite(rms)]
        return float(np.median(rms)) if len(rms) else 0.0


def _components(n: int, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Component label of each vertex over the triangles' edges, and which are used."""
    from ._segment_kernels import components

    return components(n, np.ascontiguousarray(faces, np.int64))


def _stable(labels: np.ndarray) -> np.ndarray:
    """Renumber labels 0.. in the order of each label's smallest point index."""
    uniq, first, inverse = np.unique(labels, return_index=True, return_inverse=True)
    rank = np.empty(len(uniq), dtype=np.int64)
    rank[np.argsort(first, kind="stable")] = np.arange(len(uniq))
    return rank[inverse.ravel()]


def segment(scan: Any, *, view_axis: str = "z", wall_angle_deg: float = WALL_ANGLE_DEG,
            jump_factor: float = JUMP_FACTOR, min_piece_points: int = MIN_PIECE_POINTS,
            min_step: float | None = None) -> Segmentation:
    """Cut a scan into pieces that are each a smooth height field along ``view_axis``.

    Parameters
    ----------
    scan : Scan, Mesh or (N, 3) array_like
        The scan: its triangles are used when it has some, else (a bare point cloud)
        a tight Delaunay triangulation of its points in the view plane (points on a
        regular lattice in the view plane: the lattice's cells).
    view_axis : {"z", "x", "y", "pca"}
        The depth direction, as in :func:`~asrbf_mesh.to_height_field`.
    wall_angle_deg : float
        Triangles whose normal makes more than this angle with the view axis (seen
        nearly edge-on) are cut; in (0, 90]. 90 cuts none by angle.
    jump_factor : float
        Triangles whose longest edge exceeds this multiple of the median edge length are
        cut (depth jumps, bridged gaps); > 1.
    min_piece_points : int
        Pieces with fewer points are flagged ``small``; >= 1.
    min_step : float, optional
        Depth steps up to this size (scan units) are never cut, walls and jumps alike.
        Default: 1 % of the scan's depth extent (between its 1st and 99th percentiles),
        and where the depths come in levels (a depth camera's quanta) at least 2.5
        levels. A number is used as it is: 0 cuts every step.

    Returns
    -------
    Segmentation
        Every point has a piece.

    Raises
    ------
    ConfigError
        For a bad parameter; the message names it.
    ScanError
        For points that are not a non-empty (N, 3) array of finite numbers.

    Examples
    --------
    >>> x, y = np.meshgrid(np.arange(20.0), np.arange(10.0))
    >>> z = np.where(x < 10, 0.0, 10.0)  # a cliff of ten spacings at x = 10
    >>> seg = segment(np.c_[x.ravel(), y.ravel(), z.ravel()])
    >>> seg.n_pieces, seg.sizes.tolist()
    (2, [100, 100])
    """
    view_axis = check_choice(view_axis, "view_axis", _config.VIEW_AXES)
    wall_angle_deg = check_float(wall_angle_deg, "wall_angle_deg", low=0.0, high=90.0,
                                 low_open=True)
    jump_factor = check_float(jump_factor, "jump_factor", low=1.0, low_open=True)
    min_piece_points = check_int(min_piece_points, "min_piece_points", 1)
    if min_step is not None:
        min_step = check_float(min_step, "min_step", low=0.0)
    pts = check_points(scan, "points", min_points=1)
    faces = getattr(scan, "faces", None)
    faces = None if faces is None else np.asarray(faces, dtype=np.int64).reshape(-1, 3)

    from ._frame import _rotation

    local = pts @ _rotation(pts, view_axis)
    source = "faces"
    if faces is None or len(faces) == 0:
        source = "cloud"
        faces = _cloud_faces(local)
    steps = _Steps(local[:, 2], min_step)
    # a noisy smooth surface is no wall (rule 1b); not where depths come in levels (the
    # steps know a depth camera's), nor under a step the caller set
    smooth = _Smooth(local, noisy=min_step is None and steps.quanta is None)
    cut, median = _cut_triangles(local, faces, wall_angle_deg, jump_factor, steps, smooth)
    labels, anchor = _label(local, faces[~cut])
    labels, n_split = _split_wrapped(local, faces, labels, anchor, wall_angle_deg,
                                     jump_factor * median, steps, smooth)
    sizes = np.bincount(labels)
    return Segmentation(labels, sizes, sizes < min_piece_points, view_axis, wall_angle_deg,
                        jump_factor, min_piece_points, source, int(len(faces)),
                        int(cut.sum()), n_split, steps.floor)


def _cloud_faces(local: np.ndarray) -> np.ndarray:
    """Triangulate a bare cloud tightly in the view plane (no triangles if it spans no area).

    Points on a regular lattice (a range grid saved as points) by the lattice
    (:func:`~asrbf_mesh._footprint.lattice_faces`), others by a Delaunay triangulation
    without long edges.
    """
    from ._footprint import lattice_faces, point_cloud_faces
    from ._frame import sampling_spacing

    xy = local[:, :2]
    if len(xy) < 3:
        return np.zeros((0, 3), dtype=np.int64)
    faces = lattice_faces(local)
    if faces is not None:
        return faces
    try:
        spacing = sampling_spacing(xy)
    except ScanError:  # all points share one (x, y)
        return np.zeros((0, 3), dtype=np.int64)
    return point_cloud_faces(xy, spacing)


def _label(local: np.ndarray, kept: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Piece of every point: components of the kept triangles, the rest to the nearest.

    Also returns each point's anchor: itself when a kept triangle uses it, else the
    nearest point that one uses (whose piece it joined).
    """
    n = len(local)
    anchor = np.arange(n)
    if len(kept) == 0:  # nothing is a surface: the whole scan is one piece
        return np.zeros(n, dtype=np.int64), anchor
    comp, used = _components(n, kept)
    if not used.all():
        from ._grid_knn import nearest_3d

        anchors = np.flatnonzero(used)
        anchor[~used] = anchors[nearest_3d(local[anchors], local[~used])]
        comp[~used] = comp[anchor[~used]]
    return _stable(comp), anchor


def _split_wrapped(local: np.ndarray, faces: np.ndarray, labels: np.ndarray,
                   anchor: np.ndarray, wall_angle_deg: float, jump: float,
                   steps: _Steps | None = None, smooth: _Smooth | None = None
                   ) -> tuple[np.ndarray, int]:
    """Rule 4: split the pieces that wrap around the end of a cliff; (labels, splits).

    The searches run along every triangle's edges within a piece, the cut ones too: the
    points of a cliff's wall belong to the piece of their nearest kept point, and the
    bisector between the cliff's upper and lower sides runs through its wall.
    """
    from ._frame import sampling_spacing
    from ._segment_kernels import SeedGraph, edge_graph, edge_lengths, jump_pairs

    if len(faces) == 0 or jump <= 0 or len(local) < 4:
        return labels, 0
    try:
        radius = _PAIR_SPACINGS * sampling_spacing(local[:, :2], max_samples=_SPACING_SAMPLES)
    except ScanError:  # all points share one (x, y)
        return labels, 0
    slope = math.tan(math.radians(min(wall_angle_deg, 89.9)))
    jumps = jump_pairs(local, radius, slope, jump)  # close in the view plane, far in depth
    if steps is not None and len(jumps):
        jumps = jumps[steps.keep(local[jumps[:, 0], 2], local[jumps[:, 1], 2])]
    if len(jumps) >= _MIN_CLIFF_PAIRS:  # a steep slope of a smooth surface is no cliff
        jumps = jumps[~(smooth or _Smooth(local)).across(jumps)]
    if len(jumps) < _MIN_CLIFF_PAIRS:
        return labels, 0
    n = len(local)
    indptr, indices = edge_graph(n, np.ascontiguousarray(faces, np.int64))
    graph = SeedGraph(indptr, indices, edge_lengths(local, indptr, indices))
    labels = labels.copy()
    n_split = 0

    def cliff_pairs(pieces: list[int]) -> dict[int, np.ndarray]:
        """Each piece's jump pairs inside it, in index order, where it has enough."""
        first = labels[jumps[:, 0]]
        within = np.flatnonzero(first == labels[jumps[:, 1]])
        return {p: jumps[k] for p, k in _members(first[within], pieces, within).items()
                if len(k) >= _MIN_CLIFF_PAIRS}

    def sides(piece: int, inner: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        own = np.flatnonzero(labels == piece)
        return own, _wrapped_side(local, own, graph, labels, anchor,
                                  _largest_cliff(local[:, :2], inner, radius))

    from numba import get_num_threads

    # a piece's search stays in it and its parts are searched again once it is split
    # (at most _SPLIT_ROUNDS deep): each piece's chain runs on its own, two searches at
    # a time where numba may use two threads (a batch worker pinned to one thread
    # searches one piece after another), the largest first. Searched in rounds (every
    # piece of a round done before the next), a Kinect frame's searches waited for each
    # round's largest piece: 0.17 s for 0.18 s of searching. The parts are the same
    # whatever the order; only the labels' numbering would differ, and _stable renumbers
    with ThreadPoolExecutor(max_workers=max(1, min(2, get_num_threads()))) as pool:
        running: dict = {}

        def submit(pieces: list[int], depth: int) -> None:
            pairs = cliff_pairs(pieces)
            for p in sorted(pairs, key=lambda p: -len(pairs[p])):
                running[pool.submit(sides, p, pairs[p])] = (p, depth)

        submit([int(p) for p in np.unique(labels[jumps[:, 0]])], 0)
        while running:
            done, _ = wait(running, return_when=FIRST_COMPLETED)
            for fut in sorted(done, key=lambda f: running[f]):
                piece, depth = running.pop(fut)
                own, side = fut.result()
                if side is None:
                    continue
                new = int(labels.max()) + 1
                labels[own[side]] = new
                n_split += 1
                if depth + 1 < _SPLIT_ROUNDS:
                    submit([piece, new], depth + 1)
    return _stable(labels), n_split


def _members(labels: np.ndarray, wanted: list, index: np.ndarray) -> dict[int, np.ndarray]:
    """For each label in ``wanted``, the entries of ``index`` whose label it is, in order."""
    order = np.argsort(labels, kind="stable")
    ranked, at = labels[order], index[order]
    lo = np.searchsorted(ranked, wanted, side="left")
    hi = np.searchsorted(ranked, wanted, side="right")
    return {int(p): at[a:b] for p, a, b in zip(wanted, lo, hi, strict=True)}


def _wrapped_side(local: np.ndarray, own: np.ndarray, graph, labels: np.ndarray,
                  anchor: np.ndarray, jumps: np.ndarray) -> np.ndarray | None:
    """Boolean over ``own``: the lower side of its longest cliff, or None.

    ``jumps`` are the jump pairs (point indices) of the piece's longest cliff
    (:func:`_largest_cliff`), ``graph`` the triangles' edges (a
    :class:`~asrbf_mesh._segment_kernels.SeedGraph`, 3D lengths), ``labels``
    the pieces so far (a search stays in its piece) and ``anchor`` each point's nearest
    point on a kept triangle (see :func:`_label`). None when the cliff has fewer than
    ``_MIN_CLIFF_PAIRS`` pairs or the bisector would not split the piece.
    """
    if len(jumps) < _MIN_CLIFF_PAIRS:
        return None
    upper_first = local[jumps[:, 0], 2] > local[jumps[:, 1], 2]
    up = np.unique(np.where(upper_first, jumps[:, 0], jumps[:, 1]))
    lo = np.unique(np.where(upper_first, jumps[:, 1], jumps[:, 0]))
    both = np.intersect1d(up, lo)
    up, lo = np.setdiff1d(up, both), np.setdiff1d(lo, both)
    if len(up) == 0 or len(lo) == 0:
        return None
    # each point takes the side of its nearest jump point along the triangles' edges; a
    # point in no triangle, the side of its anchor
    source = graph.nearest(labels, np.concatenate([up, lo]))
    source = np.where(source[own] >= 0, source[own], source[anchor[own]])
    if not (source >= 0).any():
        return None
    side = np.isin(source, lo)
    if side.all() or not side.any():
        return None
    return side


def _largest_cliff(xy: np.ndarray, jumps: np.ndarray, radius: float) -> np.ndarray:
    """Return the jump pairs of the longest cliff (pairs chained within ``_CLIFF_GAP`` radii).

    Of equally long cliffs, the one with the first pair.
    """
    from ._segment_kernels import close_components

    cliff = close_components(0.5 * (xy[jumps[:, 0]] + xy[jumps[:, 1]]), _CLIFF_GAP * radius)
    return jumps[cliff == np.argmax(np.bincount(cliff))]
