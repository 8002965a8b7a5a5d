"""The footprint of a scan in its view plane: what its triangles cover, what they enclose.

Shared by reconstruction (mesh only where the scan is, holes included) and hole
filling (tell holes from the outer border).
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
from scipy import ndimage

from . import _holes_kernels as _hk
from ._grid_knn import nearest_feature
from ._outliers import isolated_points
from ._triangle import delaunay, squared_edges
from .errors import ScanError

__all__ = ["Footprint", "lattice_faces", "point_cloud_faces", "signed_areas"]


def signed_areas(xy: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """Twice the signed area of each triangle in the plane (> 0: counter-clockwise), (F,)."""
    p = xy[tris]
    return ((p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1])
            - (p[:, 2, 0] - p[:, 0, 0]) * (p[:, 1, 1] - p[:, 0, 1]))


#: :func:`point_cloud_faces`: a cloud whose median Delaunay edge exceeds this many
#: sampling spacings is sampled irregularly (an airborne LiDAR tile), and its long edges
#: are measured against that median edge.
IRREGULAR = 1.6
#: :func:`point_cloud_faces`: triangles sampled for the median Delaunay edge.
_EDGE_SAMPLE = 20_000


def point_cloud_faces(xy: np.ndarray, spacing: float, *, max_edge: float = 2.5) -> np.ndarray:
    """Triangulate a bare point cloud's footprint: Delaunay in xy without long edges.

    Triangles with an edge longer than ``max_edge * spacing`` are dropped (an alpha
    shape in spirit), so gaps wider than a few samples stay open. ``spacing`` is the
    median nearest-neighbour distance, the grid step of a range grid's samples, where
    the median Delaunay edge is about as long; of points strewn at random (a LiDAR
    tile) the median Delaunay edge is about 2.3 times that, and about half the edges
    were longer than 2.5 spacings: a 100,000-point tile fell apart into 8,053 pieces.
    Where the median edge exceeds :data:`IRREGULAR` spacings, edges are measured
    against it instead. Points that span no area (fewer than 3, or all on one line)
    give no triangles.
    """
    tris = delaunay(xy)
    if len(tris) == 0 or not np.isfinite(max_edge * spacing):
        return tris
    e2 = squared_edges(xy, tris)  # as delaunay() measures them: the same triangles
    some = np.unique(np.linspace(0, len(tris) - 1, min(len(tris), _EDGE_SAMPLE)).astype(np.int64))
    median = float(np.sqrt(np.median(np.concatenate([e[some] for e in e2]))))
    scale = median if median > IRREGULAR * spacing else spacing
    top = (max_edge * scale) ** 2
    return tris[(e2[0] <= top) & (e2[1] <= top) & (e2[2] <= top)]


#: :func:`lattice_faces`: points sampled to find the lattice's steps.
_LATTICE_SAMPLE = 4096
#: :func:`lattice_faces`: a coordinate is on the lattice within this share of a step.
_LATTICE_TOL = 1e-3
#: :func:`lattice_faces`: the points must fill at least this share of the lattice's box.
_LATTICE_FILL = 0.25
#: :func:`lattice_faces`: the longer step at most this many times the shorter (beyond,
#: a Delaunay triangulation without edges over 2.5 spacings would leave its cells open).
_LATTICE_ASPECT = 1.5


def lattice_faces(local: np.ndarray) -> np.ndarray | None:
    """Triangulate (N, 3) points whose (x, y) lie on a regular lattice, as a range grid is.

    An elevation grid or a depth image saved as bare points: every (x, y) is ``(x0 + i
    dx, y0 + j dy)`` to within ``_LATTICE_TOL`` of a step, no two at one node, filling
    at least ``_LATTICE_FILL`` of the lattice's box. Each cell with four points gives two
    counter-clockwise triangles split along the diagonal with the smaller depth change,
    a cell with three one; missing points leave their cells open. None when the points
    are no such lattice (then :func:`point_cloud_faces`' Delaunay triangulation
    applies). Linear in N: 1 ms for 10,000 points and 7-16 ms for 90,000, where
    triangle's Delaunay took 13 and 103 ms (holding the GIL: a fit's frame, computed
    beside it, waited).
    """
    n = len(local)
    if n < 4:
        return None
    sample = np.linspace(0, n - 1, min(n, _LATTICE_SAMPLE)).astype(np.int64)
    ax = _lattice_index(local[:, 0], sample)
    ay = None if ax is None else _lattice_index(local[:, 1], sample)
    if ax is None or ay is None:
        return None
    (i, dx), (j, dy) = ax, ay
    nx, ny = int(i.max()) + 1, int(j.max()) + 1
    if max(dx, dy) > _LATTICE_ASPECT * min(dx, dy) or nx < 2 or ny < 2 \
            or nx * ny * _LATTICE_FILL > n:
        return None
    vid = np.full(nx * ny, -1, dtype=np.int64)
    vid[j * nx + i] = np.arange(n)
    if np.count_nonzero(vid >= 0) != n:
        return None  # two points at one node
    vid = vid.reshape(ny, nx)
    a, b = vid[:-1, :-1].ravel(), vid[:-1, 1:].ravel()  # nodes (i, j), (i + 1, j)
    c, d = vid[1:, :-1].ravel(), vid[1:, 1:].ravel()  # (i, j + 1), (i + 1, j + 1)
    ha, hb, hc, hd = a >= 0, b >= 0, c >= 0, d >= 0
    full = ha & hb & hc & hd
    z = local[:, 2]
    on_ad = np.zeros(len(a), dtype=bool)  # split along a-d (else b-c)
    f = np.flatnonzero(full)
    on_ad[f] = np.abs(z[a[f]] - z[d[f]]) <= np.abs(z[b[f]] - z[c[f]])
    abd, adc = np.column_stack([a, b, d]), np.column_stack([a, d, c])
    abc, bdc = np.column_stack([a, b, c]), np.column_stack([b, d, c])
    # counter-clockwise seen from +z: x grows with i, y with j
    return np.concatenate([abd[full & on_ad], adc[full & on_ad], abc[full & ~on_ad],
                           bdc[full & ~on_ad], bdc[~ha & hb & hc & hd],
                           adc[ha & ~hb & hc & hd], abd[ha & hb & ~hc & hd],
                           abc[ha & hb & hc & ~hd]])


def _lattice_index(t: np.ndarray, sample: np.ndarray) -> tuple[np.ndarray, float] | None:
    """Each value's index on an evenly spaced lattice of ``t``'s values and the step, or None.

    The step is the smallest gap between the sampled values (checked on every value).
    """
    u = np.unique(t[sample])
    if len(u) < 2:
        return None
    step, lo = float(np.diff(u).min()), float(t.min())
    # (a lattice filling a share of its box has at most len(t) / _LATTICE_FILL nodes a row)
    if not (step > 0 and (float(t.max()) - lo) / step < len(t) / _LATTICE_FILL):
        return None
    idx = np.rint((t - lo) / step)
    if np.abs(t - lo - idx * step).max() > _LATTICE_TOL * step:
        return None
    return idx.astype(np.int64), step


#: Mode ``surface`` still covers the holes no wider than this many sampling spacings both
#: ways (a missing sample or two, a gap of a bare cloud's triangulation): a pinhole is
#: sampling, not a hole of the surface.
PINHOLE = 4.0


@dataclass(frozen=True, eq=False)
class Footprint:
    """Raster of the xy plane: 0 where the scan's triangles cover it, else a region label.

    Regions touching the raster's margin are the outside; the others are holes.
    """

    lo: np.ndarray
    cell: float
    labels: np.ndarray
    outside: frozenset[int]

    def label_at(self, q: np.ndarray) -> np.ndarray:
        """Region label at (M, 2) xy points (0: covered; outside the raster: 0)."""
        ny, nx = self.labels.shape
        ij = np.floor((np.asarray(q) - self.lo) / self.cell).astype(np.int64)
        ok = (ij >= 0).all(1) & (ij[:, 0] < nx) & (ij[:, 1] < ny)
        out = np.zeros(len(ij), dtype=np.int64)
        out[ok] = self.labels[ij[ok, 1], ij[ok, 0]]
        return out

    def inside(self, q: np.ndarray) -> np.ndarray:
        """Whether (M, 2) xy points lie on the scan or in one of its holes (not outside)."""
        lab = self.label_at(q)
        return ~np.isin(lab, list(self.outside)) & self._in_raster(q)

    def touching(self, gx: np.ndarray, gy: np.ndarray) -> np.ndarray:
        """Cells of the grid ``gx`` x ``gy`` holding any raster cell on the scan or in a hole.

        ``(len(gy) - 1, len(gx) - 1)`` bool. Unlike testing cell centres with
        :meth:`inside`, a fragment or a strip narrower than a grid cell keeps a cell.
        """
        ny, nx = self.labels.shape
        inside = ~np.isin(self.labels, list(self.outside))
        j, i = np.nonzero(inside)
        cx = self.lo[0] + (i + 0.5) * self.cell
        cy = self.lo[1] + (j + 0.5) * self.cell
        ci = np.searchsorted(gx, cx, side="right") - 1
        cj = np.searchsorted(gy, cy, side="right") - 1
        ok = (ci >= 0) & (ci < len(gx) - 1) & (cj >= 0) & (cj < len(gy) - 1)
        keep = np.zeros((len(gy) - 1, len(gx) - 1), dtype=bool)
        keep[cj[ok], ci[ok]] = True
        return keep

    def _in_raster(self, q: np.ndarray) -> np.ndarray:
        ny, nx = self.labels.shape
        ij = np.floor((np.asarray(q) - self.lo) / self.cell).astype(np.int64)
        return (ij >= 0).all(1) & (ij[:, 0] < nx) & (ij[:, 1] < ny)

    @classmethod
    def of_points(cls, xy: np.ndarray, faces: np.ndarray | None, spacing: float, *,
                  mode: str = "scan") -> Footprint:
        """Footprint of a scan: its own triangles (``scan``, ``surface``) or a concave hull.

        ``scan`` is the triangles and the holes they enclose, ``surface`` the triangles
        alone (holes stay open, but pinholes: :data:`PINHOLE`), both from the scan's
        triangles or a tight triangulation (edges up to 2.5 x spacing) of a bare cloud.
        ``hull`` triangulates the points in xy keeping edges up to 8 x spacing (an alpha
        shape), which also bridges the scan's bays and notches.
        """
        if mode == "hull":
            faces = point_cloud_faces(xy, spacing, max_edge=8.0)
        elif faces is None or len(faces) == 0:
            faces = point_cloud_faces(xy, spacing)
        fp = cls.of(xy, faces, spacing)
        return fp.without_holes(PINHOLE * spacing) if mode == "surface" else fp

    def without_holes(self, smaller: float) -> Footprint:
        """Return this footprint with its holes outside, but those narrower than ``smaller``.

        A hole whose raster bounding box is at most ``smaller`` wide both ways (a missing
        sample or two of a range grid, a gap of a bare cloud's triangulation) stays a
        hole; every other uncovered region becomes the outside (label 1).
        """
        keep = np.zeros(int(self.labels.max()) + 1, dtype=bool)
        limit = smaller / self.cell
        for k, box in zip(range(1, len(keep)), ndimage.find_objects(self.labels), strict=False):
            if box is not None and k not in self.outside and all(
                    sl.stop - sl.start <= limit for sl in box):
                keep[k] = True
        lab = np.where(keep[self.labels], 2, np.minimum(self.labels, 1))
        return Footprint(self.lo, self.cell, lab.astype(self.labels.dtype), frozenset({1}))

    @classmethod
    def of(cls, xy: np.ndarray, faces: np.ndarray, spacing: float, *,
           bay_mouth: float | None = None) -> Footprint:
        """Rasterize the triangles at half the sampling spacing and label the gaps.

        With ``bay_mouth`` (a length), a *bay* of the outside, a region at least twice as
        wide as ``bay_mouth`` joined to the rest of the outside only through mouths
        narrower than it, gets a label of its own (not outside): a disk punched into a
        gap between two parts of the scan is then a hole to fill, while the mouth and the
        narrow channels stay outside.
        """
        cell = 0.5 * spacing
        # the raster spans the points that are not isolated: one stray point far away
        # (left out of the fit too) would otherwise blow the raster up
        stray = isolated_points(xy, workers=max(1, numba.get_num_threads()))
        box = xy[~stray] if stray.any() and not stray.all() else xy
        lo = box.min(axis=0) - 3 * cell
        n = np.ceil((box.max(axis=0) + 3 * cell - lo) / cell) + 1
        if not (np.all(np.isfinite(n)) and float(n[0]) * float(n[1]) <= 200_000_000):
            raise ScanError("the scan's footprint raster would be too large "
                            "(spacing too small?)")
        nx, ny = n.astype(int)
        cov = _hk.coverage(xy, faces, lo, cell, int(nx), int(ny))
        labels, _ = ndimage.label(~cov, structure=np.ones((3, 3), bool))
        outside = frozenset(np.unique(np.concatenate(
            [labels[0], labels[-1], labels[:, 0], labels[:, -1]])).tolist()) - {0}
        if bay_mouth is not None and outside:
            labels = _label_bays(labels, outside, 0.5 * bay_mouth / cell)
        return cls(lo, cell, labels, outside)


#: A bay is at least this many times as wide (its widest inscribed disk) as its mouth.
#: On the face map, ratio 1 made bays of the gaps between the head and the ears (a third
#: of the face's fill, 4,476 vertices, across occlusions); 2 keeps them open and still
#: fills the disks punched into those gaps.
_BAY_WIDTH = 2.0


def _label_bays(labels: np.ndarray, outside: frozenset[int], rho: float) -> np.ndarray:
    """Relabel the bays of the outside (see :meth:`Footprint.of`), probe radius ``rho`` cells.

    A probe disk of radius ``rho`` rolled in from beyond the raster reaches the open
    outside; a part of the outside where the probe fits (a *core*) but which it cannot
    reach from beyond is a bay: the uncovered cells within ``rho`` + 2 cells of that core
    and out of the probe's reach from beyond get a new label each.

    A raster of more than :data:`_COARSE_CELLS` cells finds where its bays' cores can be
    on a raster of blocks first (:func:`_bay_boxes`) and measures them in boxes around
    those places only (:func:`_bays_in_box`): the same labels as the whole raster's.
    """
    pad = int(np.ceil(rho)) + 2
    out = np.pad(_member(labels, outside), pad, constant_values=True)
    if out.all():  # nothing covered: no bay
        return labels
    found: list[tuple[np.ndarray, np.ndarray]] = []  # bay cells (flat) and their cores
    k = _block(rho)
    if out.size <= _COARSE_CELLS or k < 2:
        _bays_in_box(out, (0, 0) + out.shape, None, rho, found)
    else:
        boxes, seeds, beyond = _bay_boxes(out, rho, k)
        done: list[tuple[int, int, int, int]] = []
        for box in boxes:
            if not any(b[0] <= box[0] and b[1] <= box[1] and box[2] <= b[2] and box[3] <= b[3]
                       for b in done):
                done.append(_bays_in_box(out, box, (seeds, beyond, k), rho, found))
    if not found:
        return labels
    # a cell two boxes found has the same core in both
    cells, first = np.unique(np.concatenate([f[0] for f in found]), return_index=True)
    cores = np.concatenate([f[1] for f in found])[first]
    j, i = np.divmod(cells, out.shape[1])
    keep = (j >= pad) & (j < out.shape[0] - pad) & (i >= pad) & (i < out.shape[1] - pad)
    _, inv = np.unique(cores[keep], return_inverse=True)
    new = labels.copy()
    new[j[keep] - pad, i[keep] - pad] = int(labels.max()) + 1 + inv.ravel()
    return new


#: Rasters (padded) of more cells than this look for their bays on blocks first
#: (:func:`_bay_boxes`): the dev scans' rasters hold 0.3-0.6 million cells, a Kinect
#: frame's 16-25 million, mostly open outside (TUM desk2: its footprint took 1.5-1.9 s
#: with the bays found on the whole raster, 0.8 s on blocks of 3 x 3 and 9 boxes; desk
#: 1.0-1.3 s and 0.55 s).
_COARSE_CELLS = 4_000_000


def _block(rho: float) -> int:
    """Return the side of the blocks :func:`_bay_boxes` may use with probe radius ``rho``.

    A cell lies within ``(k - 1) / sqrt(2)`` cells of its k x k block's centre, so a
    block farther than ``D = (rho + (k - 1) sqrt(2)) / k`` blocks from every block holding
    a covered cell holds only cells where the probe fits, and the block holding the
    centre of a core's widest disk (at least ``_BAY_WIDTH rho``) is at least
    ``(2 rho - (k - 1) sqrt(2)) / k`` blocks from them: above D, with a cell to spare,
    while ``rho > 2 (k - 1) sqrt(2) + 1``. 3 for the bay mouth of fill-holes (rho 8).
    """
    for k in (3, 2):
        if rho > 2.0 * (k - 1) * np.sqrt(2.0) + 1.0:
            return k
    return 1


def _bay_boxes(out: np.ndarray, rho: float, k: int
               ) -> tuple[list[tuple[int, int, int, int]], np.ndarray, np.ndarray]:
    """Boxes of the raster ``out`` (True: outside) around every place a bay's core can be.

    On the raster of ``k`` x ``k`` blocks (outside where all their cells are), the blocks
    far enough from every block with a covered cell hold only cells where the probe fits
    (:func:`_block`); the cores of such blocks that do not reach the raster's edge and
    are wide enough hold a block of every bay's core. Returns each such core's box (row0,
    col0, row1, col1, in cells), the cells of all their blocks (the *seeds*, (S, 2) rows
    and columns) and the blocks of the cores that reach the edge (``beyond``: their cells
    are the open outside's), for :func:`_bays_in_box`.
    """
    ny, nx = out.shape
    blocks = np.pad(out, ((0, -ny % k), (0, -nx % k)), constant_values=True)
    blocks = blocks.reshape(blocks.shape[0] // k, k, blocks.shape[1] // k, k).all(axis=(1, 3))
    edt = _hk.distance_to_false(blocks)
    slack = (k - 1) * np.sqrt(2.0)
    fits = edt > (rho + slack) / k
    core, n = ndimage.label(fits, structure=np.ones((3, 3), bool))
    edge = np.unique(np.concatenate([core[0], core[-1], core[:, 0], core[:, -1]]))
    beyond = _member(core, edge) & fits
    inner = fits & ~beyond
    widest = np.zeros(n + 1)
    np.maximum.at(widest, core[inner], edt[inner])
    inner &= widest[core] >= (2.0 * rho - slack) / k
    boxes = [(sl[0].start * k, sl[1].start * k, min(sl[0].stop * k, ny), min(sl[1].stop * k, nx))
             for sl in ndimage.find_objects(np.where(inner, core, 0)) if sl is not None]
    bj, bi = np.nonzero(inner)
    dj, di = np.divmod(np.arange(k * k), k)
    seeds = np.column_stack([(bj[:, None] * k + dj).ravel(), (bi[:, None] * k + di).ravel()])
    return boxes, seeds[(seeds[:, 0] < ny) & (seeds[:, 1] < nx)], beyond


def _bays_in_box(out: np.ndarray, box: tuple[int, int, int, int],
                 coarse: tuple[np.ndarray, np.ndarray, int] | None, rho: float,
                 found: list[tuple[np.ndarray, np.ndarray]]) -> tuple[int, int, int, int]:
    """Find the bays in ``box`` of the raster ``out``; append them to ``found``.

    With ``coarse`` None, ``box`` is the whole raster. Else ``coarse`` holds what
    :func:`_bay_boxes` found (seeds, blocks beyond, block side) and ``box`` (row0, col0,
    row1, col1) grows, its margin doubling, until each core holding a seed either holds
    a cell of a block beyond (it is the open outside's) or lies inside the box with the
    window :func:`_windows` puts around it. Every bay's core holds a seed, so the cores
    that reach the box's edge are the open outside or too narrow, as on the whole
    raster, and each distance that decides is the whole raster's: the transform sees
    ``ceil(2 rho) + 2`` cells more around the box. ``found`` gets, per window, the bay
    cells (row-major flat indices) and their cores' first cells (the same: the order of
    the whole raster's core labels). Returns the box as grown.
    """
    ny, nx = out.shape
    r = int(np.ceil(2.0 * rho)) + 2  # the context that keeps distances to 2 rho exact
    m = int(np.ceil(2.0 * rho)) + 4
    grow = m
    while True:
        j0, i0 = max(box[0] - grow, 0), max(box[1] - grow, 0)
        j1, i1 = min(box[2] + grow, ny), min(box[3] + grow, nx)
        if coarse is None:
            j0, i0, j1, i1 = 0, 0, ny, nx
        whole = (j0, i0, j1, i1) == (0, 0, ny, nx)
        c0, d0 = max(j0 - r, 0), max(i0 - r, 0)
        ctx = out[c0:min(j1 + r, ny), d0:min(i1 + r, nx)]
        if ctx.all():
            return j0, i0, j1, i1
        edt = _hk.distance_to_false(ctx)[j0 - c0:j1 - c0, i0 - d0:i1 - d0]
        fits = edt > rho
        core, n = ndimage.label(fits, structure=np.ones((3, 3), bool))
        if n == 0:
            return j0, i0, j1, i1
        edge = np.concatenate([core[0], core[-1], core[:, 0], core[:, -1]])
        if coarse is not None and not whole:
            seeds, blocks, k = coarse
            ins = seeds[(seeds[:, 0] >= j0) & (seeds[:, 0] < j1) & (seeds[:, 1] >= i0)
                        & (seeds[:, 1] < i1)]
            held = np.unique(core[ins[:, 0] - j0, ins[:, 1] - i0])
            far = blocks[np.arange(j0, j1)[:, None] // k, np.arange(i0, i1)[None] // k] & fits
            edge = np.r_[edge, core[far]]  # cores holding a block beyond are beyond
            if np.isin(held, np.setdiff1d(edge, core[far])).any() or 0 in held:
                grow *= 2  # a seed's core reaches the box's edge: look farther
                continue
        beyond = np.unique(edge)
        inner = fits & ~_member(core, beyond)
        if not inner.any():
            return j0, i0, j1, i1
        # a bay is at least BAY_WIDTH times as wide as its mouth: a long gap between two
        # parts of the scan, a little wider here and there, is not one
        widest = np.zeros(n + 1)  # each core's widest inscribed disk (ndimage.maximum
        np.maximum.at(widest, core[inner], edt[inner])  # sorts every label: 3 s on a Kinect)
        inner &= widest[core] >= _BAY_WIDTH * rho
        if not inner.any():
            return j0, i0, j1, i1
        windows = _windows(np.where(inner, core, 0), m)
        if not whole and any(w[0].start == 0 and j0 > 0 or w[1].start == 0 and i0 > 0
                             or w[0].stop == j1 - j0 and j1 < ny
                             or w[1].stop == i1 - i0 and i1 < nx for w in windows):
            grow *= 2  # a core's window would reach past the box
            continue
        break
    # the bays lie within rho + 2 cells of the inner cores, and what decides them within
    # rho more: the two transforms below run on a window around each core (cores whose
    # windows overlap share one) only. A Kinect frame's raster of 16 million cells spent
    # 2.2 s on them whole, 1.2 s on one window around all its cores, 0.004 s on these
    # (two windows).
    first = np.full(n + 1, np.iinfo(np.int64).max)
    jj, ii = np.nonzero(inner)
    np.minimum.at(first, core[jj, ii], (jj + j0) * nx + (ii + i0))
    box_out = out[j0:j1, i0:i1]
    for win in windows:
        w_inner = inner[win]
        probe = fits[win] & ~w_inner  # where the probe from beyond fits
        # (with no such cell the transform would measure to a phantom one beyond the corner)
        reach = _hk.distance_to_false(~probe) <= rho if probe.any() \
            else np.zeros_like(probe)
        wj, wi = nearest_feature(w_inner)  # scipy's feature transform, bit for bit
        gj, gi = np.indices(w_inner.shape)
        dist = np.sqrt(((wj - gj) ** 2 + (wi - gi) ** 2).astype(np.float64))
        here = box_out[win] & ~reach & (dist <= rho + 2.0)
        hj, hi = np.nonzero(here)
        found.append(((hj + win[0].start + j0) * nx + hi + win[1].start + i0,
                      first[core[win][wj[hj, hi], wi[hj, hi]]]))
    return j0, i0, j1, i1


def _member(labels: np.ndarray, among) -> np.ndarray:
    """``np.isin(labels, among)`` for non-negative int labels, by a lookup table.

    ``np.isin`` sorts: on a Kinect frame's raster of 16 million cells the bays' two
    calls took 0.42 s, the tables 0.05-0.08 s.
    """
    table = np.zeros(int(labels.max()) + 1, dtype=bool)
    ids = np.fromiter(among, dtype=np.int64)
    table[ids[(ids >= 0) & (ids < len(table))]] = True
    return table[labels]


#: Most bay cores given a window each (:func:`_windows`).
_MAX_WINDOWS = 64


def _windows(cores: np.ndarray, margin: int) -> list[tuple[slice, slice]]:
    """Windows of the raster around its labelled ``cores``: each one's box grown by ``margin``.

    Boxes that overlap are merged (their union's box, grown), until none does: a cell is
    in one window at most, and a core within ``2 margin`` of another shares its window.
    Past :data:`_MAX_WINDOWS` cores (the merging is quadratic or worse), one window
    around them all.
    """
    boxes = [np.array([max(s[0].start - margin, 0), max(s[1].start - margin, 0),
                       min(s[0].stop + margin, cores.shape[0]),
                       min(s[1].stop + margin, cores.shape[1])])
             for s in ndimage.find_objects(cores) if s is not None]
    if len(boxes) > _MAX_WINDOWS:
        b = np.r_[np.min(boxes, axis=0)[:2], np.max(boxes, axis=0)[2:]]
        return [(slice(b[0], b[2]), slice(b[1], b[3]))]
    merged = True
    while merged:
        merged = False
        for i in range(len(boxes)):
            for j in range(i + 1, len(boxes)):
                a, b = boxes[i], boxes[j]
                if a[0] < b[2] and b[0] < a[2] and a[1] < b[3] and b[1] < a[3]:
                    boxes[i] = np.r_[np.minimum(a[:2], b[:2]), np.maximum(a[2:], b[2:])]
                    del boxes[j]
                    merged = True
                    break
            if merged:
                break
    return [(slice(b[0], b[2]), slice(b[1], b[3])) for b in boxes]
