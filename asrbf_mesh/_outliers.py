"""Isolated points: stray returns far from every other point of a scan.

One stray point (a range sensor's multipath return, a corrupt line in an XYZ file) used to
ruin a fit silently: the frame normalizes each axis by the scan's extent, so a point at
z = 10⁶ squeezes the real surface into a sliver of the unit cube (a 100 × 100 surface of
amplitude ±1 fitted with RMS 1,651–4,545 over seeds 0–2 instead of 0.005–0.006).
:func:`isolated_points` finds such points so that :func:`~asrbf_mesh.fit` can leave them
out of the frame and the surface, and say so.

The rule is geometric and scale-free. Each coordinate is first divided by its *robust*
extent, the range between its 1st and 99th percentiles (so that the strays do not inflate
it; an axis with no such range takes the largest of the others), as the fit's own frame
normalizes each axis. Then a point is isolated when its ``k``-th nearest neighbour
(``k = 3``: a pair or a triple of strays is isolated too) lies farther than
``distance_rel`` (15 %) of the diagonal of that robust box, and farther than
``DENSITY_FACTOR`` (20) times the median of that distance over the scan (so that a sparse
scan, a hundred points scattered over the square, keeps its corners).

On the scans shipped and benchmarked here (the face map, the four Stanford bunny scans,
the bunny crop) the farthest real point reaches at most 0.46 of the threshold (bun090, in
3D; 0.17 in the view plane), so the rule flags no point of a real scan and a clean scan
fits exactly as before.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ._validate import check_float, check_int, plural

__all__ = ["OutlierWarning", "isolated_points", "describe_isolated",
           "NEIGHBOURS", "DISTANCE_REL", "DENSITY_FACTOR"]

#: The neighbour whose distance decides (a group of up to this many strays is isolated).
NEIGHBOURS = 3
#: Isolated: the k-th neighbour farther than this fraction of the robust diagonal ...
DISTANCE_REL = 0.15
#: ... and farther than this many times the scan's median k-th neighbour distance.
DENSITY_FACTOR = 20.0


class OutlierWarning(UserWarning):
    """Isolated points were left out of a fit (how many, and where)."""


def robust_box(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Lower corner and per-axis extent of the box between the 1st and 99th percentiles.

    An axis without extent takes the largest extent of the others (all zero: ones).
    """
    lo, hi = np.quantile(points, [0.01, 0.99], axis=0)
    ext = hi - lo
    top = float(ext.max()) if ext.size else 0.0
    ext = np.where(ext > 0, ext, top if top > 0 else 1.0)
    return lo, ext


def isolated_points(points: np.ndarray, *, neighbours: int = NEIGHBOURS,
                    distance_rel: float = DISTANCE_REL, workers: int = 1) -> np.ndarray:
    """Return the mask of the isolated points of a scan, (N,) bool.

    Parameters
    ----------
    points : (N, 3) float array
        Finite scan points, world units.
    neighbours : int
        ``k``: a point is judged by the distance to its ``k``-th nearest other point.
    distance_rel : float
        Threshold, a fraction of the robust bounding-box diagonal (see the module notes).
    workers : int
        Threads of the neighbour queries (one: :func:`~asrbf_mesh.fit` runs this beside
        the segmentation; the footprint of fill-holes, alone, takes numba's count).

    Returns
    -------
    (N,) bool array
        True for isolated points. All False for scans of at most ``neighbours + 1``
        points.

    Examples
    --------
    >>> xy = np.stack(np.meshgrid(np.arange(20.0), np.arange(20.0)), -1).reshape(-1, 2)
    >>> pts = np.c_[xy, np.sin(xy[:, 0] / 3)]
    >>> pts[7, 2] = 1e6
    >>> np.flatnonzero(isolated_points(pts)).tolist()
    [7]
    """
    k = check_int(neighbours, "neighbours", 1)
    rel = check_float(distance_rel, "distance_rel", low=0.0, low_open=True)
    p = np.asarray(points, dtype=np.float64)
    n = len(p)
    if n <= k + 1:
        return np.zeros(n, dtype=bool)
    lo, ext = robust_box(p)
    u = (p - lo) / ext  # each axis in units of its robust extent, as the frame does
    diag = float(np.sqrt(u.shape[1]))
    dist, _ = cKDTree(u).query(u, k=k + 1, workers=workers)
    dk = dist[:, -1]
    return dk > max(rel * diag, DENSITY_FACTOR * float(np.median(dk)))


def describe_isolated(points: np.ndarray, mask: np.ndarray, name: str = "") -> str:
    """One line for an :class:`OutlierWarning`: how many, what share, the farthest one."""
    n_out = int(mask.sum())
    inliers = points[~mask]
    centre = np.median(inliers, axis=0) if len(inliers) else np.zeros(3)
    out = points[mask]
    far = out[np.argmax(np.linalg.norm(out - centre, axis=1))]
    where = ", ".join(f"{v:.6g}" for v in far)
    return (f"{name}{plural(n_out, 'isolated point')} ({100.0 * n_out / len(points):.3g} % "
            f"of the scan, far from every other point) left "
            f"out of the frame and the fit; {'the farthest ' if n_out > 1 else ''}at "
            f"({where})")
