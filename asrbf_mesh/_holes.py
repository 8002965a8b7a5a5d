"""Hole filling of range scans from a fitted network.

A scan's triangles cover part of the xy plane of its view frame. What they leave
uncovered splits into the *outside* (the region connected to the far margin:
everything beyond the scan's outer border) and *holes* (uncovered regions the
scan surrounds). The border is never filled: holes are told from it by this
footprint, not by loop length. A *bay* of the outside, wider than :data:`BAY_MOUTH`
spacings behind a narrower mouth (a hole punched through the border or into the gap
between two parts of the scan), is filled up to its mouth; the mouth stays open.

Each hole selected by size is filled without touching the scan: new vertices
inside the hole at the scan's own spacing (or its rim's, where the scan is sampled more
coarsely: :data:`LOCAL_SPACING`), a constrained triangulation in xy
(``triangle``, with no extra vertex on the hole's boundary so the rim edges are
shared exactly), depths from a spline of the scan points around the rim (the mean of
a thin-plate and a cubic polyharmonic spline), fitted over the ring's own best-fit
plane; where that plane is seen too obliquely or
the ring is too curved for one, from the network's low-frequency substrate (its
neurons at least as wide as the hole) plus the scan's residual ``z - f`` around the rim
carried across the hole by a thin-plate spline (:mod:`asrbf_mesh._hole_patch`). Either
way there is no step at the seam, and the slope and curvature of the surroundings
continue into the fill.

Where the surface folds over itself (an occlusion: an ear in front of the head), a
hole's rim runs over two layers of surface; each layer is then filled on its own, up
to the fold, from its own surroundings.

The steps live in their own modules: finding the holes in :mod:`asrbf_mesh._hole_find`,
building one hole's patch in :mod:`asrbf_mesh._hole_patch`, filling it layer by layer at
a fold in :mod:`asrbf_mesh._hole_layers`; this module runs them over every hole and
reports. Punched holes with ground truth are on the evaluation side
(:func:`asrbf_mesh.evaluate.punch_holes`).

References
----------
Meng et al. (2013), section 4.1: holes "convincingly restored" by evaluating the
network over them.
"""

from __future__ import annotations

import dataclasses
import functools
import os
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from ._footprint import point_cloud_faces, signed_areas
from ._forked import map_forked
from ._frame import sampling_spacing
from ._hole_camera import camera_frame, fill_in_camera
from ._hole_close import (
    _KEY,
    _agree_with_scan,
    _edge_keys,
    _edge_parts,
    _EdgeSet,
    _fill_cycles,
    _fill_fallback,
    _fits,
    _in_sorted,
    _Parts,
    _rim_keys,
    _rim_keys_of,
    _winds_as_hole,
    close_gaps,
)
from ._hole_find import Hole, boundary_edges, find_holes, usable_faces_warned
from ._hole_layers import fill_layers
from ._hole_patch import BLENDS, Ctx, Patch, fill_single
from ._hole_refill import refill_crossed
from ._hole_wall import close_wall, fill_across_wall
from ._mesh import Mesh, Scan
from ._network import Network
from ._validate import check_choice, check_float, check_points, check_seed, parse_length
from .errors import ConfigError, ScanError

__all__ = ["BAY_MOUTH", "BLENDS", "FillResult", "HoleInfo", "fill_holes", "find_holes"]

#: A bay of the outside (a region at least twice as wide as this many spacings, joined to
#: the rest of the outside only through narrower mouths: a hole punched into an occlusion
#: gap between two parts of the scan) is filled like a hole, up to its mouth; the mouth
#: and narrower channels stay open. Measured on the punch protocol (seeds 0-9), pooled RMS
#: over its enclosed holes, % of the diagonal, without bays -> 8 spacings: face 0.614 ->
#: 0.421 (seed 2's bite into the ear gap 1.95 -> 0.67), bun090 0.377 -> 0.368, bun180
#: 0.221 -> 0.221; 4 and 6 spacings left the face at 0.600 and 0.499, 12 at 0.451.
BAY_MOUTH = 8.0


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
        The network that gave the depths (with ``frame="camera"``, of the camera frame's
        coordinates, :mod:`~asrbf_mesh._hole_camera`).
    frame : {"view", "camera"}
        Where the holes were filled: the view plane, or a depth camera's projective frame.
    """

    mesh: Mesh
    holes: tuple[HoleInfo, ...]
    border_edges: int
    seconds: float
    network: Network = field(repr=False)
    frame: str = "view"

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
                "seconds": self.seconds, "frame": self.frame,
                "holes": [h.__dict__ | {"centre": list(h.centre)} for h in self.holes]}


#: A hole whose rim edges are longer in the view plane than this many scan spacings
#: (their median) is filled at its rim's own spacing, not the scan's: the scan is
#: sampled that much more coarsely around it (a perspective depth frame's far range:
#: the rims of Kinect frame desk in metric coordinates, whose spacing is its near
#: range's, are 1.1-25 spacings, median 5.7), and the fill's triangles match the sampling around
#: them. A uniformly sampled scan's rims are 1.0-1.4 spacings: filled at the scan's
#: spacing.
LOCAL_SPACING = 2.5
#: ... when the rim has at least this many edges: a missing triangle or two (3-6 rim
#: edges, up to 5.6 spacings long on the bunny scans) says little about the sampling.
LOCAL_RIM_EDGES = 8


def _hole_spacing(rim_xy: np.ndarray, spacing: float) -> float:
    """Return the sample spacing of a hole's fill: its rim edges' median, or the scan's.

    ``rim_xy`` (E, 2, 2) holds the rim edges' ends in the view plane; see
    :data:`LOCAL_SPACING`.
    """
    if len(rim_xy) < LOCAL_RIM_EDGES:
        return spacing
    rim = float(np.median(np.linalg.norm(rim_xy[:, 0] - rim_xy[:, 1], axis=1)))
    return rim if rim > LOCAL_SPACING * spacing else spacing


def _fill_one(hole: Hole, ctx: Ctx) -> tuple[Patch, str | None]:
    """Fill one hole; returns the patch and why it is not closed (None if it is)."""
    spacing = _hole_spacing(ctx.xy[hole.edges], ctx.spacing)
    if spacing != ctx.spacing:
        ctx = dataclasses.replace(ctx, spacing=spacing)
    patch = fill_single(hole, ctx)
    layered = fill_layers(hole, ctx)  # the rim on two layers (a fold, a cliff): each alone
    if layered is not None:  # with the wall between closed, else where one patch cannot
        walled = close_wall(hole, layered, ctx)
        patch = walled or (layered if layered.missing < patch.missing else patch)
    if not patch.missing:
        return patch, None
    why = f" ({patch.note})" if patch.note else ""
    if len(patch.tris) == 0:
        return patch, f"nothing could be filled{why}"
    return patch, f"{patch.missing} rim edges could not be closed{why}"


def _fill_job(state: tuple[list[Hole], Ctx], i: int) -> tuple[Patch, str | None]:
    """Fill hole ``i`` of ``state`` (the holes, the context): a job of :func:`map_forked`."""
    holes, ctx = state
    return _fill_one(holes[i], ctx)


def _loop_job(state: tuple[np.ndarray, np.ndarray, cKDTree],
              job: tuple[np.ndarray, float]) -> tuple[np.ndarray, np.ndarray, str | None]:
    """Fill one loop at its spacing in its rim's plane: a job of :func:`map_forked`."""
    from ._hole_loops import fill_loop

    vertices, scan_points, tree = state
    loop, step = job
    return fill_loop(loop, vertices, step, scan_points, tree)


def _as_scan(scan: Any) -> Scan:
    """Return the scan to fill: a Scan as it is, a Mesh as its vertices and faces, or points."""
    if isinstance(scan, Scan):
        return scan
    if isinstance(scan, Mesh):
        return Scan(scan.vertices, scan.faces)
    if isinstance(scan, (str, os.PathLike)):
        raise ScanError(f"scan must be a Scan, a Mesh or an (N, 3) array of points, got the "
                        f"path {os.fsdecode(scan)!r}: load it with load_scan")
    return Scan(check_points(scan, "scan"))


def _close_loops(vertices: np.ndarray, faces: np.ndarray, infos: list[HoleInfo],
                 rims: list[set[int]], hole_keys: np.ndarray, ccw: bool,
                 scan_points: np.ndarray, R: np.ndarray, spacing: float,
                 limit: float | None, diag: float, big_keys: np.ndarray | None = None,
                 owners: list[np.ndarray] | None = None, only: np.ndarray | None = None,
                 wall: Any = None) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
    """Fill the enclosed boundary loops the view-plane fills left open (in their own plane).

    Updates ``infos`` in place: a hole whose rim the loop shares becomes filled; a loop
    no view-plane hole covered (its region ran into the outside in the projection) is
    added as a new hole. A fill that would reuse an edge the mesh already has (a chord
    between two rim vertices that are neighbours across the surface) is refused: the
    mesh stays manifold. Returns the vertices, the faces and each part's outer border
    (a loop of vertex ids).

    A gap the patches left where a hole's rim touches the outer border at a vertex is
    walked as part of that border; the border's cycle is cut at such pinches
    (:func:`~asrbf_mesh._hole_loops.simple_cycles`) and a cycle cut off it is filled when
    it holds a rim edge of an enclosed hole still open (``hole_keys``, sorted edge keys)
    and winds as a hole does in the view plane (against the triangles, ``ccw``: their
    orientation there): a cycle winding with them is the border of a blob pinched to the
    rest (a fragment of a depth frame's far range), not a gap. Kinect frame desk2: its
    one hole left open, 2 of 8 rim edges, was such a gap. With ``only`` (sorted edge
    keys), only the loops holding one of those edges are filled (a second pass). With
    ``owners``, the index in ``infos`` of the hole each added face fills is appended
    there, one array per fill.
    """
    from ._hole_loops import outer_loops, simple_cycles, split_loops

    outer, loops = split_loops(faces, len(vertices))
    parts = _Parts(faces)  # blob or gap, where the winding cannot tell
    for border in outer:
        cut = sorted(simple_cycles(border), key=len)[:-1]  # the longest stays the border
        loops += [c for c in cut if _in_sorted(_rim_keys(c), hole_keys).any()
                  and (_winds_as_hole(vertices[c] @ R, ccw) or parts.is_gap(c))]
    tree = cKDTree(scan_points)
    keys, count = np.unique(_edge_keys(faces), return_counts=True)
    known = _EdgeSet(keys)  # every edge of the mesh and of the fills added so far
    boundary = keys[count == 1]
    new_v: list[np.ndarray] = [vertices]
    new_f: list[np.ndarray] = [faces]
    n = len(vertices)
    # the loops to fill and their spacings; their first fills computed together (forked)
    # a triangle whose three edges are all boundary is a fragment of its own, joined to
    # the rest at its corners at most: its border is no hole (closed by its own reverse
    # it was a triangle twice over, in an unwelded mesh next to every fill)
    lone = faces[_in_sorted(_edge_keys(faces), boundary).reshape(3, -1).all(axis=0)]
    lone = {tuple(t) for t in np.sort(lone, axis=1).tolist()}
    loops = [loop for loop in loops if len(loop) >= 3  # else a pinched vertex, not a hole
             and _in_sorted(_rim_keys(loop), boundary).all()  # a cycle of boundary edges
             and (only is None or _in_sorted(_rim_keys(loop), only).any())
             and not (len(loop) == 3 and tuple(sorted(loop.tolist())) in lone)]
    sizes, steps = [], []
    for loop in loops:
        local = (vertices[loop] @ R)[:, :2]
        sizes.append(float(np.linalg.norm(np.ptp(local, axis=0))))
        steps.append(_hole_spacing(np.stack([local, np.roll(local, -1, axis=0)], 1), spacing))
    # a loop along a hole left open for its size is part of it (what is left of a large
    # hole split into its bays: :func:`~asrbf_mesh._hole_find.find_holes`), as large
    big = np.zeros(0, np.int64) if big_keys is None else big_keys
    large = [(limit is not None and size > limit) or bool(_in_sorted(_rim_keys(loop), big).any())
             for loop, size in zip(loops, sizes, strict=True)]
    todo = [j for j in range(len(loops)) if not large[j]]
    firsts = dict(zip(todo, map_forked(_loop_job, (vertices, scan_points, tree),
                                       [(loops[j], steps[j]) for j in todo],
                                       cost=[len(loops[j]) for j in todo]), strict=True))
    for j, loop in enumerate(loops):
        size, step = sizes[j], steps[j]
        owner = [i for i, r in enumerate(rims) if r.intersection(loop.tolist())]
        if large[j]:
            if not owner:
                infos.append(HoleInfo(len(infos), size, 100.0 * size / diag,
                                      tuple(float(x) for x in vertices[loop].mean(axis=0)),
                                      len(loop), False,
                                      f"larger than max_hole_size ({size:.4g} > {limit:.4g} "
                                      "scan units)"))
                rims.append(set())  # rims[i] stays the rim of infos[i]
            continue
        (v, t, reason), layers = firsts[j], 1
        layered = None if wall is None else wall(loop, size, step, vertices, R=R, known=known)
        if layered is not None:  # over two layers and a wall: each on its own
            (v, t, layers), reason = layered, None
        elif not len(t) or not _fits(t, loop, known):  # refused, or no plane fill at all
            if len(np.unique(loop)) < len(loop):  # pinched: each cycle on its own
                v, t, reason = _fill_cycles(loop, vertices, step, scan_points, tree, known,
                                            R, ccw, parts)
            else:
                v, t, reason = _fill_fallback(loop, vertices, step, scan_points, tree, known)
        if len(t) == 0:
            if not owner and reason is not None:  # None: blobs pinched together, no hole
                infos.append(HoleInfo(len(infos), size, 100.0 * size / diag,
                                      tuple(float(x) for x in vertices[loop].mean(axis=0)),
                                      len(loop), False, reason))
                rims.append(set())
            continue
        t = np.where(t < 0, n - t - 1, t)
        if owners is not None:
            owners.append(np.full(len(t), owner[0] if owner else len(infos)))
        new_v.append(v)
        new_f.append(t)
        known.add(_edge_keys(t))
        n += len(v)
        if owner:
            for i in owner:  # the fill is counted once, with the hole that owns its faces
                h = infos[i]
                mine = i == owner[0]
                infos[i] = dataclasses.replace(
                    h, filled=True, reason=None,
                    vertices_added=h.vertices_added + len(v) * mine,
                    faces_added=h.faces_added + len(t) * mine,
                    layers=max(h.layers, layers) if mine else h.layers)
        else:
            infos.append(HoleInfo(len(infos), size, 100.0 * size / diag,
                                  tuple(float(x) for x in vertices[loop].mean(axis=0)),
                                  len(loop), True, None, len(v), len(t), layers))
            rims.append(set(loop.tolist()))
    faces = np.vstack(new_f)
    return np.vstack(new_v), faces, outer_loops(faces, n)


#: :func:`_leave_out_crossings`: a loop's fill that crosses the scan is a wall between two
#: layers, left out whole, when its triangles face the view by less than this (|cos| of
#: the angle between normal and view, area-weighted; the view-plane fill's own limit for
#: a plane seen too obliquely, ``_hole_patch._MIN_NZ``). On bun090 punched with seed 8 the
#: walls between its ear and head faced it by 0.02-0.10, a punched hole's loop fill by
#: 0.27: left out whole, that hole's error had risen from 0.132 to 0.209 %.
WALL_FACING = 0.15


def _leave_out_crossings(vertices: np.ndarray, faces: np.ndarray, outer: list[np.ndarray],
                         owner: np.ndarray, infos: list[HoleInfo], first: int, loops: int,
                         n_base: int, R: np.ndarray, rim_keys: list[np.ndarray], diag: float
                         ) -> tuple[np.ndarray, np.ndarray, list[np.ndarray], np.ndarray,
                                    dict[int, float]]:
    """Leave out the fill triangles that cross the scan or another fill (updates ``infos``).

    :func:`~asrbf_mesh._hole_cross.crossing_faces` finds them among the faces from
    ``first`` on (``owner``: each face's index in ``infos``, -1 for the scan's; ``R``
    turns the vertices to the view frame, where its grid lies). Only those are left out,
    but of a loop closed in its own plane or by fairing (the faces from ``loops`` on) that
    crosses and is seen edge-on (:data:`WALL_FACING`) the whole fill: a wall between two
    layers (bun090's ear and the head behind it: +2,020 vertices on a 17-vertex loop,
    296 of its triangles through the scan), where there is no surface to close. A
    view-plane patch yields only to the scan and to other patches: where it crosses a
    loop's fill, the loop's goes (Kinect frame desk meshed as its grid: 110 of its 230
    holes filled before, 155 with the rest of this). The small gaps left out
    triangles open are closed by chords where that crosses nothing
    (:func:`~asrbf_mesh._hole_close.close_gaps`). A hole is then open when its rim
    (``rim_keys``: its rim edges' keys, with its patch's for a patch the loop stage
    completed) or what its left-out patch triangles opened is open; when only a loop's
    fill credited to it is (a loop beside it, sharing a rim vertex), that gap is reported
    as a hole of its own. Vertices no face uses any more are dropped (the scan's are
    kept, as every outer border's). Returns the vertices, faces and outer borders, each
    face's owner, and the holes it opened with the share of their fills' triangles left
    out.
    """
    from ._hole_cross import crossing_faces, crossing_of

    local = vertices @ R  # R: the view frame's rotation
    bad = crossing_faces(local, faces, first)
    if len(bad) == 0:
        return vertices, faces, outer, owner, {}
    crossed = bad
    if bad[-1] >= loops:  # the whole fill of a loop that crosses, where it is a wall
        part = _edge_parts(faces[loops:])
        t = local[faces[loops:]]
        normal = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
        area = np.linalg.norm(normal, axis=1)
        facing = (np.bincount(part, weights=np.abs(normal[:, 2]))
                  / np.maximum(np.bincount(part, weights=area), 1e-300))
        walls = np.unique(part[bad[bad >= loops] - loops])
        walls = walls[facing[walls] < WALL_FACING]
        dropped = np.union1d(bad[bad >= loops], loops + np.flatnonzero(np.isin(part, walls)))
        if bad[0] < loops:  # a patch yields only to the scan and other patches: test again
            kept = np.delete(np.arange(len(faces)), dropped)
            patches = bad[bad < loops]
            again = crossing_of(local, faces[kept], np.searchsorted(kept, patches))
            crossed = np.union1d(bad[bad >= loops], patches[again])
            bad = np.union1d(dropped, crossed)
        else:
            bad = dropped
    crossing = np.bincount(owner[crossed], minlength=len(infos))  # a new face has an owner
    kept = np.delete(faces, bad, axis=0)
    keys, count = np.unique(_edge_keys(kept), return_counts=True)
    open_now = _still_open(kept, outer, (keys, count))
    left_keys = _edge_keys(faces[bad])  # the left-out triangles' edges, and whose
    order = np.argsort(left_keys, kind="stable")
    left_keys, left_owner = left_keys[order], np.tile(owner[bad], 3)[order]
    mend, key = close_gaps(local, kept, open_now, left_keys, WALL_FACING, keys)
    mended = np.zeros(len(infos), np.int64)
    kept_owner = np.delete(owner, bad)
    if len(mend):
        mend_owner = left_owner[np.searchsorted(left_keys, key)]
        np.add.at(mended, mend_owner, 1)
        kept, kept_owner = np.vstack([kept, mend]), np.r_[kept_owner, mend_owner]
        # a mend's edges: the open ones it closes, and chords two of its triangles share
        open_now = np.setdiff1d(open_now, _edge_keys(mend))
    left = np.bincount(owner[bad], minlength=len(infos))
    used = np.zeros(len(vertices), dtype=bool)
    used[:n_base] = True
    used[kept.ravel()] = True
    for loop in outer:
        used[loop] = True
    of_vertex = np.full(len(vertices), -1)
    of_vertex[faces[bad].ravel()] = np.repeat(owner[bad], 3)
    lost = of_vertex[~used]
    gone = np.bincount(lost[lost >= 0], minlength=len(infos))
    opened = []
    for i in np.flatnonzero(left).tolist():
        h = infos[i]
        why = (f"{crossing[i]:,} of its fill's triangles would cross the scan or another "
               f"fill (the surface folds over itself there): {left[i]:,} left out")
        h = dataclasses.replace(
            h, faces_added=max(h.faces_added - int(left[i]) + int(mended[i]), 0),
            vertices_added=max(h.vertices_added - int(gone[i]), 0))
        mine = bad[owner[bad] == i]  # its left-out triangles: what they opened is open yet?
        rim = rim_keys[i] if i < len(rim_keys) else np.zeros(0, np.int64)
        patch = _edge_keys(faces[mine[mine < loops]])
        gap = _in_sorted(_edge_keys(faces[mine[mine >= loops]]), open_now).any()
        if (not h.filled or _in_sorted(np.r_[rim, patch], open_now).any()
                or (gap and i >= len(rim_keys))):
            infos[i] = dataclasses.replace(h, filled=False, reason=why)
            opened.append(i)
            continue
        infos[i] = h  # closed: its own gaps mended by chords, or none
        if gap:  # open is a loop beside it the loop stage had credited to it (a shared
            # rim vertex): a gap of its own, reported so, with its own fill's counts
            theirs = mine[mine >= loops]
            why = (f"{np.count_nonzero(np.isin(theirs, crossed)):,} of its fill's triangles "
                   f"would cross the scan or another fill (the surface folds over itself "
                   f"there): {len(theirs):,} left out")
            ends = np.unique(faces[theirs])
            size = float(np.linalg.norm(np.ptp(local[ends, :2], axis=0)))
            infos.append(HoleInfo(len(infos), size, 100.0 * size / diag,
                                  tuple(float(x) for x in vertices[ends].mean(axis=0)),
                                  int(np.count_nonzero(used[ends])), False,
                                  f"a gap beside hole {i}: {why}"))
    kept_count = np.bincount(kept_owner[kept_owner >= 0], minlength=len(infos))
    opened = {i: left[i] / max(left[i] + kept_count[i], 1) for i in opened}
    if used.all():
        return vertices, kept, outer, kept_owner, opened
    slot = np.cumsum(used) - 1
    return vertices[used], slot[kept], [slot[loop] for loop in outer], kept_owner, opened


def _still_open(faces: np.ndarray, outer: list[np.ndarray],
                counted: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """Sorted keys of the boundary edges of ``faces`` that lie on no part's outer border.

    ``counted``: the faces' edge keys and how many faces each has, when known.
    """
    keys, count = counted or np.unique(_edge_keys(faces), return_counts=True)
    still_open = keys[count == 1]
    if outer:
        still_open = np.setdiff1d(still_open, np.concatenate([_rim_keys(o) for o in outer]))
    return still_open


def _open_after_all(holes: list[Hole], infos: list[HoleInfo], before: list[HoleInfo],
                    still_open: np.ndarray) -> None:
    """Mark open again the holes counted filled whose rim is still open (updates ``infos``).

    The loop stage credits a loop's fill to every hole whose rim shares a vertex with it:
    a small loop beside a hole skipped for its size, or one that closes a corner of a
    larger hole, made that hole read as filled (a punched disk joined to a scan's
    occlusion gap, 28 % of the diagonal across: "filled", 0 vertices added). A hole is
    filled when none of its rim edges is still open, but on a part's outer border; else
    it keeps the reason it had before the loop stage, or says how many edges are open.
    """
    for i, h in enumerate(holes):
        if not infos[i].filled:
            continue
        n_open = int(np.count_nonzero(_in_sorted(_rim_keys_of(h.edges), still_open)))
        if n_open:
            infos[i] = dataclasses.replace(
                infos[i], filled=False,
                reason=before[i].reason or f"{n_open} rim edges could not be closed")


def _closed_after_all(partial: dict[int, np.ndarray], infos: list[HoleInfo],
                      still_open: np.ndarray) -> None:
    """Mark filled the holes whose partial patch left no gap at the end (updates ``infos``).

    A patch is partial when triangles were dropped or it missed rim edges. The triangles
    :func:`_agree_with_scan` drops often leave nothing open: they lay over triangles the
    scan or the patch already has (a layer's patch beside a fold), or would have closed an
    edge of the outer border, which stays open anyway (bun180 punched with seed 5: 4
    triangles dropped, every rim edge of its hole shared by two faces); rim edges a patch
    missed the loop stage may close (the steep side of a synthetic cylinder). A hole is
    filled when none of its rim edges and none of its patch's edges (``partial``: their
    keys) is still open (``still_open``: :func:`_still_open`).
    """
    for i, edge_keys in partial.items():
        if not infos[i].filled and not _in_sorted(edge_keys, still_open).any():
            infos[i] = dataclasses.replace(infos[i], filled=True, reason=None)


def fill_holes(scan: Scan | Mesh | np.ndarray, net: Network | None = None, *,
               max_hole_size: str | float | None = None, blend: str = "thin-plate",
               lowpass_rel: float | None = 1.0, seed: int = 0,
               progress: bool | None = None, pieces: str | int = "auto",
               frame: str = "auto") -> FillResult:
    """Fill the holes of a range scan with the network's surface.

    Parameters
    ----------
    scan : Scan, Mesh or (N, 3) array_like
        A triangulated scan (range grid, OBJ, ...), a mesh, or a bare point cloud
        (a faceless Scan or an array of points: then its footprint is triangulated in
        xy first, see :func:`~asrbf_mesh._footprint.point_cloud_faces`).
    net : Network, optional
        A network fitted to this scan; fitted here (``seed``) when omitted.
    max_hole_size : float or str, optional
        Fill only holes whose bounding-box diagonal (in the view plane) is at most
        this length in scan units, or a percentage of the scan's bounding-box
        diagonal such as ``"5%"``. Default: every hole.
    blend : {"thin-plate", "harmonic"}
        ``"thin-plate"`` (default): a smoothing spline of the scan points within
        max(6 spacings, 0.18 x the hole size) of the rim (the mean of a thin plate and
        a cubic polyharmonic spline), over the ring's own best-fit plane, or, where
        that plane does not suit, the network's substrate plus a thin plate of the
        residual ``z - f`` in the view plane;
        ``"harmonic"``: the substrate plus a harmonic interpolation of the rim
        residuals alone (C0 only).
    lowpass_rel : float or None
        Where the substrate is used, only the neurons at least this many times as
        wide as the hole (default 1: the network's low-frequency substrate); ``None``
        keeps every neuron. Narrow neurons fit the data around a hole, and their tails
        sag into it: on punched holes of the face map the full network filled with an
        RMS error of 0.49 % of the diagonal (harmonic blend) and 0.33 % (thin plate),
        the substrate with the thin plate 0.056 % (BENCHMARKS.md, hole filling).
    seed : int
        Seed of the fit when ``net`` is omitted.
    progress : bool, optional
        Progress bar of the fit.
    pieces : "auto" or 1
        The fit made when ``net`` is omitted: one network per smooth piece (``"auto"``)
        or the paper's single network (see :func:`~asrbf_mesh.fit`).
    frame : {"auto", "view"}
        ``"auto"`` (default): a depth camera's mesh in its camera coordinates (a
        perspective view from the origin along z, which the view plane folds over) is
        filled in the camera's projective frame when no ``net`` is given
        (:mod:`~asrbf_mesh._hole_camera`: hole sizes then measured in the image, scaled
        to the scan's median depth); so is its bare point cloud, meshed in the image
        (:func:`~asrbf_mesh._hole_camera.image_faces`); ``"view"``: always in the view
        plane.

    Returns
    -------
    FillResult
        The repaired mesh (scan vertices and faces first, untouched but for the
        fixes of :func:`~asrbf_mesh._hole_find.usable_faces`: faces that repeat a vertex
        or another face and fins left out, faces against their neighbours turned; a
        warning says how many) and a report
        of every hole: filled, or skipped with a reason. The outer border is never
        filled and is not counted as a hole.

    Raises
    ------
    ScanError
        If ``scan`` is not a Scan, a Mesh or an (N, 3) array of finite numbers, or is
        unusable (no triangles, and none from its points).
    ConfigError
        If ``net`` is not a Network, ``max_hole_size`` is not a finite positive length
        or a percentage in (0, 100], ``blend`` is unknown, ``lowpass_rel`` is not a
        finite positive number (or None), ``seed`` not an integer >= 0 or ``frame``
        unknown.
    """
    t0 = time.perf_counter()
    scan = _as_scan(scan)
    if net is not None and not isinstance(net, Network):
        raise ConfigError(f"net must be a Network (or None: fitted here), "
                          f"got {type(net).__name__}")
    check_choice(blend, "blend", BLENDS)
    if lowpass_rel is not None:
        check_float(lowpass_rel, "lowpass_rel", low=0.0, low_open=True)
    seed = check_seed(seed)
    check_choice(frame, "frame", ("auto", "view"))
    diag = scan.bbox_diagonal
    limit = parse_length(max_hole_size, diag, "max_hole_size")
    cam = camera_frame(scan) if net is None and frame == "auto" else None
    if cam is not None:
        return fill_in_camera(fill_holes, scan, cam, limit, diag, t0, blend=blend,
                              lowpass_rel=lowpass_rel, seed=seed, progress=progress,
                              pieces=pieces)
    if net is None:
        from ._fit import fit

        net = fit(scan, seed=seed, pieces=pieces, progress=progress)
    R = net.frame.rotation
    local = scan.points @ R
    xy = np.ascontiguousarray(local[:, :2])
    depth = local[:, 2]
    spacing = sampling_spacing(xy)
    faces = usable_faces_warned(scan.faces, scan.source)
    if faces is None or len(faces) == 0:
        faces = point_cloud_faces(xy, spacing)
    if len(faces) == 0:
        raise ScanError(f"{scan.source or 'scan'}: no triangles to find holes in, and "
                        "none could be made from its points")
    # the footprint (compiled kernels and array steps that release the GIL, mostly) is
    # found beside the scan's trees and edge tables: TUM desk2's 1.1-1.2 s and 0.34 s
    # take 0.8-1.0 s together on two cores
    with ThreadPoolExecutor(max_workers=1) as pool:
        found = pool.submit(find_holes, xy, faces, spacing, bay_mouth=BAY_MOUTH * spacing,
                            max_size=limit)
        area = signed_areas(xy, faces)
        ccw = bool(np.sum(area > 0) >= np.sum(area < 0))
        rim_edges = boundary_edges(faces)[0]
        trees = cKDTree(xy[faces].mean(axis=1)), cKDTree(xy)
        rim_keys = np.sort(rim_edges[:, 0].astype(np.int64) * _KEY + rim_edges[:, 1])
        scan_keys, scan_uses = np.unique(_edge_keys(faces), return_counts=True)
        inner_keys = scan_keys[scan_uses >= 2]  # a patch's triangle on one: a third face
        holes, _, fp = found.result()
    ctx = Ctx(xy, depth, net, faces, *trees, spacing, ccw, fp.label_at, blend, lowpass_rel,
              rim_edges, piece=net.piece_at(xy) if net.n_pieces > 1 else None,
              cache={"edges": scan_keys})

    new_pts: list[np.ndarray] = []
    new_tris: list[np.ndarray] = []
    owners: list[np.ndarray] = [np.full(len(faces), -1)]  # each face's hole (-1: the scan's)
    infos: list[HoleInfo] = []
    rims: list[set[int]] = []
    partial: dict[int, np.ndarray] = {}  # info index -> rim and patch edge keys
    n_base = len(scan.points)
    n_new = 0
    todo = [i for i, h in enumerate(holes) if limit is None or h.size <= limit]
    filled = dict(zip(todo, map_forked(_fill_job, (holes, ctx), todo,
                                       cost=[len(holes[i].edges) for i in todo]), strict=True))
    for i, h in enumerate(holes):
        rim = np.unique(h.edges)
        centre = tuple(float(v) for v in scan.points[rim].mean(axis=0))
        size_pct = 100.0 * h.size / diag
        base = {"index": i, "size_abs": h.size, "size_pct": size_pct, "centre": centre,
                "rim_vertices": int(len(rim))}
        rims.append(set(rim.tolist()))
        if limit is not None and h.size > limit:
            infos.append(HoleInfo(**base, filled=False,
                                  reason=f"larger than max_hole_size ({h.size:.4g} > "
                                         f"{limit:.4g} scan units)"))
            continue
        patch, reason = filled[i]
        verts, tris = patch.verts, patch.tris
        if len(tris) == 0:
            infos.append(HoleInfo(**base, filled=False, reason=reason))
            continue
        placed = np.where(tris < 0, n_base + n_new - tris - 1, tris)
        tris, clash = _agree_with_scan(placed, rim_keys, inner_keys)
        if clash and reason is None:  # the loop stage closes what is left, in 3D
            reason = (f"{clash} triangles would have run against the scan's orientation or "
                      "given a scan edge a third face")
        if reason is not None:  # judged by what is still open after the loop stage
            partial[len(infos)] = np.r_[_rim_keys_of(h.edges), _edge_keys(placed)]
        if len(tris) == 0:
            infos.append(HoleInfo(**base, filled=False, reason=reason))
            continue
        new_pts.append(verts)
        new_tris.append(tris)
        owners.append(np.full(len(tris), len(infos)))
        n_new += len(verts)
        infos.append(HoleInfo(**base, filled=reason is None, reason=reason,
                              vertices_added=len(verts), faces_added=len(tris),
                              layers=patch.layers))
    add_local = np.vstack(new_pts) if new_pts else np.zeros((0, 3))
    vertices = np.vstack([scan.points, add_local @ R.T])
    all_faces = np.vstack([faces, *new_tris]) if new_tris else faces
    # the rim edges of the holes still open (not for their size): a cycle pinched off the
    # outer border that holds one is what their patch left
    hole_keys = np.unique(np.concatenate([np.zeros(0, np.int64)] + [
        _rim_keys_of(h.edges) for h, info in zip(holes, infos, strict=True)
        if not info.filled and (limit is None or h.size <= limit)]))
    before = list(infos)
    big_keys = np.unique(np.concatenate([np.zeros(0, np.int64)] + [
        _rim_keys_of(h.edges) for h in holes if limit is not None and h.size > limit]))
    loop_args = (ccw, scan.points, R, spacing, limit, diag, big_keys, owners)
    n_patched = len(all_faces)  # the view-plane patches' faces end here, the loops' begin
    wall = functools.partial(fill_across_wall, ctx=ctx)
    vertices, all_faces, outer = _close_loops(vertices, all_faces, infos, rims, hole_keys,
                                              *loop_args, wall=wall)
    still_open = _still_open(all_faces, outer)
    if _in_sorted(still_open, hole_keys).any():
        # a gap the outer border's walk ran through (pinched to it at a vertex) may be a
        # loop of its own once the other loops are filled: one more pass (TUM desk2 as a
        # mesh: an 11-edge gap down a depth step, 28 rim edges of a 158-vertex hole)
        vertices, all_faces, outer = _close_loops(vertices, all_faces, infos, rims,
                                                  hole_keys, *loop_args, only=hole_keys,
                                                  wall=wall)
        still_open = _still_open(all_faces, outer)
    _open_after_all(holes, infos, before, still_open)
    if partial:
        _closed_after_all(partial, infos, still_open)
    vertices, all_faces, outer, owner, opened = _leave_out_crossings(
        vertices, all_faces, outer, np.concatenate(owners), infos, len(faces), n_patched,
        n_base, R, [partial.get(i, _rim_keys_of(h.edges)) for i, h in enumerate(holes)], diag)
    if opened:  # filled again whole, as loops in 3D, where that crosses nothing
        rim_of = {i: np.unique(_rim_keys_of(holes[i].edges)) if i < len(holes) else None
                  for i in opened}
        vertices, all_faces, _, outer, done = refill_crossed(
            vertices, all_faces, owner, outer, rim_of, opened, R,
            functools.partial(_hole_spacing, spacing=spacing), scan.points, WALL_FACING, n_base)
        for i, (n_v, n_f, whole) in done.items():
            h = infos[i]
            infos[i] = dataclasses.replace(h, filled=True, reason=None,
                                           vertices_added=n_v + h.vertices_added * (not whole),
                                           faces_added=n_f + h.faces_added * (not whole))
    quality = np.r_[np.zeros(n_base), np.ones(len(vertices) - n_base)]
    mesh = Mesh(vertices, all_faces, vertex_quality=quality)
    border_edges = sum(len(loop) for loop in outer)
    return FillResult(mesh, tuple(infos), border_edges, time.perf_counter() - t0, net)
