"""Hole filling of range scans from a fitted network.

A scan's triangles cover part of the xy plane of its view frame. What they leave
uncovered splits into the *outside* (the region connected to the far margin:
everything beyond the scan's outer border) and *holes* (uncovered regions the
scan surrounds). The border is never filled: holes are told from it by this
footprint, not by loop length.

Each hole selected by size is filled without touching the scan: new vertices
inside the hole at the scan's own spacing, a constrained triangulation in xy
(``triangle``, with no extra vertex on the hole's boundary so the rim edges are
shared exactly), depths from the network's low-frequency substrate (its neurons at
least as wide as the hole), and the scan's residual ``z - f`` around the rim carried
across the hole by a thin-plate spline, so there is no step at the seam and the
slope and curvature of the surroundings continue into the fill.

References
----------
Meng et al. (2013), section 4.1: holes "convincingly restored" by evaluating the
network over them.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.sparse as sp
from scipy.interpolate import RBFInterpolator
from scipy.sparse.linalg import spsolve
from scipy.spatial import cKDTree

from . import _holes_kernels as _hk
from .errors import AsrbfError, ScanError
from .footprint import Footprint, point_cloud_faces, signed_areas
from .frame import sampling_spacing
from .io import Scan
from .mesh import Mesh
from .network import Network

__all__ = ["FillResult", "HoleInfo", "PunchedScan", "fill_holes", "find_holes", "parse_size",
           "punch_holes"]


@dataclass(frozen=True)
class HoleInfo:
    """One hole of a scan and what was done with it.

    Attributes
    ----------
    index : int
        Hole number (largest first).
    size_abs : float
        Diagonal of the hole's bounding box in the view plane, scan units.
    size_pct : float
        The same, in % of the scan's bounding-box diagonal.
    centre : tuple of float
        Centre of the hole's rim, world coordinates.
    rim_vertices : int
        Scan vertices on the hole's rim.
    filled : bool
        Whether it was filled (closed: every rim edge gained a triangle).
    reason : str or None
        Why it was not filled.
    vertices_added, faces_added : int
        What the fill added.
    """

    index: int
    size_abs: float
    size_pct: float
    centre: tuple[float, float, float]
    rim_vertices: int
    filled: bool
    reason: str | None = None
    vertices_added: int = 0
    faces_added: int = 0


@dataclass(frozen=True, eq=False)
class FillResult:
    """Outcome of :func:`fill_holes`.

    Attributes
    ----------
    mesh : Mesh
        The scan's vertices and faces, unchanged and first, then the fill;
        ``vertex_quality`` is 1 on added vertices and 0 on the scan's.
    holes : tuple of HoleInfo
        Every hole found, filled or not.
    border_edges : int
        Boundary edges on the scan's outer border (left open).
    seconds : float
        Wall time, fit included when the network was fitted here.
    network : Network
        The network that gave the depths.
    """

    mesh: Mesh
    holes: tuple[HoleInfo, ...]
    border_edges: int
    seconds: float
    network: Network = field(repr=False)

    @property
    def holes_found(self) -> int:
        """Number of holes (the outer border excluded)."""
        return len(self.holes)

    @property
    def holes_filled(self) -> int:
        """Number of holes filled and closed."""
        return sum(h.filled for h in self.holes)

    @property
    def holes_skipped(self) -> list[dict[str, Any]]:
        """Holes left open, each with its size and the reason."""
        return [{"index": h.index, "size_abs": h.size_abs, "size_pct": h.size_pct,
                 "reason": h.reason} for h in self.holes if not h.filled]

    @property
    def vertices_added(self) -> int:
        """Vertices added inside the holes."""
        return sum(h.vertices_added for h in self.holes)

    @property
    def faces_added(self) -> int:
        """Triangles added."""
        return sum(h.faces_added for h in self.holes)

    def to_dict(self) -> dict[str, Any]:
        """Summary for ``--json``."""
        return {"holes_found": self.holes_found, "holes_filled": self.holes_filled,
                "holes_skipped": self.holes_skipped, "vertices_added": self.vertices_added,
                "faces_added": self.faces_added, "border_edges": self.border_edges,
                "seconds": self.seconds,
                "holes": [h.__dict__ | {"centre": list(h.centre)} for h in self.holes]}


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
        If ``count`` such disks cannot be placed.
    """
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
        raise ScanError(f"could place only {len(centres)} of {count} interior disks")
    cen = np.array(centres)
    rad = np.array(radii)
    d = np.linalg.norm(xy[:, None, :] - cen[None], axis=2)
    removed = (d <= rad[None]).any(axis=1)
    keep = np.flatnonzero(~removed)
    remap = np.full(len(xy), -1, dtype=np.int64)
    remap[keep] = np.arange(len(keep))
    faces = None
    if scan.faces is not None:
        f = remap[scan.faces]
        faces = f[(f >= 0).all(axis=1)]
    holed = Scan(scan.points[keep], faces, source=scan.source, grid_shape=None)
    return PunchedScan(holed, scan.points[removed].copy(), cen, rad)


def parse_size(value: str | float | None, diagonal: float) -> float | None:
    """Parse a length in scan units (``12.5``) or a percentage of the diagonal (``"5%"``).

    Examples
    --------
    >>> parse_size("5%", 200.0)
    10.0
    >>> parse_size(3, 200.0)
    3.0
    """
    if value is None:
        return None
    try:
        if isinstance(value, str) and value.strip().endswith("%"):
            v = float(value.strip()[:-1]) * diagonal / 100.0
        else:
            v = float(value)
    except ValueError:
        raise AsrbfError(f"max hole size must be a length or a percentage like '5%', "
                         f"got {value!r}") from None
    if not (np.isfinite(v) and v > 0):
        raise AsrbfError(f"max hole size must be positive, got {value!r}")
    return v


@dataclass
class _Hole:
    label: int
    edges: np.ndarray  # (E, 2) scan vertex indices, rim edges
    size: float


def _boundary_edges(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Edges used by exactly one face, and that face's third vertex."""
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    third = np.concatenate([faces[:, 2], faces[:, 0], faces[:, 1]])
    key = np.sort(e, axis=1)
    _, inv, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    once = counts[inv.ravel()] == 1
    return e[once], third[once]


def find_holes(xy: np.ndarray, faces: np.ndarray,
               spacing: float) -> tuple[list[_Hole], int, Footprint]:
    """Holes of a triangulated height field and the count of outer-border edges.

    Parameters
    ----------
    xy : (N, 2) array
        Vertex positions in the view plane (physical units).
    faces : (F, 3) int array
        The scan's triangles.
    spacing : float
        Sampling spacing (physical units).

    Returns
    -------
    holes : list of _Hole
        Largest first.
    border_edges : int
    footprint : Footprint
    """
    fp = Footprint.of(xy, faces, spacing)
    cell = fp.cell
    edges, third = _boundary_edges(faces)
    a, b, c = xy[edges[:, 0]], xy[edges[:, 1]], xy[third]
    mid = 0.5 * (a + b)
    d = b - a
    nrm = np.column_stack([d[:, 1], -d[:, 0]])
    nrm /= np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-300)
    flip = np.einsum("ij,ij->i", nrm, c - mid) > 0  # point away from the edge's face
    nrm[flip] *= -1
    lab = np.zeros(len(edges), dtype=np.int64)
    for t in (0.3, 0.7, 1.2, 2.0):
        lab = np.where(lab == 0, fp.label_at(mid + t * cell * nrm), lab)
    is_out = np.isin(lab, list(fp.outside))
    border = int(is_out.sum())
    holes = []
    for k in np.unique(lab[(lab > 0) & ~is_out]):
        e = edges[lab == k]
        if len(e) < 3:
            continue
        v = xy[np.unique(e)]
        holes.append(_Hole(int(k), e, float(np.linalg.norm(v.max(0) - v.min(0)))))
    holes.sort(key=lambda h: -h.size)
    return holes, border, fp


def _harmonic(n_vertices: int, tris: np.ndarray, fixed: np.ndarray,
              values: np.ndarray) -> np.ndarray:
    """Harmonic extension (graph Laplacian) of ``values`` on ``fixed`` vertices."""
    e = np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]])
    e = np.unique(np.sort(e, axis=1), axis=0)
    w = np.ones(len(e))
    A = sp.coo_matrix((np.r_[w, w], (np.r_[e[:, 0], e[:, 1]], np.r_[e[:, 1], e[:, 0]])),
                      shape=(n_vertices, n_vertices)).tocsr()
    deg = np.asarray(A.sum(axis=1)).ravel()
    L = sp.diags(deg) - A
    free = np.ones(n_vertices, bool)
    free[fixed] = False
    out = np.zeros(n_vertices)
    out[fixed] = values
    if free.any():
        Lff = L[free][:, free].tocsc()
        rhs = -L[free][:, fixed] @ values
        out[free] = spsolve(Lff + sp.identity(Lff.shape[0]) * 1e-12, rhs)
    return out


BLENDS = ("thin-plate", "harmonic")
_RING = 6.0  # rim neighbourhood (in sampling spacings) whose residuals the thin plate sees


def _lowpass(net: Network, hole_size: float, factor: float | None) -> Network:
    """Drop the neurons narrower than ``factor`` x the hole size from the network."""
    if factor is None:
        return net
    cut = factor * hole_size / float(np.sqrt(net.frame.scale[0] * net.frame.scale[1]))
    keep = net.widths >= cut
    return Network(net.a0, net.centers[keep], net.widths[keep], net.weights[keep], net.frame,
                   net.config, None, net.info)


def _segments_through(pts: np.ndarray, seg: np.ndarray, points: np.ndarray,
                      spacing: float) -> np.ndarray:
    """Which segments pass (within 1e-6 spacing) through any of ``points``."""
    a, b = pts[seg[:, 0]], pts[seg[:, 1]]
    d = b - a
    L2 = np.maximum(np.einsum("ij,ij->i", d, d), 1e-300)
    hit = np.zeros(len(seg), bool)
    for q in points:
        t = np.clip(np.einsum("ij,ij->i", q - a, d) / L2, 0.0, 1.0)
        dist = np.linalg.norm(a + t[:, None] * d - q, axis=1)
        hit |= dist < 1e-6 * spacing
    return hit


def _fill_one(hole: _Hole, xy: np.ndarray, depth: np.ndarray, net: Network, faces: np.ndarray,
              face_tree: cKDTree, scan_tree: cKDTree, spacing: float, ccw: bool,
              labels_fn, blend_mode: str,
              lowpass: float | None) -> tuple[np.ndarray, np.ndarray, str | None]:
    """Triangulate one hole; returns (new vertex local xyz, triangles, failure reason)."""
    import triangle

    rim = np.unique(hole.edges)
    local_id = {int(v): i for i, v in enumerate(rim)}
    rim_xy = xy[rim]
    seg = np.vectorize(local_id.__getitem__)(hole.edges)
    # interior samples on the scan's spacing grid, away from the rim
    lo, hi = rim_xy.min(0), rim_xy.max(0)
    gx = np.arange(lo[0] + 0.5 * spacing, hi[0], spacing)
    gy = np.arange(lo[1] + 0.5 * spacing, hi[1], spacing)
    inner = np.zeros((0, 2))
    if len(gx) and len(gy):
        g = np.stack(np.meshgrid(gx, gy), -1).reshape(-1, 2)
        g = g[labels_fn(g) == hole.label]
        if len(g):
            dist, _ = cKDTree(rim_xy).query(g)
            inner = g[dist > 0.6 * spacing]
    pts = np.vstack([rim_xy, inner])
    constraints = seg
    for _ in range(4):
        try:
            # with an open rim, triangle's hole eating would empty the whole polygon: keep
            # the convex hull ("c") and let the coverage filters below remove the outside
            flags = "pYQ" if len(constraints) == len(seg) else "pcYQ"
            res = triangle.triangulate({"vertices": pts, "segments": constraints}, flags)
        except Exception as exc:  # triangle signals bad input by exceptions
            return np.zeros((0, 3)), np.zeros((0, 3), np.int64), f"triangulation failed ({exc})"
        if "triangles" not in res:
            return np.zeros((0, 3)), np.zeros((0, 3), np.int64), "nothing to triangulate"
        extra = res["vertices"][len(pts):]
        if len(extra) == 0:
            break
        # the rim crosses itself in the view plane (the surface folds): triangle had to add
        # vertices at the crossings; drop the crossing rim edges from the constraints
        constraints = constraints[~_segments_through(pts, constraints, extra, spacing)]
    else:
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64), "the rim crosses itself"
    tris = res["triangles"].astype(np.int64)
    cen = pts[tris].mean(axis=1)
    # drop triangles over the scan itself (islands inside the hole, concave rims)
    _, cand = face_tree.query(cen, k=min(12, face_tree.n))
    cand = np.atleast_2d(cand).astype(np.int64)
    covered = _hk.inside_any(cen, xy, faces, cand)
    region = labels_fn(cen)  # 0 where the raster calls it covered: trust the exact test
    tris = tris[~covered & ((region == hole.label) | (region == 0))]
    if len(tris) == 0:
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64), "nothing to triangulate"
    area = signed_areas(pts, tris)
    wrong = area < 0 if ccw else area > 0
    tris[wrong] = tris[wrong][:, [0, 2, 1]]
    # closed: every rim edge is now an edge of exactly one fill triangle
    te = np.sort(np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]]), axis=1)
    rim_e = np.sort(seg, axis=1)
    te_keys = set(map(tuple, te.tolist()))
    missing = sum(tuple(r) not in te_keys for r in rim_e.tolist())
    # depths: network + rim residual blended across the hole
    used = np.unique(tris)
    n_rim = len(rim)
    new_xy = pts[n_rim:]
    fnet = _lowpass(net, hole.size, lowpass)
    if blend_mode == "harmonic" or len(new_xy) == 0:
        residual = depth[rim] - fnet.evaluate(rim_xy)
        blend = _harmonic(len(pts), tris, np.arange(n_rim), residual)[n_rim:]
    else:
        ring = np.unique(np.concatenate(scan_tree.query_ball_point(
            rim_xy, _RING * spacing)))
        res_ring = depth[ring] - fnet.evaluate(xy[ring])
        blend = RBFInterpolator(xy[ring], res_ring, kernel="thin_plate_spline",
                                neighbors=min(64, len(ring)))(new_xy)
    new_z = fnet.evaluate(new_xy) + blend if len(new_xy) else np.zeros(0)
    keep_new = np.isin(np.arange(n_rim, len(pts)), used)
    # renumber: rim -> scan ids, kept interior -> appended ids (negative placeholders)
    order = np.full(len(pts), -1, dtype=np.int64)
    order[:n_rim] = rim
    new_ids = np.flatnonzero(keep_new)
    order[n_rim + new_ids] = -(np.arange(len(new_ids)) + 1)
    reason = None
    if missing:
        fold = " (the rim crosses itself in the view plane)" if len(constraints) < len(seg) else ""
        reason = f"{missing} rim edges could not be closed{fold}"
    return (np.column_stack([new_xy[new_ids], new_z[new_ids]]), order[tris], reason)


def fill_holes(scan: Scan, net: Network | None = None, *,
               max_hole_size: str | float | None = None, blend: str = "thin-plate",
               lowpass_rel: float | None = 1.0, seed: int = 0,
               progress: bool | None = None) -> FillResult:
    """Fill the holes of a range scan with the network's surface.

    Parameters
    ----------
    scan : Scan
        A triangulated scan (range grid, OBJ, ...) or a bare point cloud (then its
        footprint is triangulated in xy first, see :func:`point_cloud_faces`).
    net : Network, optional
        A network fitted to this scan; fitted here (``seed``) when omitted.
    max_hole_size : float or str, optional
        Fill only holes whose bounding-box diagonal (in the view plane) is at most
        this length in scan units, or a percentage of the scan's bounding-box
        diagonal such as ``"5%"``. Default: every hole.
    blend : {"thin-plate", "harmonic"}
        How the scan's residual ``z - f`` is carried across the hole: a thin-plate
        spline of the residuals of the scan points within 6 spacings of the rim
        (default), or a harmonic interpolation of the rim residuals alone (C0 only).
    lowpass_rel : float or None
        Over a hole, use only the neurons at least this many times as wide as the
        hole (default 1: the network's low-frequency substrate); ``None`` keeps every
        neuron. Narrow neurons fit the data around a hole, and their tails sag into
        it: on punched holes of the face map the full network filled with an RMS error
        of 0.49 % of the diagonal (harmonic blend) and 0.27 % (thin plate), the
        substrate with the thin plate 0.11 % (BENCHMARKS.md, hole filling).
    seed : int
        Seed of the fit when ``net`` is omitted.
    progress : bool, optional
        Progress bar of the fit.

    Returns
    -------
    FillResult
        The repaired mesh (scan vertices and faces first, untouched) and a report
        of every hole: filled, or skipped with a reason. The outer border is never
        filled and is not counted as a hole.

    Raises
    ------
    ScanError
        If the scan is unusable.
    """
    t0 = time.perf_counter()
    if blend not in BLENDS:
        raise AsrbfError(f"blend must be one of {', '.join(BLENDS)}; got {blend!r}")
    if lowpass_rel is not None and not (np.isfinite(lowpass_rel) and lowpass_rel > 0):
        raise AsrbfError(f"lowpass_rel must be a positive number or None, got {lowpass_rel!r}")
    if net is None:
        from .learn import fit

        net = fit(scan, seed=seed, progress=progress)
    R = net.frame.rotation
    local = scan.points @ R
    xy = np.ascontiguousarray(local[:, :2])
    depth = local[:, 2]
    spacing = sampling_spacing(xy)
    diag = scan.bbox_diagonal
    limit = parse_size(max_hole_size, diag)
    faces = scan.faces
    if faces is None or len(faces) == 0:
        faces = point_cloud_faces(xy, spacing)
    if len(faces) == 0:
        raise ScanError("the scan has no triangles to find holes in")
    holes, border, fp = find_holes(xy, faces, spacing)
    area = signed_areas(xy, faces)
    ccw = bool(np.sum(area > 0) >= np.sum(area < 0))
    face_tree = cKDTree(xy[faces].mean(axis=1))
    scan_tree = cKDTree(xy)

    new_pts: list[np.ndarray] = []
    new_tris: list[np.ndarray] = []
    infos: list[HoleInfo] = []
    n_base = len(scan.points)
    n_new = 0
    for i, h in enumerate(holes):
        rim = np.unique(h.edges)
        centre = tuple(float(v) for v in scan.points[rim].mean(axis=0))
        size_pct = 100.0 * h.size / diag
        base = {"index": i, "size_abs": h.size, "size_pct": size_pct, "centre": centre,
                "rim_vertices": int(len(rim))}
        if limit is not None and h.size > limit:
            infos.append(HoleInfo(**base, filled=False,
                                  reason=f"larger than max_hole_size ({h.size:.4g} > "
                                         f"{limit:.4g} scan units)"))
            continue
        verts, tris, reason = _fill_one(h, xy, depth, net, faces, face_tree, scan_tree,
                                        spacing, ccw, fp.label_at, blend, lowpass_rel)
        if len(tris) == 0:
            infos.append(HoleInfo(**base, filled=False, reason=reason))
            continue
        tris = np.where(tris < 0, n_base + n_new - tris - 1, tris)
        new_pts.append(verts)
        new_tris.append(tris)
        n_new += len(verts)
        infos.append(HoleInfo(**base, filled=reason is None, reason=reason,
                              vertices_added=len(verts), faces_added=len(tris)))
    add_local = np.vstack(new_pts) if new_pts else np.zeros((0, 3))
    vertices = np.vstack([scan.points, add_local @ R.T])
    all_faces = np.vstack([faces, *new_tris]) if new_tris else faces
    quality = np.r_[np.zeros(n_base), np.ones(len(add_local))]
    mesh = Mesh(vertices, all_faces, vertex_quality=quality)
    return FillResult(mesh, tuple(infos), border, time.perf_counter() - t0, net)
