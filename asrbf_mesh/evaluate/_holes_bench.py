"""Ground-truth hole benchmark: punch disks, fill them by several methods, measure.

Interior disks are removed from a scan (:func:`~asrbf_mesh.evaluate.punch_holes`) and
their points kept as the truth; each method fills the holed scan, and the distance of
every truth point to the filled surface is reported in % of the scan's bounding-box
diagonal. Methods: ours (:func:`~asrbf_mesh._holes.fill_holes`, fit included), a
thin-plate-spline height field on our fill triangulation (scipy ``RBFInterpolator``,
64 neighbours), MeshLab's Close Holes and screened Poisson (normals from the points).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.interpolate import RBFInterpolator

from .._holes import FillResult, fill_holes
from .._igl import point_mesh_distance
from .._mesh import Mesh, Scan
from . import _meshlab
from ._punch import PunchedScan, punch_holes

__all__ = ["HOLE_METHODS", "HoleRow", "hole_benchmark"]

HOLE_METHODS = ("ours (ASRBF)", "TPS height field (same triangulation)", "MeshLab Close Holes",
                "screened Poisson (depth 9)")


@dataclass(frozen=True)
class HoleRow:
    """One method's fill of the punched holes, measured against the truth."""

    method: str
    truth_points: int
    mean_pct: float
    rms_pct: float
    max_pct: float
    seconds: float
    closed: str = ""


def tps_fill(holed: Scan, ours: FillResult) -> Mesh:
    """Our fill triangulation with depths from a thin-plate spline of the holed scan."""
    m = ours.mesh
    n = holed.n_points
    tps = RBFInterpolator(holed.points[:, :2], holed.points[:, 2],
                          kernel="thin_plate_spline", neighbors=64)
    v = m.vertices.copy()
    if len(v) > n:
        v[n:, 2] = tps(v[n:, :2])
    return Mesh(v, m.faces)


def closed_holes(res: FillResult, punched: PunchedScan) -> str:
    """Punched disks whose hole was found and filled (a filled hole centred in the disk)."""
    count = folded = 0
    for c, r in zip(punched.centres, punched.radii, strict=True):
        hit = [h for h in res.holes
               if h.filled and np.linalg.norm(np.array(h.centre[:2]) - c) < r]
        count += bool(hit)
        folded += any(h.layers > 1 for h in hit)
    out = f"{count}/{len(punched.radii)}"
    return out + (f" ({folded} at a fold, filled per layer)" if folded else "")


def hole_benchmark(scan: Scan, *, count: int = 5, seed: int = 0,
                   on_step: Callable[[str], None] | None = None) -> list[HoleRow]:
    """Punch ``count`` disks into ``scan``, fill them by every method, measure each fill.

    Parameters
    ----------
    scan : Scan
        A triangulated range scan (a range grid or mesh).
    count : int
        Disks to punch (radius 3-6 % of the xy extent, interior, seeded).
    seed : int
        Seed of the disks and of our fit.
    on_step : callable, optional
        Called with each method's name before it runs (progress reporting).

    Returns
    -------
    list of HoleRow
        One row per method of :data:`HOLE_METHODS`, in that order.
    """
    p = punch_holes(scan, count=count, seed=seed)
    diag = scan.bbox_diagonal
    step = on_step or (lambda name: None)
    fills: list[tuple[str, Mesh, float, str]] = []
    step(HOLE_METHODS[0])
    t0 = time.perf_counter()
    ours = fill_holes(p.scan, seed=seed, progress=False)
    fills.append((HOLE_METHODS[0], ours.mesh, time.perf_counter() - t0, closed_holes(ours, p)))
    step(HOLE_METHODS[1])
    t0 = time.perf_counter()  # the spline only: the triangulation is ours
    tps = tps_fill(p.scan, ours)
    fills.append((HOLE_METHODS[1], tps, time.perf_counter() - t0, ""))
    step(HOLE_METHODS[2])
    t0 = time.perf_counter()
    ch = _meshlab.close_holes(Mesh(p.scan.points, p.scan.faces), max_hole_edges=100_000)
    fills.append((HOLE_METHODS[2], ch, time.perf_counter() - t0, ""))
    step(HOLE_METHODS[3])
    t0 = time.perf_counter()
    sp = _meshlab.screened_poisson(p.scan.points, depth=9)
    fills.append((HOLE_METHODS[3], sp, time.perf_counter() - t0, ""))
    rows = []
    for method, mesh, secs, closed in fills:
        d = 100.0 * point_mesh_distance(p.truth, mesh) / diag
        rows.append(HoleRow(method, len(p.truth), float(d.mean()), float(np.sqrt(np.mean(d**2))),
                            float(d.max()), secs, closed))
    return rows
