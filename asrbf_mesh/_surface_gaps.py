"""Where a grid mesh stands over surface the scan does not have, and what it does there.

A coarse grid (a LOD level) meshes across depth jumps the scan leaves open: walls
between two pieces over an occlusion gap, and ramps inside one piece across a *slit*
(two sheets of the piece that meet at different depths, joined around the slit's end:
a bone's condyle over the shaft behind it, an airplane's tail plane under its wing).
:class:`Gaps` finds them; :func:`open_gaps` takes them out of a grid mesh and tears each
slit ramp into its two sheets, each ending on its own scan border.
"""

from __future__ import annotations

from functools import cached_property
from typing import Any

import numpy as np

from ._footprint import signed_areas
from ._igl import point_mesh_distance
from ._mesh import Mesh

#: A wall over an occlusion gap is open when no scan edge joins its two pieces within
#: 1.5 grid steps of it and its middle is farther from the scan than this share of its
#: height (and 1.5 grid steps, :data:`OPEN_CAP` at most). Measured on LOD level 0
#: (Metro RMS, % of the diagonal) of a synthetic bunny view from 270 degrees: every wall
#: 0.614; the distance alone at 0.35
#: 0.329, at 0.2 0.087, but at 0.2 the face map's level 0 opened where its scan has
#: steep triangles down a cliff (a border 4.7 grid steps from the scan's); the edges
#: alone 0.087, but they opened bun000's and bun045's levels where the piece map cut
#: steep scan triangles (their RMS order fell on 8 and 4 of seeds 0-9).
OPEN_SHARE = 0.2
#: ... but never farther than this many grid steps: a wall tens of grid steps tall (a chin
#: in front of the body far behind it) has scan surface within a fifth of its height
#: somewhere along it. On a synthetic bunny view from below, seed 0, the coarser levels
#: kept such a wall (levels 1-3 at 0.62-0.64 % RMS, out of order within Metro's noise);
#: capped at 6 steps 0.08 / 0.22 / 0.42 / 0.63 %. At 3 steps bun000's levels 0 and 1
#: came out of order (walls opened where its scan is closed); at 10, the view's again.
OPEN_CAP = 6.0
#: A grid triangle of one piece stands across a slit when, besides the distance test
#: above, the scan samples within 1.5 grid steps of its middle (view plane) leave a
#: depth gap over this share of its height: the two sheets and nothing between. Down a
#: steep curved surface the samples fill the depths in between, and a coarse triangle's
#: chord there stays.
SLIT_GAP = 0.5
#: ... and its middle farther from the scan than this share of its height (1.5 grid
#: steps at least, :data:`OPEN_CAP` at most), and the scan's border within 2 grid steps
#: or 2 median scan edges of it (the scan is open there: a rough spot of the face map
#: had torn its level 0 where the scan is closed). At 0.2, as for walls, airplane0's
#: level 3 kept ramps down its slit's end (Metro RMS 0.40 % against 0.09).
SLIT_SHARE = 0.1


class Gaps:
    """Tests of a grid mesh's tall triangles against the scan (local xyz and faces).

    Parameters
    ----------
    net : Network
        The model meshed (its pieces).
    local : (N, 3) float64 array
        The scan's points in the model's local frame.
    faces : (F, 3) int array
        The scan's triangles.
    step : float
        The grid's spacing, local units.
    border : (E, 2) int array, optional
        The scan's boundary edges, if the caller has them.
    """

    def __init__(self, net: Any, local: np.ndarray, faces: np.ndarray, step: float,
                 border: np.ndarray | None = None) -> None:
        self.net, self.step = net, float(step)
        self.all_local, self.faces, self.border = local, faces, border
        self.scan = Mesh(local, faces)

    # the trees are built when a test first needs them: most levels have few tall triangles

    @cached_property
    def local(self) -> np.ndarray:
        """The samples on the scan's surface (used by its triangles), local xyz."""
        return self.all_local[np.unique(self.faces)]

    @cached_property
    def xy_tree(self) -> Any:
        from scipy.spatial import cKDTree

        return cKDTree(self.local[:, :2])

    @cached_property
    def edge(self) -> float:
        """The scan's median triangle edge in the view plane."""
        e = self.all_local[self.faces[:, 1], :2] - self.all_local[self.faces[:, 0], :2]
        return float(np.median(np.hypot(e[:, 0], e[:, 1])))

    @cached_property
    def rim_tree(self) -> Any:
        """The scan's border vertices (holes' rims included), view plane."""
        from scipy.spatial import cKDTree

        from ._hole_find import boundary_edges

        border = boundary_edges(self.faces)[0] if self.border is None else self.border
        rim = np.unique(border)
        return cKDTree(self.all_local[rim, :2] if len(rim) else np.full((1, 2), np.inf))

    @cached_property
    def trees(self) -> dict[int, Any]:
        """Per pair of pieces, the view-plane midpoints of the scan edges joining them.

        Keyed by ``min * n_pieces + max`` of the two pieces.
        """
        from scipy.spatial import cKDTree

        f, loc, n = self.faces, self.all_local, self.net.n_pieces
        piece = self.net.piece_at(loc[:, :2])
        e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
        e = e[piece[e[:, 0]] != piece[e[:, 1]]]
        e = np.sort(e, axis=1)
        e = e[np.unique(e[:, 0] * len(loc) + e[:, 1], return_index=True)[1]]
        pair = np.minimum(piece[e[:, 0]], piece[e[:, 1]]) * n + np.maximum(
            piece[e[:, 0]], piece[e[:, 1]])
        mid = 0.5 * (loc[e[:, 0], :2] + loc[e[:, 1], :2])
        return {int(k): cKDTree(mid[pair == k]) for k in np.unique(pair)}

    def __call__(self, middle: np.ndarray, height: np.ndarray, a: np.ndarray,
                 b: np.ndarray, distance: np.ndarray | None = None) -> np.ndarray:
        """Whether the scan is open where each triangle stands: (M,) bool.

        ``middle``: each triangle's middle (view-plane centroid, half way up; local
        xyz); ``height``: its depth span; ``a``, ``b``: the smallest and largest piece
        among its vertices (equal inside one piece). Down a cliff the scan meshes with
        steep triangles: they join the two pieces, and a wall beside them stands for
        them (its middle within about a grid step of the scan). Across an occlusion gap
        the scan is open: no scan edge joins the pieces there, and the nearest scan
        surface to the wall's middle is a piece's border, half its height away. Open:
        both (:data:`OPEN_SHARE`). Inside one piece: far from the scan, by its border,
        across a slit (:data:`SLIT_SHARE`, :data:`SLIT_GAP`). ``distance``: each
        middle's distance from the scan, if known.
        """
        step = self.step
        if distance is None:
            distance = point_mesh_distance(middle, self.scan)
        share = np.where(a == b, SLIT_SHARE, OPEN_SHARE)
        out = distance > np.maximum(np.minimum(share * height, OPEN_CAP * step), 1.5 * step)
        one = np.flatnonzero(out & (a == b))
        if len(one):  # a slit is open: the scan's border passes it
            rim = self.rim_tree.query(middle[one, :2], distance_upper_bound=max(
                2.0 * step, 2.0 * self.edge))[0]
            out[one[~np.isfinite(rim)]] = False
            one = one[np.isfinite(rim)]
        for i, near in zip(one, self.xy_tree.query_ball_point(middle[one, :2], 1.5 * step),
                           strict=True):
            lo, hi = middle[i, 2] - 0.5 * height[i], middle[i, 2] + 0.5 * height[i]
            z = np.sort(np.clip(self.local[near, 2], lo, hi))
            out[i] = np.diff(np.concatenate([[lo], z, [hi]])).max() > SLIT_GAP * height[i]
        key = np.minimum(a, b) * self.net.n_pieces + np.maximum(a, b)
        for k in np.unique(key[out & (a != b)]):
            tree = self.trees.get(int(k))
            if tree is not None:
                at = np.flatnonzero(out & (key == k))
                near = tree.query(middle[at, :2], distance_upper_bound=1.5 * step)[0]
                out[at] = ~np.isfinite(near)
        return out

    def onto_samples(self, v: np.ndarray, miss: float) -> np.ndarray:
        """Give vertices on a scan sample's place the sample's depth where they miss it.

        ``v``: (M, 3) local xyz; a vertex on a sample's view-plane place (within 1e-9
        grid steps) missing its depth by over ``miss`` takes it; the others stay.
        """
        d, j = self.xy_tree.query(v[:, :2])
        z = self.local[j, 2]
        out = v.copy()
        on = (d <= 1e-9 * self.step) & (np.abs(v[:, 2] - z) > miss)
        out[on, 2] = z[on]
        return out

    def torn(self, tri: np.ndarray) -> np.ndarray:
        """Slit ramps ``tri`` ((M, 3, 3) local xyz) torn into their two sheets: (2M, 3, 3).

        The largest depth gap between a ramp's vertices splits them into two sheets. Each
        sheet keeps its own vertices; the other's give way to the scan samples of this
        sheet's depths (within half the gap) nearest them in the view plane, within 2
        grid steps: the sheet then ends on its own scan border. NaN where none lies there.
        """
        z = tri[:, :, 2]
        order = np.argsort(z, axis=1, kind="stable")
        zs = np.take_along_axis(z, order, axis=1)
        split = np.where(zs[:, 1] - zs[:, 0] > zs[:, 2] - zs[:, 1], 1, 2)  # first upper one
        gap = np.take_along_axis(zs, split[:, None], 1)[:, 0] - np.take_along_axis(
            zs, split[:, None] - 1, 1)[:, 0]
        upper = np.take_along_axis(np.arange(3)[None, :] >= split[:, None], np.argsort(
            order, axis=1), axis=1)  # each vertex: on the upper sheet
        out = np.repeat(tri[:, None], 2, axis=1)  # (M, 2 sheets: lower, upper, 3, 3)
        near = self.xy_tree.query_ball_point(tri[:, :, :2].reshape(-1, 2), 2.0 * self.step)
        for i in range(len(tri)):
            for sheet in (0, 1):
                own = upper[i] == bool(sheet)
                lo = z[i, own].min() - 0.5 * gap[i]
                hi = z[i, own].max() + 0.5 * gap[i]
                for c in np.flatnonzero(~own):
                    cand = np.asarray(near[3 * i + c], dtype=np.int64)
                    cand = self.local[cand[(self.local[cand, 2] >= lo)
                                           & (self.local[cand, 2] <= hi)]]
                    out[i, sheet, c] = cand[np.argmin(np.sum(
                        (cand[:, :2] - tri[i, c, :2]) ** 2, axis=1))] if len(cand) else np.nan
        return out.reshape(-1, 3, 3)


def open_gaps(local_v: np.ndarray, faces: np.ndarray, is_wall: np.ndarray,
              piece: np.ndarray, wall_max: float, gaps: Gaps | None
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return a grid mesh's triangles without those standing over open scan.

    Walls taller than ``wall_max`` (local depth units) where ``gaps`` finds the scan
    open are left out (without ``gaps``, every such wall). A grid triangle of one piece
    as tall across a slit (its middle, or a point half way from it to a corner, far
    from the scan, by its border and between the slit's sheets) is torn into two, one per
    sheet (:meth:`Gaps.torn`): each sheet ends on its own scan border instead of
    ramping to the other. A torn triangle that would turn over or shrink to a sliver
    (under 1/1000 of the grid triangle's area) is left out.

    Returns
    -------
    faces : (F', 3) int64 array
        Indices into ``local_v`` followed by the new points.
    points : (M, 3) float64 array
        The new vertices (scan samples, local xyz).
    piece : (M,) int64 array
        Their pieces.
    """
    none = (np.zeros((0, 3)), np.zeros(0, np.int64))
    height = np.ptp(local_v[faces, 2], axis=1)
    tall = height > wall_max
    if gaps is None or not tall.any():
        return faces[~(tall & is_wall)], *none
    w = local_v[faces[tall]]  # each triangle's middle: half way up
    middle = np.column_stack([w[:, :, :2].mean(axis=1),
                              0.5 * (w[:, :, 2].min(axis=1) + w[:, :, 2].max(axis=1))])
    a, b = piece[faces[tall]].min(axis=1), piece[faces[tall]].max(axis=1)
    # a ramp may pass a steep scan surface near its middle: also its parts half way from
    # its centroid to each corner; every distance from one search of the scan's triangles
    one = np.flatnonzero(~is_wall[tall])
    part = 0.5 * (w[one].mean(axis=1)[:, None] + w[one])  # (n, 3 corners, 3)
    dist = point_mesh_distance(np.concatenate([middle, part.reshape(-1, 3)]), gaps.scan)
    out = gaps(middle, height[tall], a, b, distance=dist[:len(middle)])
    dist = dist[len(middle):].reshape(-1, 3)
    one, dist, part = one[~out[one]], dist[~out[one]], part[~out[one]]
    for corner in range(3):
        out[one] |= gaps(part[:, corner], height[tall][one], a[one], b[one],
                         distance=dist[:, corner])
    tall[tall] = out
    ramp = np.flatnonzero(tall & ~is_wall)
    kept = faces[~tall]
    if not len(ramp):
        return kept, *none
    old = local_v[faces[ramp]]
    tri = gaps.torn(old)
    before = np.repeat(signed_areas(local_v[:, :2], faces[ramp]), 2)
    area = signed_areas(tri.reshape(-1, 3)[:, :2], np.arange(3 * len(tri)).reshape(-1, 3))
    # kept: every corner found, the same turn as the grid triangle's, not a sliver
    ok = np.isfinite(tri).all(axis=(1, 2)) & (area * np.sign(before) > 1e-3 * np.abs(before))
    tri = tri[ok]
    n = len(local_v)
    own = np.repeat(faces[ramp], 2, axis=0)[ok]
    same = np.all(tri == np.repeat(old, 2, axis=0)[ok], axis=2)  # corners kept as they were
    new = np.flatnonzero(~same.ravel())
    torn = own.ravel().copy()
    torn[new] = n + np.arange(len(new))
    piece_new = np.repeat(np.repeat(piece[faces[ramp]].min(axis=1), 2)[ok], 3)[new]
    return (np.concatenate([kept, torn.reshape(-1, 3)]), tri.reshape(-1, 3)[new],
            piece_new.astype(np.int64))
