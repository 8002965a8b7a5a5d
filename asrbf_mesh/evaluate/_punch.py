"""Punched holes with ground truth: interior disks removed from a scan, kept as the truth.

The hole benchmark (:func:`~asrbf_mesh.evaluate.hole_benchmark`) fills them by several
methods and measures each fill against the removed points.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._footprint import Footprint
from .._frame import sampling_spacing
from .._mesh import Scan
from .._validate import check_float, check_int, check_seed
from ..errors import ConfigError, ScanError

__all__ = ["PunchedScan", "punch_holes"]


@dataclass(frozen=True, eq=False)
class PunchedScan:
    """A scan with disks removed, and the removed points as ground truth."""

    scan: Scan
    truth: np.ndarray
    centres: np.ndarray
    radii: np.ndarray


def punch_holes(scan: Scan, *, count: int = 5, radius_rel: tuple[float, float] = (0.03, 0.06),
                seed: int = 0, max_tries: int = 5000) -> PunchedScan:
    """Remove ``count`` interior disks (in world xy) from a scan, keeping them as truth.

    Radii are drawn in ``radius_rel`` times the larger side of the xy extent; a disk is
    accepted only if it lies inside the scan's footprint with a margin of half a
    radius (no border, no existing hole nearby) and away from the other disks.

    Raises
    ------
    ScanError
        If ``scan`` is not a Scan, or ``count`` such disks cannot be placed.
    ConfigError
        If ``count``, ``seed`` or ``max_tries`` is not an integer in range, or
        ``radius_rel`` not two numbers ``0 < low <= high``.
    """
    if not isinstance(scan, Scan):
        raise ScanError(f"scan must be a Scan, got {type(scan).__name__}")
    count = check_int(count, "count", 1)
    seed = check_seed(seed)
    max_tries = check_int(max_tries, "max_tries", 1)
    try:
        lo, hi = radius_rel
    except (TypeError, ValueError):
        raise ConfigError(f"radius_rel must be two numbers (low, high), "
                          f"got {radius_rel!r}") from None
    lo = check_float(lo, "radius_rel[0]", low=0.0, low_open=True)
    check_float(hi, "radius_rel[1]", low=lo)
    rng = np.random.default_rng(seed)
    xy = np.ascontiguousarray(scan.points[:, :2])
    spacing = sampling_spacing(xy)
    fp = Footprint.of_points(xy, scan.faces, spacing)
    extent = float((xy.max(0) - xy.min(0)).max())
    centres: list[np.ndarray] = []
    radii: list[float] = []
    ring = np.linspace(0, 2 * np.pi, 48, endpoint=False)
    for _ in range(max_tries):
        if len(centres) == count:
            break
        r = rng.uniform(*radius_rel) * extent
        c = xy[rng.integers(len(xy))]
        probe = np.concatenate([c + np.column_stack([np.cos(ring), np.sin(ring)]) * rr
                                for rr in (0.25 * r, 0.5 * r, r, 1.5 * r)])
        lab = fp.label_at(np.vstack([c[None], probe]))
        if np.any(lab != 0):  # every probe on the scan's own triangles
            continue
        pairs = zip(centres, radii, strict=True)
        if any(np.linalg.norm(c - c2) < 1.6 * (r + r2) for c2, r2 in pairs):
            continue
        centres.append(c)
        radii.append(r)
    if len(centres) < count:
        raise ScanError(f"{scan.source or 'scan'}: could place only {len(centres)} of "
                        f"{count} interior disks")
    cen = np.array(centres)
    rad = np.array(radii)
    d = np.linalg.norm(xy[:, None, :] - cen[None], axis=2)
    removed = (d <= rad[None]).any(axis=1)
    points, faces = remove_points(scan.points, scan.faces, removed)
    holed = Scan(points, faces, source=scan.source, grid_shape=None)
    return PunchedScan(holed, scan.points[removed].copy(), cen, rad)


def remove_points(points: np.ndarray, faces: np.ndarray | None, drop: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray | None]:
    """Remove the points ``drop`` (bool mask) and the faces that touch them.

    Returns the points kept and the faces left, renumbered onto them (None stays None).
    """
    keep = np.flatnonzero(~drop)
    remap = np.full(len(points), -1, dtype=np.int64)
    remap[keep] = np.arange(len(keep))
    if faces is None:
        return points[keep], None
    f = remap[faces]
    return points[keep], f[(f >= 0).all(axis=1)]
