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

Where the surface folds over itself (an occlusion: an ear in front of the head), a
hole's rim runs over two layers of surface; each layer is then filled on its own, up
to the fold, from its own surroundings.

References
----------
Meng et al. (2013), section 4.1: holes "convincingly restored" by evaluating the
network over them.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np
import scipy.sparse as sp
from scipy.interpolate import RBFInterpolator
from scipy.sparse.linalg import spsolve
from scipy.spatial import cKDTree

from . import _holes_kernels as _hk
from ._footprint import Footprint, point_cloud_faces, signed_areas
from ._frame import sampling_spacing
from ._io import Scan
from ._mesh import Mesh
from ._network import Network
from .errors import AsrbfError, ScanError

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
    layers : int
        Layers of surface the hole was filled on: more than 1 where the surface folds
        over itself (an occlusion: one layer in front of another in the view), each
        layer then filled up to the fold, whose silhouette stays a boundary.
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
    layers: int = 1


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
# The residual spline sees the scan points within max(6 spacings, a quarter of the hole
# size) of the rim, thinned to at most 1,500, in one global thin plate (no neighbour
# cut-off). Measured on punched holes (face / bun000 / bun045 / bun180, RMS % of the
# diagonal): 64 nearest neighbours within 6 spacings 0.113 / 0.235 / 0.075 / 0.157; the
# global spline on a quarter of the hole size 0.056 / 0.238 / 0.071 / 0.167; on half of it
# 0.052 / 0.229 / 0.122 / 0.174; smoothing changed the third digit only.
_RING = 6.0
_RING_REL = 0.25
_RING_MAX = 1500
# a triangle whose normal is within acos(0.1) = 84 degrees of the view plane is seen edge-on:
# at an occlusion fold such triangles bridge the depth jump between two layers of surface
_EDGE_ON = 0.1


def _thin_out(idx: np.ndarray, xy: np.ndarray, cap: int) -> np.ndarray:
    """At most about ``cap`` of the points ``idx``, evenly spread (one per grid cell)."""
    if len(idx) <= cap:
        return idx
    p = xy[idx]
    lo, span = p.min(0), np.ptp(p, axis=0).max()
    step = span / np.sqrt(cap / 2.0)
    while True:
        key = np.floor((p - lo) / step).astype(np.int64)
        _, first = np.unique(key[:, 0] * (1 << 31) + key[:, 1], return_index=True)
        if len(first) <= cap:
            return idx[np.sort(first)]
        step *= 1.2


def _lowpass(net: Network, hole_size: float, factor: float | None) -> Network:
    """Drop the neurons narrower than ``factor`` x the hole size from the network."""
    if factor is None:
        return net
    cut = factor * hole_size / float(np.sqrt(net.frame.scale[0] * net.frame.scale[1]))
    keep = net.widths >= cut
    return Network(net.a0, net.centers[keep], net.widths[keep], net.weights[keep], net.frame,
                   net.config, None, net.info)


_EMPTY = (np.zeros((0, 3)), np.zeros((0, 3), np.int64))


@dataclass(frozen=True, eq=False)
class _Ctx:
    """What every hole's fill needs to know about the scan (view-frame coordinates)."""

    xy: np.ndarray
    depth: np.ndarray
    net: Network
    faces: np.ndarray
    face_tree: cKDTree
    scan_tree: cKDTree
    spacing: float
    ccw: bool
    labels_fn: Any
    blend: str
    lowpass: float | None
    boundary: np.ndarray  # (B, 2) the scan's boundary edges


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


def _triangulate(pts: np.ndarray, seg: np.ndarray, flags: str) -> tuple[np.ndarray, np.ndarray]:
    """Constrained triangulation; returns (triangles, vertices triangle had to add)."""
    import triangle

    res = triangle.triangulate({"vertices": pts, "segments": seg}, flags)
    tris = np.asarray(res.get("triangles", np.zeros((0, 3))), dtype=np.int64).reshape(-1, 3)
    return tris, np.asarray(res["vertices"])[len(pts):]


def _grid_samples(lo: np.ndarray, hi: np.ndarray, spacing: float) -> np.ndarray:
    """Points of the scan-spacing grid strictly inside the box [lo, hi]."""
    gx = np.arange(lo[0] + 0.5 * spacing, hi[0], spacing)
    gy = np.arange(lo[1] + 0.5 * spacing, hi[1], spacing)
    if not (len(gx) and len(gy)):
        return np.zeros((0, 2))
    return np.stack(np.meshgrid(gx, gy), -1).reshape(-1, 2)


def _away_from(g: np.ndarray, pts: np.ndarray, seg: np.ndarray, gap: float) -> np.ndarray:
    """Keep the points of ``g`` farther than ``gap`` from every segment ``pts[seg]``."""
    if len(g) == 0:
        return g
    a, b = pts[seg[:, 0]], pts[seg[:, 1]]
    d = b - a
    L2 = np.maximum(np.einsum("ij,ij->i", d, d), 1e-300)
    t = np.clip(((g[:, None, :] - a[None]) * d[None]).sum(-1) / L2, 0.0, 1.0)
    near = np.linalg.norm(a[None] + t[..., None] * d[None] - g[:, None, :], axis=2).min(1)
    return g[near > gap]


def _residual_spline(ctx: _Ctx, ring: np.ndarray, fnet: Network, centre: np.ndarray,
                     size: float):
    """Thin-plate spline of the scan's residual ``z - f`` on the ``ring`` points."""
    ring = _thin_out(ring, ctx.xy, _RING_MAX)
    res = ctx.depth[ring] - fnet.evaluate(ctx.xy[ring])
    spline = RBFInterpolator((ctx.xy[ring] - centre) / size, res, kernel="thin_plate_spline",
                             neighbors=None)
    return lambda q: spline((q - centre) / size)


def _close(pts: np.ndarray, rim: np.ndarray, seg: np.ndarray, tris: np.ndarray,
           size: float, ctx: _Ctx, cover_faces: np.ndarray, cover_tree: cKDTree,
           region: Any, ring: np.ndarray,
           substrate: bool = True) -> tuple[np.ndarray, np.ndarray, int]:
    """Finish one triangulated patch: drop what lies over the scan, orient, set depths.

    ``pts`` are the rim (scan vertices ``rim``, first) and the new interior points;
    returns (new vertex local xyz, triangles with scan ids >= 0 and new ids -1, -2, ...,
    rim edges ``seg`` left without a triangle).
    """
    if len(tris) == 0:
        return *_EMPTY, len(seg)
    cen = pts[tris].mean(axis=1)
    # drop triangles over the scan itself (islands inside the hole, concave rims)
    _, cand = cover_tree.query(cen, k=min(12, cover_tree.n))
    cand = np.atleast_2d(cand).astype(np.int64)
    keep = ~_hk.inside_any(cen, ctx.xy, cover_faces, cand)
    if region is not None:
        keep &= region(cen)
    tris = tris[keep]
    if len(tris) == 0:
        return *_EMPTY, len(seg)
    area = signed_areas(pts, tris)
    wrong = area < 0 if ctx.ccw else area > 0
    tris[wrong] = tris[wrong][:, [0, 2, 1]]
    te = np.sort(np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]]), axis=1)
    te_keys = set(map(tuple, te.tolist()))
    missing = sum(tuple(r) not in te_keys for r in np.sort(seg, axis=1).tolist())
    # depths: the network's substrate + the rim residual carried across the hole
    n_rim = len(rim)
    new_xy = pts[n_rim:]
    # at a fold the network (a height field) averages the layers: no substrate there
    fnet = _lowpass(ctx.net, size, ctx.lowpass if substrate else np.inf)
    if len(new_xy) == 0:
        new_z = np.zeros(0)
    elif ctx.blend == "harmonic":
        residual = ctx.depth[rim] - fnet.evaluate(pts[:n_rim])
        new_z = (fnet.evaluate(new_xy)
                 + _harmonic(len(pts), tris, np.arange(n_rim), residual)[n_rim:])
    else:
        spline = _residual_spline(ctx, ring, fnet, pts[:n_rim].mean(0), size)
        new_z = fnet.evaluate(new_xy) + spline(new_xy)
    kept = np.flatnonzero(np.isin(np.arange(n_rim, len(pts)), tris))
    order = np.full(len(pts), -1, dtype=np.int64)
    order[:n_rim] = rim
    order[n_rim + kept] = -(np.arange(len(kept)) + 1)
    return np.column_stack([new_xy[kept], new_z[kept]]), order[tris], missing


def _reach(size: float, spacing: float) -> float:
    """Radius around the rim whose scan points the residual spline sees."""
    return max(_RING * spacing, _RING_REL * size)


def _chains(edges: np.ndarray) -> list[tuple[np.ndarray, bool]]:
    """Split edges into ordered vertex chains, each with whether it is a closed loop."""
    adj: dict[int, list[int]] = {}
    for a, b in edges.tolist():
        adj.setdefault(a, []).append(b)
        adj.setdefault(b, []).append(a)
    used: set[tuple[int, int]] = set()
    out = []
    starts = [v for v, n in adj.items() if len(n) != 2] + list(adj)
    for s in starts:
        for nxt in adj[s]:
            if (min(s, nxt), max(s, nxt)) in used:
                continue
            chain, prev, cur = [s], s, nxt
            used.add((min(s, nxt), max(s, nxt)))
            while True:
                chain.append(cur)
                step = [w for w in adj[cur] if (min(cur, w), max(cur, w)) not in used]
                if len(adj[cur]) != 2 or not step:
                    break
                prev, cur = cur, step[0]
                used.add((min(prev, cur), max(prev, cur)))
            loop = chain[-1] == chain[0]
            if loop:
                chain.pop()
            out.append((np.array(chain, dtype=np.int64), loop))
    return out


def _simple_polygon(xy: np.ndarray, chain: np.ndarray, loop: bool,
                    max_trim: int = 8) -> tuple[np.ndarray, np.ndarray, tuple[int, int]] | None:
    """Close a rim chain by its chord into a simple polygon.

    An open chain whose chord crosses it (the chain curls at the fold) is trimmed by a
    few vertices at its ends until it does not. Returns the polygon's chain, its
    triangles and the vertices trimmed at each end; None if trimming does not help.
    """
    n = len(chain)
    trims = [(0, 0)] if loop else [(a, t - a) for t in range(max_trim + 1) for a in range(t + 1)]
    for a, b in trims:
        c = chain[a:n - b]
        if len(c) < 3:
            break
        seg = np.column_stack([np.arange(len(c)), np.roll(np.arange(len(c)), -1)])
        tris, extra = _triangulate(xy[c], seg, "pQ")
        if len(extra) == 0 and len(tris):
            return c, tris, (a, b)
    return None


_Layer = tuple[int, np.ndarray, np.ndarray]  # number, triangles, vertices


def _fold_layers(hole: _Hole, ctx: _Ctx, reach: float) -> tuple[np.ndarray, list[_Layer]] | None:
    """Split the scan around a hole into layers of surface; None if the rim lies on one.

    Returns the layer of each rim edge (-1: on the fold's wall or joining two layers) and,
    per layer, its number, triangles and vertices.
    """
    from scipy.sparse.csgraph import connected_components

    rim_xy = ctx.xy[np.unique(hole.edges)]
    centre = 0.5 * (rim_xy.min(0) + rim_xy.max(0))
    near = ctx.face_tree.query_ball_point(centre, 0.5 * hole.size + reach + 2 * ctx.spacing)
    lf = ctx.faces[np.asarray(near, dtype=np.int64)]
    # triangles seen edge-on bridge the depth jump at the fold: they belong to no layer
    p3 = np.column_stack([ctx.xy, ctx.depth])
    nrm = np.cross(p3[lf[:, 1]] - p3[lf[:, 0]], p3[lf[:, 2]] - p3[lf[:, 0]])
    lf = lf[np.abs(nrm[:, 2]) >= _EDGE_ON * np.maximum(np.linalg.norm(nrm, axis=1), 1e-300)]
    if len(lf) == 0:
        return None
    verts, inv = np.unique(lf, return_inverse=True)
    inv = inv.reshape(-1, 3)
    e = np.concatenate([inv[:, [0, 1]], inv[:, [1, 2]]])
    graph = sp.coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(len(verts),) * 2)
    _, comp = connected_components(graph, directed=False)
    layer_of = np.full(len(ctx.xy), -1, dtype=np.int64)
    layer_of[verts] = comp
    la, lb = layer_of[hole.edges[:, 0]], layer_of[hole.edges[:, 1]]
    edge_layer = np.where(la == lb, la, -1)
    ks = [k for k in np.unique(edge_layer[edge_layer >= 0]) if (edge_layer == k).sum() >= 2]
    if len(ks) < 2:
        return None
    return edge_layer, [(int(k), lf[comp[inv[:, 0]] == k], verts[comp == k]) for k in ks]


def _layer_rim(rim_edges: np.ndarray, layer_verts: np.ndarray,
               boundary: np.ndarray) -> np.ndarray:
    """Complete a layer's part of a hole's rim to the boundary loop it lies on, if any.

    Where two layers overlap in the view, some of a layer's rim edges face the other
    layer's triangles instead of the hole and were not counted in the rim: the layer's
    own boundary loop through its rim edges, when it closes near the hole, restores them.
    """
    from scipy.sparse.csgraph import connected_components

    b = boundary[np.isin(boundary, layer_verts).all(axis=1)]
    if len(b) == 0:
        return rim_edges
    vs, inv = np.unique(b, return_inverse=True)
    inv = inv.reshape(-1, 2)
    graph = sp.coo_matrix((np.ones(len(b)), (inv[:, 0], inv[:, 1])), shape=(len(vs),) * 2)
    _, comp = connected_components(graph, directed=False)
    degree = np.bincount(inv.ravel(), minlength=len(vs))
    out = [rim_edges]
    for c in np.unique(comp[np.searchsorted(vs, rim_edges[:, 0])]):
        members = comp == c
        if (degree[members] == 2).all():  # a closed loop within the layer's neighbourhood
            out.append(b[members[inv[:, 0]]])
    return np.unique(np.sort(np.vstack(out), axis=1), axis=0)


def _fill_chain(chain: np.ndarray, loop: bool, hole: _Hole, ctx: _Ctx, layer_faces: np.ndarray,
                layer_verts: np.ndarray, reach: float) -> tuple[np.ndarray, np.ndarray, set]:
    """Fill one layer's rim chain closed by its chord.

    Returns (new vertices, triangles, rim edges that belong to the fold's silhouette:
    chain ends trimmed at the fold, or a chain whose polygon the layer already covers).
    """
    def edges_of(c: np.ndarray) -> set[tuple[int, int]]:
        return set(map(tuple, np.sort(np.column_stack([c[:-1], c[1:]]), axis=1).tolist()))

    found = _simple_polygon(ctx.xy, chain, loop)
    if found is None:  # this layer's rim crosses itself too: leave it open
        return *_EMPTY, set()
    c, tris, (a, b) = found
    silhouette = edges_of(chain[:a + 1]) | edges_of(chain[len(chain) - b - 1:]) if a or b else set()
    poly = ctx.xy[c]
    seg = np.column_stack([np.arange(len(c)), np.roll(np.arange(len(c)), -1)])
    g = _grid_samples(poly.min(0), poly.max(0), ctx.spacing)
    if len(g):
        _, cand = cKDTree(poly[tris].mean(axis=1)).query(g, k=min(8, len(tris)))
        g = g[_hk.inside_any(g, poly, tris, np.atleast_2d(cand).astype(np.int64))]
        g = _away_from(g, poly, seg, 0.6 * ctx.spacing)
    pts = np.vstack([poly, g])
    tris, extra = _triangulate(pts, seg, "pYQ")
    if len(extra):
        return *_EMPTY, silhouette
    ring = np.unique(np.concatenate(ctx.scan_tree.query_ball_point(poly, reach)))
    ring = ring[np.isin(ring, layer_verts)]
    v, t, _ = _close(pts, c, seg, tris, hole.size, ctx, layer_faces,
                     cKDTree(ctx.xy[layer_faces].mean(axis=1)), None, ring, substrate=False)
    if len(t) == 0:  # the layer's own triangles cover the whole polygon: nothing is open
        silhouette |= edges_of(c)
    return v, t, silhouette


def _fill_layers(hole: _Hole, ctx: _Ctx) -> _Patch | None:
    """Fill a hole at a fold of the surface, one layer at a time.

    At an occlusion fold the hole's rim runs over two (or more) layers of surface, one
    in front of the other: in the view plane their rims cross, or one layer covers the
    other's hole. The layers are the pieces of the scan around the hole once the
    triangles seen edge-on (the fold's wall) are set aside; each layer's part of the rim
    is closed by its chord (the unseen fold edge) and filled like a hole of its own,
    from that layer's own surroundings only. The fold's silhouette stays a boundary, as
    it is in the scan. Returns None when the rim lies on one layer.
    """
    reach = _reach(hole.size, ctx.spacing)
    split = _fold_layers(hole, ctx, reach)
    if split is None:
        return None
    edge_layer, layers = split
    new_v: list[np.ndarray] = []
    new_t: list[np.ndarray] = []
    n_new = 0
    done: set[tuple[int, int]] = set()
    for k, layer_faces, layer_verts in layers:
        for chain, loop in _chains(_layer_rim(hole.edges[edge_layer == k], layer_verts,
                                              ctx.boundary)):
            if len(chain) < 3:
                continue
            try:
                v, t, silhouette = _fill_chain(chain, loop, hole, ctx, layer_faces,
                                               layer_verts, reach)
            except Exception:  # noqa: BLE001 - triangle signals bad input by exceptions
                continue
            done |= silhouette
            if len(t) == 0:
                continue
            new_t.append(np.where(t < 0, t - n_new, t))
            new_v.append(v)
            n_new += len(v)
            te = np.sort(np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]]), axis=1)
            done |= set(map(tuple, te.tolist()))
    note = f"the surface folds over itself here: {len(layers)} layers"
    if not new_t:
        return _Patch(*_EMPTY, len(hole.edges), note, len(layers))
    on_layer = np.sort(hole.edges[edge_layer >= 0], axis=1)
    missing = sum(tuple(r) not in done for r in on_layer.tolist())
    return _Patch(np.vstack(new_v), np.vstack(new_t), missing, note, len(layers))


class _Patch(NamedTuple):
    """A hole's fill: new vertices, triangles, rim edges left open and what happened."""

    verts: np.ndarray
    tris: np.ndarray
    missing: int
    note: str | None = None
    layers: int = 1


def _fill_one(hole: _Hole, ctx: _Ctx) -> tuple[_Patch, str | None]:
    """Fill one hole; returns the patch and why it is not closed (None if it is)."""
    patch = _fill_single(hole, ctx)
    if patch.missing:  # a fold: the rim crosses itself, or another layer covers the hole
        layered = _fill_layers(hole, ctx)
        if layered is not None and layered.missing < patch.missing:
            patch = layered
    if not patch.missing:
        return patch, None
    why = f" ({patch.note})" if patch.note else ""
    if len(patch.tris) == 0:
        return patch, f"nothing could be filled{why}"
    return patch, f"{patch.missing} rim edges could not be closed{why}"


def _fill_single(hole: _Hole, ctx: _Ctx) -> _Patch:
    """Fill a hole as one patch of the height field."""
    rim = np.unique(hole.edges)
    local_id = {int(v): i for i, v in enumerate(rim)}
    rim_xy = ctx.xy[rim]
    seg = np.vectorize(local_id.__getitem__)(hole.edges)
    # interior samples on the scan's spacing grid, away from the rim
    g = _grid_samples(rim_xy.min(0), rim_xy.max(0), ctx.spacing)
    g = g[ctx.labels_fn(g) == hole.label] if len(g) else g
    if len(g):
        dist, _ = cKDTree(rim_xy).query(g)
        g = g[dist > 0.6 * ctx.spacing]
    pts = np.vstack([rim_xy, g])
    constraints = seg
    try:
        for _ in range(5):
            # with an open rim, triangle's hole eating would empty the whole polygon: keep
            # the convex hull ("c") and let the coverage filters below remove the outside
            tris, extra = _triangulate(pts, constraints,
                                       "pYQ" if len(constraints) == len(seg) else "pcYQ")
            if len(extra) == 0:
                break
            # the rim crosses itself in the view plane: drop the crossing rim edges from the
            # constraints
            constraints = constraints[~_segments_through(pts, constraints, extra, ctx.spacing)]
        else:
            return _Patch(*_EMPTY, len(seg), "the rim crosses itself in the view plane")
    except Exception as exc:  # noqa: BLE001 - triangle signals bad input by exceptions
        return _Patch(*_EMPTY, len(seg), f"triangulation failed: {exc}")

    def region(cen: np.ndarray) -> np.ndarray:
        lab = ctx.labels_fn(cen)  # 0 where the raster calls it covered: trust the exact test
        return (lab == hole.label) | (lab == 0)

    ring = np.unique(np.concatenate(ctx.scan_tree.query_ball_point(
        rim_xy, _reach(hole.size, ctx.spacing))))
    verts, tris, missing = _close(pts, rim, seg, tris, hole.size, ctx, ctx.faces,
                                  ctx.face_tree, region, ring)
    note = "the rim crosses itself in the view plane" if len(constraints) < len(seg) else None
    return _Patch(verts, tris, missing, note)


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
        spline of the residuals of the scan points around the rim, within 6 spacings
        or a quarter of the hole's size (default), or a harmonic interpolation of the
        rim residuals alone (C0 only).
    lowpass_rel : float or None
        Over a hole, use only the neurons at least this many times as wide as the
        hole (default 1: the network's low-frequency substrate); ``None`` keeps every
        neuron. Narrow neurons fit the data around a hole, and their tails sag into
        it: on punched holes of the face map the full network filled with an RMS error
        of 0.49 % of the diagonal (harmonic blend) and 0.33 % (thin plate), the
        substrate with the thin plate 0.056 % (BENCHMARKS.md, hole filling).
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
        from ._learn import fit

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
    ctx = _Ctx(xy, depth, net, faces, cKDTree(xy[faces].mean(axis=1)), cKDTree(xy), spacing,
               ccw, fp.label_at, blend, lowpass_rel, _boundary_edges(faces)[0])

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
        patch, reason = _fill_one(h, ctx)
        verts, tris = patch.verts, patch.tris
        if len(tris) == 0:
            infos.append(HoleInfo(**base, filled=False, reason=reason))
            continue
        tris = np.where(tris < 0, n_base + n_new - tris - 1, tris)
        new_pts.append(verts)
        new_tris.append(tris)
        n_new += len(verts)
        infos.append(HoleInfo(**base, filled=reason is None, reason=reason,
                              vertices_added=len(verts), faces_added=len(tris),
                              layers=patch.layers))
    add_local = np.vstack(new_pts) if new_pts else np.zeros((0, 3))
    vertices = np.vstack([scan.points, add_local @ R.T])
    all_faces = np.vstack([faces, *new_tris]) if new_tris else faces
    quality = np.r_[np.zeros(n_base), np.ones(len(add_local))]
    mesh = Mesh(vertices, all_faces, vertex_quality=quality)
    return FillResult(mesh, tuple(infos), border, time.perf_counter() - t0, net)
