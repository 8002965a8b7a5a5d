"""Building one hole's fill: triangulation of the hole, depths from the network and the rim.

New vertices inside the hole at the scan's own spacing (the rim's where the scan is sampled
more coarsely: ``_holes.LOCAL_SPACING``), a constrained triangulation in
xy (``triangle``, with no extra vertex on the hole's boundary so the rim edges are shared
exactly), depths from a thin-plate spline of the scan points around the rim, fitted as
heights over the ring's own best-fit plane (:func:`_plane_depth`); where that plane is
seen too obliquely or the ring is too curved to have one, from the network's
low-frequency substrate (:func:`_lowpass`) plus the scan's residual ``z - f`` around the
rim carried across the hole by a thin-plate spline in the view plane (or a harmonic
interpolation, ``blend="harmonic"``), so there is no step at the seam.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np
import scipy.sparse as sp
from scipy.interpolate import RBFInterpolator
from scipy.sparse.linalg import spsolve
from scipy.spatial import cKDTree

from . import _config
from . import _holes_kernels as _hk
from ._footprint import signed_areas
from ._hole_find import Hole
from ._network import Network
from ._piece import Piece
from ._triangle import triangulate

__all__ = ["BLENDS", "EMPTY", "Ctx", "Patch", "away_from", "close_patch", "fill_single",
           "grid_samples", "ring_reach", "triangulate"]

#: How the scan's residual is carried across a hole (``fill_holes(blend=...)``).
BLENDS = _config.BLENDS
# The residual spline sees the scan points within max(6 spacings, a quarter of the hole
# size) of the rim, thinned to at most 1,500, in one global thin plate (no neighbour
# cut-off). Measured on punched holes (face / bun000 / bun045 / bun180, RMS % of the
# diagonal): 64 nearest neighbours within 6 spacings 0.113 / 0.235 / 0.075 / 0.157; the
# global spline on a quarter of the hole size 0.056 / 0.238 / 0.071 / 0.167; on half of it
# 0.052 / 0.229 / 0.122 / 0.174; smoothing changed the third digit only.
_RING = 6.0
_RING_REL = 0.25
_RING_MAX = 1500


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


def _lowpass(net: Network, hole_size: float, factor: float | None,
             cache: dict | None = None) -> Network:
    """Drop the neurons narrower than ``factor`` x the hole size from the network.

    With ``cache`` (a dict kept for one network), each substrate is made once: the kept
    neurons are those of the widest n, so n names it (a Kinect frame's 161 fills made
    one each, 0.2 s).
    """
    if factor is None:
        return net
    if cache is not None:
        widths = cache.get("widths")
        if widths is None:
            widths = cache["widths"] = np.concatenate([p.widths for p in net.pieces])
        key: int | str = "flat" if np.isinf(factor) else int(np.count_nonzero(
            widths >= factor * hole_size / float(np.sqrt(net.frame.scale[0]
                                                         * net.frame.scale[1]))))
        sub = cache.get(key)
        if sub is None:
            sub = cache[key] = _lowpass(net, hole_size, factor)
        return sub
    if np.isinf(factor):  # no substrate: one flat surface (pieces' constants would step)
        return Network(0.0, np.zeros((0, 2)), np.zeros(0), np.zeros(0), net.frame, net.config,
                       None, net.info)
    cut = factor * hole_size / float(np.sqrt(net.frame.scale[0] * net.frame.scale[1]))
    keeps = [p.widths >= cut for p in net.pieces]
    if all(k.all() for k in keeps):
        return net
    # a piece that keeps every neuron is reused as it is, its evaluation grid with it
    pieces = tuple(p if k.all() else Piece(p.a0, p.centers[k], p.widths[k], p.weights[k],
                                           None, p.info)
                   for p, k in zip(net.pieces, keeps, strict=True))
    return Network.from_pieces(pieces, net.frame, net.config, net.info, net.piece_map)


EMPTY = (np.zeros((0, 3)), np.zeros((0, 3), np.int64))


@dataclass(frozen=True, eq=False)
class Ctx:
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
    substrates: dict = field(default_factory=dict)  # :func:`_lowpass`'s cache
    piece: np.ndarray | None = None  # each scan vertex's piece (None: one piece)
    cache: dict = field(default_factory=dict)  # built on first use (``_hole_wall``)


class Patch(NamedTuple):
    """A hole's fill: new vertices, triangles, rim edges left open and what happened."""

    verts: np.ndarray
    tris: np.ndarray
    missing: int
    note: str | None = None
    layers: int = 1


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


def grid_samples(lo: np.ndarray, hi: np.ndarray, spacing: float) -> np.ndarray:
    """Points of the scan-spacing grid strictly inside the box [lo, hi]."""
    gx = np.arange(lo[0] + 0.5 * spacing, hi[0], spacing)
    gy = np.arange(lo[1] + 0.5 * spacing, hi[1], spacing)
    if not (len(gx) and len(gy)):
        return np.zeros((0, 2))
    return np.stack(np.meshgrid(gx, gy), -1).reshape(-1, 2)


def away_from(g: np.ndarray, pts: np.ndarray, seg: np.ndarray, gap: float) -> np.ndarray:
    """Keep the points of ``g`` farther than ``gap`` from every segment ``pts[seg]``."""
    if len(g) == 0 or len(seg) == 0:
        return g
    a, b = pts[seg[:, 0]], pts[seg[:, 1]]
    d = b - a
    L2 = np.maximum(np.einsum("ij,ij->i", d, d), 1e-300)
    if len(g) * len(seg) <= 200_000:  # small: every point against every segment
        t = np.clip(((g[:, None, :] - a[None]) * d[None]).sum(-1) / L2, 0.0, 1.0)
        near = np.linalg.norm(a[None] + t[..., None] * d[None] - g[:, None, :], axis=2).min(1)
        return g[near > gap]
    # large: candidate segments from samples every ``gap`` along them (a segment within
    # ``gap`` of a point has a sample within 1.5 ``gap``), then the exact distance
    n = np.maximum(np.ceil(np.sqrt(L2) / gap).astype(np.int64), 1)
    owner = np.repeat(np.arange(len(seg)), n + 1)
    frac = np.concatenate([np.linspace(0.0, 1.0, k + 1) for k in n])
    samples = a[owner] + frac[:, None] * d[owner]
    hits = cKDTree(samples).query_ball_point(g, 1.5 * gap)
    lens = np.fromiter((len(h) for h in hits), dtype=np.int64, count=len(hits))
    if lens.sum() == 0:
        return g
    pi = np.repeat(np.arange(len(g)), lens)
    si = owner[np.concatenate([np.asarray(h, dtype=np.int64) for h in hits])]
    t = np.clip(np.einsum("ij,ij->i", g[pi] - a[si], d[si]) / L2[si], 0.0, 1.0)
    dist = np.linalg.norm(a[si] + t[:, None] * d[si] - g[pi], axis=1)
    close = np.zeros(len(g), dtype=bool)
    close[pi[dist <= gap]] = True
    return g[~close]


def _residual_spline(ctx: Ctx, ring: np.ndarray, fnet: Network, centre: np.ndarray,
                     size: float):
    """Thin-plate spline of the scan's residual ``z - f`` on the ``ring`` points."""
    ring = _thin_out(ring, ctx.xy, _RING_MAX)
    res = ctx.depth[ring] - fnet.evaluate(ctx.xy[ring])
    # points at one xy (a scan's copies of a vertex, coordinates rounded coarser than
    # its spacing) made the system singular: one point each, their mean residual
    xy, inv = np.unique(ctx.xy[ring], axis=0, return_inverse=True)
    if len(xy) < len(ring):
        res = np.bincount(inv.ravel(), weights=res) / np.bincount(inv.ravel())
    else:  # as they came (the same solve, bit for bit, as before)
        xy = ctx.xy[ring]
    try:
        spline = RBFInterpolator((xy - centre) / size, res, kernel="thin_plate_spline",
                                 neighbors=None)
    except (np.linalg.LinAlgError, ValueError):  # too few points, or all on one line
        mean = float(res.mean()) if len(res) else 0.0
        return lambda q: np.full(len(q), mean)
    return lambda q: spline((q - centre) / size)


# Tried and not kept (2026-12-01): the ring's frame from the mean of its points' scan
# normals (area-weighted, oriented to the scanner) instead of the plane's normal, for every
# ring, or chosen per ring by a four-sector cross-validation of each frame's ray depths on
# the ring, or only where a ring point faces away from the plane. Below Poisson (%) /
# pooled RMS, as now -> mean normal -> cross-validated -> facing: model views 71.4 / 0.0885
# -> 74.8 / 0.0743 -> 73.5 / 0.0761 -> 72.1 / 0.0771; bunny views 70.9 / 0.1609 -> 72.8 /
# 0.1584 -> 71.7 / 0.1594 -> 71.3 / 0.1587; dev scans seeds 0-9 82.8 / 0.1420 -> 80.7 /
# 0.1572 -> 80.2 / 0.1521 -> 81.2 / 0.1471; seeds 10-19 73.8 / 0.1694 -> 74.3 / 0.1689 ->
# 75.4 / 0.1685 -> 74.9 / 0.1662. The synthetic views gain, the real scans' first seeds
# lose (bun090 seed 0's cliff hole 0.264 -> 0.640 % with each).
# The thin plate runs over the ring's own best-fit plane (heights along its normal, each new
# vertex's depth where its view ray meets that surface), not over the view plane, unless the
# plane is seen too obliquely (normal's z below _MIN_NZ) or the ring is not flat enough to
# have one (third singular value above _FLAT of the first): then the view-plane fill
# (substrate + residual spline). Measured on the punch protocol (border="parts", face +
# 4 bunny scans x seeds 0-9, 192 enclosed holes, RMS % of the diagonal; screened Poisson
# pooled 0.205, median 0.144): view plane pooled 0.180, median 0.116, below Poisson on
# 67.7 % of holes, 4 holes above 0.5 %; ring plane everywhere (_MIN_NZ 0.3) 0.153 / 0.112
# / 79.7 % / 3; with _MIN_NZ 0.15 and _FLAT 0.5 0.149 / 0.113 / 79.7 % / 1 (bun000 seed 6,
# 0.526 vs Poisson 0.575). Smoothing the spline (1e-4 x n) made it 0.192 / 0.138 / 58 %;
# choosing the frame per hole by how well each predicted the ring's innermost third from
# the rest 0.162 / 0.111 / 77.1 % / 4.
# The fill's splines then see the ring within max(6 spacings, _FILL_REL x the hole size)
# of the rim only (ring_reach, which the layers and the grid fill use, is unchanged):
# _FILL_REL 0.4 made it 0.164 / 0.113 / 74.0 % / 1; 0.25 (ring_reach) 0.149 / 0.113 /
# 79.2 % / 1; 0.18 0.147 / 0.109 / 80.7 % / 0; 0.12 0.147 / 0.109 / 80.7 % / 0. With
# _FILL_REL 0.18, _MIN_NZ 0.3 gave 0.149 / 0.109 / 80.2 % / 1 (bun090 seed 0 in the view
# plane, 0.613) and _FLAT 0.4 0.150 / 0.109 / 80.7 % / 1 (bun000 seed 6 in it, 0.562).
# The thin plate interpolated the ring's noise, and carried it into the hole: it now
# smooths, by n s^2 h^2 / L^4 x _SMOOTH in its unit coordinates (n ring points, s^2 the
# ring's noise variance (:func:`_ring_noise`), h the scan's spacing, L the hole size: a
# smoothing spline's lambda goes as the noise over the bending of the surface, which
# grows with the hole). Punch protocol, seeds 0-9, below Poisson on / pooled RMS:
# interpolating, dev scans 81.2 % / 0.1469 (worst hole 0.463), eight synthetic bunny
# views 61.3 % / 0.1707; _SMOOTH 60: 82.3 % / 0.1480 (0.479) and 65.7 % / 0.1684; 150:
# 83.3 % / 0.1489 (0.496) and 68.3 % / 0.1702 (the views' holes under 400 points, below
# Poisson on 35 -> 57 %; the face map 74 -> 71 % with either). A smoothing of 3e-3
# whatever the hole: views 67.9 % / 0.1753; n s^2 / L^2 x 0.5: 67.9 % / 0.1807 (large
# holes smoothed too much).
# The surface over the ring's plane is the mean of that thin plate and the same smoothing
# spline of the kernel r^3 (a cubic polyharmonic spline: a smoothness between the thin
# plate's and the next order's), each fitted to the ring. Punch protocol, seeds 0-9,
# pooled RMS / below Poisson on / holes better than with the thin plate alone: dev scans
# 0.1480 -> 0.1442 / 82.3 -> 81.8 % (face 71 -> 74 %) / 122 of 192; eight synthetic
# bunny views 0.1664 -> 0.1641 / 66.4 -> 70.2 % / 173 of 265 (border="parts" with parts
# joined by edges). The cubic spline alone: 0.1451 / 78.6 % and 0.1643 / 72.1 % (a view
# hole at 0.546); r^2.5: 0.1447 / 80.7 % and 0.1657 / 69.8 %; the one kernel
# r^2 log r + r^3: 0.1461 / 81.2 % (dev); the thin plate with a quadratic term: 0.1472 /
# 82.8 % (dev); a linear kernel 0.189 (dev); the thin plate's mean with the network's
# view-plane fill (below) 0.166-0.189 (dev, weights 3:1 and 1:1), with a harmonic fill
# of the rim's depths 0.19-0.35 (views, weights 3:1 to 0:1). A spline in tension (kernel
# -(K0(t r) + log(t r)): the thin plate as t -> 0, a membrane as t grows; t per hole size)
# in place of the thin plate, averaged with the cubic (a Python prototype, its t = 0 the
# reference: views 70.2 % / 0.1660, dev 81.8 % / 0.1449): views t = 2, 5, 10: 70.6 / 70.9 /
# 73.2 %, pooled 0.1655 / 0.1659 / 0.1709 (worst 0.498 at 10); dev t = 3, 6: 81.2 % /
# 0.1459 and 81.2 % / 0.1490 (the face map 74 % with each); the best t of 0, 2, 5 per hole
# (an oracle) 73.2 % of the views' holes. Both splines with a quadratic term (2026-11-30,
# for the shafts and domes of the bone and airplane views, where the thin plate sags
# or bulges across large holes), below Poisson on / pooled RMS: views of three other
# models (seeds 0-9, 147 holes) 63.3 -> 65.3 % / 0.0934 -> 0.0918, dev scans 81.8 ->
# 81.8 % / 0.1442 -> 0.1441, the dev scans' seeds 10-19 72.7 -> 72.2 % / 0.1745 -> 0.1752:
# not kept. The worst of those holes are not the spline's: a bone's condyle whose ring's
# own curvature (a least-squares quadric through it) overshoots the truth by more
# than the thin plate does, a crest of the airplane's fuselage left outside the ring.
_CUBIC = 0.5
# A ring that one quadratic fits within _CURVED times its noise (RMS; rings of _CURVED_MIN
# points or more) is filled by the quintic spline with a quadratic term instead: it keeps the
# curvature the thin plate flattens (2026-11-30, eighteenth session). Punch protocol, seeds
# 0-9, below Poisson on / pooled RMS: views of three other models (147 holes) 63.3 -> 70.1 %
# / 0.0934 -> 0.0919 (36 holes changed, 27 of them lower; bone0 43 -> 71 %, bone2 33 -> 67 %);
# the dev scans (192) and their seeds 10-19 (187) the same figures (1 and 2 holes changed).
# _CURVED 4: the models 72.1 % but seeds 10-19 72.7 -> 71.1 % (worst hole 0.766 -> 0.874).
# The quintic everywhere: models 68.0 %, dev 71.4 %, seeds 10-19 58.3 %; chosen per hole by
# how each spline fitted to the ring's outer half predicts its inner half: models 70.1 %,
# seeds 10-19 64.2 %; triharmonic (r^4 log r) kernels did less (65.3 % at best on models).
# Measured again with the rim's own ring (2026-12-01; model views / bunny views / dev seeds
# 0-9 / seeds 10-19, below Poisson on): as now 71.4 / 70.9 / 82.8 / 73.8 %; a quarter of
# the quintic mixed into every other ring's spline 74.8 / 72.1 / 79.7 / 69.0 % (a half:
# models 68.7 %, views 70.6 %); _CURVED 3: 72.1 / 71.3 % (models, views). Choosing per hole
# the better of the two (an oracle) would give 79.6 / 76.2 / 84.4 / 74.3 %, but no feature
# of the ring tried told where the quintic does better: the quadratic's largest
# coefficient, median over the holes it helps against those it hurts, 0.35 against 0.59
# on the model views and 0.44 against 0.32 on seeds 10-19; its misfit under T x the noise
# (on the holes matched to their ring; as now 72.9 / 70.6 / 82.0 / 74.0 %): T 3 73.6 /
# 71.0 / 82.0 / 73.5 %, T 4 75.0 / 70.2 / 82.0 / 72.4 %, T 6 74.3 / 69.0 / 82.5 / 71.3 %;
# the noise, the plane's misfit and the ring's size no better.
# _FILL_REL 0.12 and 0.25: models 71.4 and 66.7 %, views 69.4 % with each.
# Measured, not kept (2026-12-01, twenty-sixth session; the same four sets and order):
# _SMOOTH 150: 72.8 / 70.9 / 82.3 / 73.3 % (pooled RMS 0.0885 -> 0.0899, 0.1609 -> 0.1637,
# 0.1420 -> 0.1460, 0.1694 -> 0.1709); _SMOOTH 20: models 66.0 %, views 68.7 %; 400: 69.4 /
# 69.1 %. The mean of the fills with _FILL_REL 0.12, 0.18 and 0.3: models 72.8 % (pooled
# 0.0869), views 69.4 %. A ring not curved (below) filled within its own height range over
# its plane (the spline clamped there): models 69.4 % (airplane1 seed 9's crest at the
# rim 0.342 -> 0.147 %, but three domes of the bone views 0.06-0.12 -> 0.55-0.59 %), views
# 68.7 %; the better of it and the spline per hole (an oracle) 73.5 % on the models.
# Where the fill loses to Poisson it is mostly offset, not rough (`scripts/hole_offsets.py`;
# bunny and model views seeds 0-9, dev scans seeds 0-19): over the holes it loses, the
# median of its truth points' mean signed distance to the fill over their RMS, |mean| /
# RMS, is 0.55 / 0.63 / 0.57 (bunny views / model views / dev scans; Poisson's 0.30 / 0.38 /
# 0.34 on the same holes), the fill in front of the truth (towards the scanner) on 73 / 67
# / 68 % of them; with each hole's own mean offset taken out it would be below Poisson on
# 84 / 82 / 87 % of the holes, and the surface halfway between it and Poisson's (per truth
# point, the mean of the two signed distances) on 80 / 79 / 86 %. The offset is not the
# spline's bulge over a harmonic membrane through the rim (a one-off harness, not in
# scripts/: correlation -0.08 / -0.15 over the holes of the bunny / model views;
# shrinking the fill a fifth of the way to it, judged by the holes' mean offsets, 72.5 %
# of the bunny views' holes, 55.1 % of the models'), nor the smoothing spline's own offset
# at the rim: the fill shifted by the spline's mean residual over the ring's innermost
# 30 % (by distance to the hole's centre): 71.4 % (pooled 0.0885 -> 0.0878) / 71.3 %
# (0.1609 -> 0.1611); its innermost 15 %: models 71.4 % (0.0870).
# Nor would a screened Poisson surface of the punched scan give it cheaply (2026-12-01,
# twenty-seventh session; model views, the fill's new vertices moved along the view ray
# halfway to the plane of their closest point on it; below Poisson on / pooled RMS, as now
# 71.4 % / 0.0885): Poisson at depth 9, the reference's own settings, 78.2 % / 0.0767, but
# that run alone costs what the reference does; depth 7 (1.1-2.5 s on these scans) 69.4 % /
# 0.0778; depth 6 41.5 % / 0.0971; a Poisson surface per hole of the scan points within 1.5
# hole sizes of its centre at depth 9's voxel, 66.7 % / 0.0913 (alone: 36.1 % / 0.1475; a
# voxel twice as large, 39.5 % / 0.1415). Averaging with a second estimator lowers the
# pooled RMS; the share it gains at depth 9 is its closeness to the surface it is judged by.
# Where a ring's surface turns steeply away from the ring's plane (nv060 seed 2 of a second
# set of views, `synth_views.py --view-set second`: a hole of 11 % of the diagonal, filled
# with a dome a third of its size high, 1.007 % RMS), the ring's points whose scan normal
# meets the plane's normal at a cosine under 0.26 left out of the plane and the splines
# (unless half the ring; 2026-12-01, twenty-seventh session): that hole 0.092 %, bun000
# seed 13 0.609 -> 0.454 %, two of airplane2's holes 0.30 / 0.34 -> 0.05 / 0.11 %, but
# other holes rose: bun090 seeds 0 and 5 0.264 / 0.409 -> 0.507 / 0.530 %, syn_chin seed 9
# 0.386 -> 0.566 %; model views 72.8 % (pooled 0.0821), bunny views 70.6 % (0.1639), dev
# seeds 0-9 81.8 % (0.1449, two holes above 0.5 %), seeds 10-19 74.9 % (0.1644, one). A
# cosine of 0.1: nv060's hole 0.156 %; of 0: 0.976 % (its points turn steeply, few over).
# Only the low-facing points with a point of the rest within 6 spacings in the plane 3
# spacings higher or lower (a fold, not a steep sheet): the same holes changed, models
# 72.1 % (0.0833), views 70.6 % (steep sheets have such neighbours too).
_CURVED = 2.0
_CURVED_MIN = 40
_MIN_NZ = 0.15
_FLAT = 0.5
_FILL_REL = 0.18
_SMOOTH = 60.0
_NOISE_K = 16
#: A view ray's secant search for the ring's surface (compiled, ray by ray: through
#: scipy's spline it took 2.1 s of fill-holes on a Kinect frame, compiled 1.2 s on one
#: thread) stops once it is this close to it (x hole size); a ray that ends farther than
#: _RAY_MISSED x the hole size missed it.
_RAY_DONE = 1e-10
_RAY_MISSED = 1e-6


def _ring_noise(uv: np.ndarray, h: np.ndarray) -> float:
    """Noise variance of heights ``h`` over ``uv``: residuals of local quadratic fits.

    Each point's height against the value at it of a least-squares quadratic through
    its ``_NOISE_K`` nearest neighbours (itself among them); a robust variance of those
    residuals (median of squares / 0.455, scaled by k / (k - 6) for the fit's degrees
    of freedom). 0 for a ring too small to tell or a non-finite result.
    """
    k = _NOISE_K
    if len(uv) <= 2 * k:
        return 0.0
    _, nb = cKDTree(uv).query(uv, k=k)
    d = uv[nb] - uv[:, None, :]
    d /= np.maximum(np.abs(d).max(axis=(1, 2)), 1e-300)[:, None, None]  # conditioning
    X = np.stack([np.ones(d.shape[:2]), d[..., 0], d[..., 1], d[..., 0] ** 2,
                  d[..., 0] * d[..., 1], d[..., 1] ** 2], axis=-1)
    xtx = np.einsum("nki,nkj->nij", X, X)
    xtx += 1e-9 * np.trace(xtx, axis1=1, axis2=2)[:, None, None] * np.eye(6)
    fit = np.linalg.solve(xtx, np.einsum("nki,nk->ni", X, h[nb])[..., None])[:, 0, 0]
    s2 = float(np.median((h - fit) ** 2)) / 0.455 * k / (k - 6)
    return s2 if np.isfinite(s2) else 0.0


def _curved(uv: np.ndarray, h: np.ndarray, noise: float) -> bool:
    """Whether one quadratic fits the ring's heights within :data:`_CURVED` x its noise.

    ``noise``: the variance of ``h``'s noise (:func:`_ring_noise`). Such a ring is a smooth
    curved surface (a shaft, a dome): the quintic spline carries its curvature into the
    hole (:func:`~asrbf_mesh._holes_kernels.thin_plate`, ``quintic``).
    """
    if len(uv) < _CURVED_MIN or not noise > 0.0:
        return False
    X = np.column_stack([np.ones(len(uv)), uv, uv[:, 0] ** 2, uv[:, 0] * uv[:, 1],
                         uv[:, 1] ** 2])
    coef = np.linalg.lstsq(X, h, rcond=None)[0]
    return bool(np.sqrt(np.mean((h - X @ coef) ** 2)) < _CURVED * np.sqrt(noise))


def _plane_depth(ctx: Ctx, ring: np.ndarray, centre: np.ndarray, size: float):
    """Depth at view-plane points of a thin plate over the ring's own best-fit plane.

    The ring's points (view-frame xyz) are expressed as heights ``h(u, v)`` over their
    principal plane, a thin-plate spline is fitted there, and each query point's depth is
    the ``z`` where the view ray through it meets that surface
    (:func:`~asrbf_mesh._holes_kernels.ray_depths`).
    Returns None when the plane is seen too obliquely for the ray to meet it well or the
    ring too curved to have one; the callable returns NaN where the ray did not meet it.
    """
    ring = _thin_out(ring, ctx.xy, _RING_MAX)
    P = np.column_stack([ctx.xy[ring], ctx.depth[ring]])
    c = P.mean(axis=0)
    _, sv, vt = np.linalg.svd(P - c, full_matrices=False)
    if sv[2] > _FLAT * sv[0]:
        return None
    axes, n = vt[:2], vt[2]
    if n[2] < 0:
        n = -n
    if n[2] < _MIN_NZ:
        return None
    uv = (P - c) @ axes.T
    h = (P - c) @ n
    noise = _ring_noise(uv, h)
    smoothing = _SMOOTH * len(uv) * noise * ctx.spacing ** 2 / size ** 4
    spline = _hk.thin_plate(uv / size, h / size, smoothing, _CUBIC,
                            quintic=_curved(uv / size, h / size, noise / size ** 2))
    if spline is None:  # too few points, or all on a line
        return None

    def depth(q: np.ndarray) -> np.ndarray:
        return _hk.ray_depths(q, c, axes, n, size, spline, _RAY_DONE, _RAY_MISSED)

    return depth


def close_patch(pts: np.ndarray, rim: np.ndarray, seg: np.ndarray, tris: np.ndarray,
           size: float, ctx: Ctx, cover_faces: np.ndarray, cover_tree: cKDTree,
           region: Any, ring: np.ndarray,
           substrate: bool = True) -> tuple[np.ndarray, np.ndarray, int]:
    """Finish one triangulated patch: drop what lies over the scan, orient, set depths.

    ``pts`` are the rim (scan vertices ``rim``, first) and the new interior points;
    returns (new vertex local xyz, triangles with scan ids >= 0 and new ids -1, -2, ...,
    rim edges ``seg`` left without a triangle).
    """
    if len(tris) == 0:
        return *EMPTY, len(seg)
    cen = pts[tris].mean(axis=1)
    # drop triangles over the scan itself (islands inside the hole, concave rims)
    _, cand = cover_tree.query(cen, k=min(12, cover_tree.n))
    keep = ~_hk.inside_any(cen, ctx.xy, cover_faces, cand, closed=True)
    if region is not None:
        keep &= region(cen)
    tris = tris[keep]
    if len(tris) == 0:
        return *EMPTY, len(seg)
    area = signed_areas(pts, tris)
    wrong = area < 0 if ctx.ccw else area > 0
    tris[wrong] = tris[wrong][:, [0, 2, 1]]
    te = np.sort(np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]]), axis=1)
    rim_e = np.sort(seg, axis=1).astype(np.int64)
    key = int(len(pts)) + 1  # local vertex ids: one int64 key per edge
    missing = int(np.count_nonzero(~np.isin(rim_e[:, 0] * key + rim_e[:, 1],
                                            te[:, 0].astype(np.int64) * key + te[:, 1])))
    # depths: a thin plate over the ring's plane, or the network's substrate + the rim
    # residual carried across the hole
    n_rim = len(rim)
    new_xy = pts[n_rim:]
    # at a fold the network (a height field) averages the layers: no substrate there
    cut = ctx.lowpass if substrate else np.inf
    if len(new_xy) == 0:
        new_z = np.zeros(0)
    elif ctx.blend == "harmonic":
        fnet = _lowpass(ctx.net, size, cut, ctx.substrates)
        residual = ctx.depth[rim] - fnet.evaluate(pts[:n_rim])
        new_z = (fnet.evaluate(new_xy)
                 + _harmonic(len(pts), tris, np.arange(n_rim), residual)[n_rim:])
    else:
        near, _ = cKDTree(pts[:n_rim]).query(
            ctx.xy[ring], distance_upper_bound=max(_RING * ctx.spacing, _FILL_REL * size))
        ring = ring[np.isfinite(near)] if np.isfinite(near).sum() >= 3 else ring
        new_z = np.full(len(new_xy), np.nan)
        for part_ring, part in _sides(ctx, rim, seg, ring, new_xy):
            plane = _plane_depth(ctx, part_ring, pts[:n_rim].mean(0), size)
            if plane is not None:
                new_z[part] = plane(new_xy[part])
        lost = ~np.isfinite(new_z)  # the view ray missed the ring's surface: view plane
        if lost.any():
            fnet = _lowpass(ctx.net, size, cut, ctx.substrates)
            spline = _residual_spline(ctx, ring, fnet, pts[:n_rim].mean(0), size)
            new_z[lost] = fnet.evaluate(new_xy[lost]) + spline(new_xy[lost])
    if len(new_xy):
        new_z = _within_reach(ctx, ring, size, tris, rim, new_z)
    kept = np.flatnonzero(np.isin(np.arange(n_rim, len(pts)), tris))
    order = np.full(len(pts), -1, dtype=np.int64)
    order[:n_rim] = rim
    order[n_rim + kept] = -(np.arange(len(kept)) + 1)
    return np.column_stack([new_xy[kept], new_z[kept]]), order[tris], missing


#: A fill's depths stay within its ring's depths widened by this many hole sizes (a
#: hemisphere over the hole reaches half its size). Measured on the punch protocol (dev
#: scans seeds 0-19, model and bunny views seeds 0-9): 1.0 and 0.5 changed the same 3 of
#: 791 holes' errors (bun090 seed 0's cliff hole 0.264 -> 0.430 and 0.448 %, its spike
#: had stood along the cliff); outputs with fill vertices 2 % of the diagonal past the
#: scan's depths 15 of 270 before, 12 and 4 with them.
_REACH = 0.5


def _depth_bounds(ctx: Ctx, ring: np.ndarray, size: float) -> tuple[float, float]:
    """Return the depths a hole's fill may take: its ring's, widened by :data:`_REACH` sizes.

    A surface that continues its surroundings stands no farther from them than a dome
    over the hole would. Past that the fill has left them: a view ray meeting the ring-plane
    spline of a plane seen steeply far along the ray, a network across a fold between
    two layers. On the punch protocol (seeds 0-19 of the dev scans, seeds 0-9 of the
    views) such vertices stood up to 1.8 diagonals off the scan (bun090 seed 0).
    """
    z = ctx.depth[ring] if len(ring) else np.zeros(1)
    return float(z.min()) - _REACH * size, float(z.max()) + _REACH * size


def _within_reach(ctx: Ctx, ring: np.ndarray, size: float, tris: np.ndarray,
                  rim: np.ndarray, new_z: np.ndarray) -> np.ndarray:
    """Give the new vertices out of :func:`_depth_bounds` the harmonic depths of the rest.

    The membrane over the patch's triangles through the rim's depths and the new
    depths within bounds (the maximum principle keeps it within them).
    """
    lo, hi = _depth_bounds(ctx, ring, size)
    wild = ~((new_z >= lo) & (new_z <= hi))
    if not wild.any():
        return new_z
    n_rim = len(rim)
    fixed = np.concatenate([np.arange(n_rim), n_rim + np.flatnonzero(~wild)])
    z = _harmonic(n_rim + len(new_z), tris, fixed,
                  np.concatenate([ctx.depth[rim], new_z[~wild]]))
    out = new_z.copy()
    out[wild] = np.clip(z[n_rim:][wild], lo, hi)  # (a vertex in no triangle: dropped)
    return out


#: A piece takes its own side of a hole when it holds at least this many of the hole's
#: rim vertices and of its ring's points (fewer: its points join the others' ring).
_SIDE_RIM = 4
_SIDE_RING = 12


def _sides(ctx: Ctx, rim: np.ndarray, seg: np.ndarray, ring: np.ndarray,
           new_xy: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """Split a hole's fill between the pieces its rim runs along: (ring, new vertices).

    A hole punched across an occlusion cliff (a near piece in front of a far one, no
    triangle across the jump) has a rim on both; one thin plate through both rings
    ramps across the hole, off both surfaces. Each new vertex goes to the piece of its
    nearest rim vertex and is shaped from that piece's ring alone: each side continues
    its own surface, and the triangles where the sides meet stitch them as a wall, as
    the reconstruction's walls between pieces. Pieces the rim itself joins (a rim edge
    from one to the other: the cut ran along a crease, not a jump) count as one side.
    One side: the whole ring, every vertex. ``seg`` holds the rim edges (indices into
    ``rim``).
    """
    everything = [(ring, np.arange(len(new_xy)))]
    if ctx.piece is None or len(new_xy) == 0:
        return everything
    rim_piece, ring_piece = ctx.piece[rim], ctx.piece[ring]
    ids, counts = np.unique(rim_piece, return_counts=True)
    big = [int(g) for g, c in zip(ids, counts, strict=True)
           if c >= _SIDE_RIM and np.count_nonzero(ring_piece == g) >= _SIDE_RING]
    if len(big) < 2:
        return everything
    # pieces joined by a rim edge are one side (union-find over the big pieces)
    side_of = {g: g for g in big}

    def root(g: int) -> int:
        while side_of[g] != g:
            g = side_of[g]
        return g

    for a, b in rim_piece[seg].tolist():
        if a != b and a in side_of and b in side_of:
            side_of[root(a)] = root(b)
    if len({root(g) for g in big}) < 2:
        return everything
    lut = np.arange(int(max(rim_piece.max(), ring_piece.max())) + 1)
    lut[big] = [root(g) for g in big]
    rim_piece, ring_piece = lut[rim_piece], lut[ring_piece]
    big = sorted({root(g) for g in big})
    keep = np.isin(rim_piece, big)
    _, nearest = cKDTree(ctx.xy[rim[keep]]).query(new_xy)
    side = rim_piece[keep][nearest]
    # ring points of the small pieces go with the side of their nearest big rim vertex
    _, ring_near = cKDTree(ctx.xy[rim[keep]]).query(ctx.xy[ring])
    ring_side = np.where(np.isin(ring_piece, big), ring_piece, rim_piece[keep][ring_near])
    return [(ring[ring_side == g], np.flatnonzero(side == g)) for g in big]


#: :func:`own_ring`: scan edges longer than this many spacings (3D) join no ring points:
#: a range grid's triangles across an occlusion join its layers. With edges of any
#: length, the punch protocol's dev scans (seeds 0-19) changed 16 holes' errors instead
#: of 28, and bun045 seed 1's worst hole stayed at 0.425 % RMS (0.162 % with the limit).
#: Limits of 4 and 16 spacings (2026-12-01, punch protocol, below Poisson on / pooled RMS):
#: dev seeds 0-9 82.8 % / 0.1423 and 82.8 % / 0.1421 (8: 82.8 % / 0.1420), seeds 10-19
#: 73.3 % / 0.1694 and 73.8 % / 0.1694 (8: 73.8 % / 0.1694); the bunny and model views
#: the same figures with each.
RING_EDGE = 8.0


def own_ring(ctx: Ctx, ring: np.ndarray, rim: np.ndarray) -> np.ndarray:
    """Return the points of ``ring`` on the rim's own surface, joined to a rim vertex.

    ``ring`` holds the scan points near the rim in the view plane, whatever their depth:
    where a sheet is seen in front of another (bun090's ear over the head behind it: its
    ring held points of the head 0.015 deeper), that takes points of the other layer too,
    and the fill's spline through both bends towards it. Kept: the points joined to a rim vertex by
    scan edges between points of ``ring`` and the rim, each at most :data:`RING_EDGE`
    spacings long (the triangles' vertex lists, one table per scan, cached); the whole
    ring when that keeps fewer than half of it.
    """
    if len(ring) == 0:
        return ring
    if "vertex_faces" not in ctx.cache:
        flat = ctx.faces.ravel()
        order = np.argsort(flat, kind="stable") // 3
        ptr = np.zeros(len(ctx.xy) + 1, np.int64)
        np.cumsum(np.bincount(flat, minlength=len(ctx.xy)), out=ptr[1:])
        ctx.cache["vertex_faces"] = (order, ptr)
    order, ptr = ctx.cache["vertex_faces"]
    member = np.union1d(ring, rim)
    lo, hi = ptr[member], ptr[member + 1]
    n = hi - lo
    at = np.repeat(lo - np.cumsum(n) + n, n) + np.arange(int(n.sum()))
    tri = ctx.faces[np.unique(order[at])]
    e = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    pos = np.minimum(np.searchsorted(member, e), len(member) - 1)
    ok = np.all(member[pos] == e, axis=1)
    step = np.hypot(np.linalg.norm(ctx.xy[e[:, 0]] - ctx.xy[e[:, 1]], axis=1),
                    ctx.depth[e[:, 0]] - ctx.depth[e[:, 1]])
    ok &= step <= RING_EDGE * ctx.spacing
    pos = pos[ok]
    m = len(member)
    graph = sp.coo_matrix((np.ones(len(pos)), (pos[:, 0], pos[:, 1])), shape=(m, m))
    from scipy.sparse.csgraph import connected_components

    _, comp = connected_components(graph, directed=False)
    joined = np.isin(comp, comp[np.searchsorted(member, rim)])
    keep = joined[np.searchsorted(member, ring)]
    return ring[keep] if 2 * keep.sum() >= len(ring) else ring


def ring_reach(size: float, spacing: float) -> float:
    """Radius around the rim whose scan points the residual spline sees."""
    return max(_RING * spacing, _RING_REL * size)


#: A new vertex of a view-plane patch stands at least this many spacings off the rim's
#: edges (and 0.6 off its vertices): on an exact lattice (an elevation grid's or a depth
#: camera's frame) samples sat on diagonal rim edges, 0.71 spacings from their ends,
#: and made triangles of no area (2 on a 60 x 80 grid's three voids). On the punch
#: protocol (dev scans seeds 0-9, model and bunny views seeds 0-9) 5 of 604 holes moved,
#: by 0.001 % of the diagonal at most.
_OFF_EDGE = 0.25


def fill_single(hole: Hole, ctx: Ctx) -> Patch:
    """Fill a hole as one patch of the height field."""
    rim = np.unique(hole.edges)
    local_id = {int(v): i for i, v in enumerate(rim)}
    rim_xy = ctx.xy[rim]
    seg = np.vectorize(local_id.__getitem__)(hole.edges)
    # interior samples on the scan's spacing grid, away from the rim
    g = grid_samples(rim_xy.min(0), rim_xy.max(0), ctx.spacing)
    g = g[ctx.labels_fn(g) == hole.label] if len(g) else g
    if len(g):
        dist, _ = cKDTree(rim_xy).query(g)
        # and off the rim's edges: on a lattice a sample can sit on a diagonal rim edge,
        # 0.71 spacings from its ends, and make a triangle of no area with them
        g = away_from(g[dist > 0.6 * ctx.spacing], rim_xy, seg, _OFF_EDGE * ctx.spacing)
    pts = np.vstack([rim_xy, g])
    constraints = seg
    # a bay's rim is open (its mouth): no closed polygon to triangulate
    closed = bool(np.all(np.bincount(seg.ravel(), minlength=len(rim)) % 2 == 0))
    try:
        for _ in range(5):
            # with an open rim, triangle's hole eating would empty the whole polygon: keep
            # the convex hull ("c") and let the coverage filters below remove the outside
            tris, extra = triangulate(pts, constraints, "pYQ" if closed and len(
                constraints) == len(seg) else "pcYQ")
            if len(extra) == 0:
                break
            # the rim crosses itself in the view plane: drop the crossing rim edges from the
            # constraints
            constraints = constraints[~_segments_through(pts, constraints, extra, ctx.spacing)]
        else:
            return Patch(*EMPTY, len(seg), "the rim crosses itself in the view plane")
    except Exception as exc:  # noqa: BLE001 - triangle signals bad input by exceptions
        return Patch(*EMPTY, len(seg), f"triangulation failed: {exc}")

    def region(cen: np.ndarray) -> np.ndarray:
        lab = ctx.labels_fn(cen)  # 0 where the raster calls it covered: trust the exact test
        return (lab == hole.label) | (lab == 0)

    ring = own_ring(ctx, np.unique(np.concatenate(ctx.scan_tree.query_ball_point(
        rim_xy, ring_reach(hole.size, ctx.spacing)))), rim)
    verts, tris, missing = close_patch(pts, rim, seg, tris, hole.size, ctx, ctx.faces,
                                  ctx.face_tree, region, ring)
    note = "the rim crosses itself in the view plane" if len(constraints) < len(seg) else None
    return Patch(verts, tris, missing, note)
