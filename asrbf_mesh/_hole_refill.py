"""A hole that its fill's crossings leave open, filled again in 3D.

The view-plane patch of a hole on a steep side (a cylinder's side, a fold) misses rim
edges; the loop stage closes what it missed in the rim's own plane, and that fill can
run through the patch and through itself. :func:`~asrbf_mesh._holes._leave_out_crossings`
then leaves the crossing triangles out and the hole open (synthetic cylinder sides: 20
of 44 open, every crossing within the hole's own fill). Here such a hole is closed
where its fill left it open, its fill kept; where :data:`LOST` of its fill or more was
left out, the fill had folded over itself: it goes whole, and the region that opens
(its rim, with whatever of the fill's neighbours it touched) is filled anew. Each loop
takes the first of the loop stage's fill in its rim's plane
(:func:`~asrbf_mesh._hole_loops.fill_loop`: a thin plate of the scan around it), a
faired disk and the minimum-area triangulation by chords that joins the mesh manifold,
faces the view (a fill seen edge-on is a wall across a depth step, not a surface) and
crosses nothing; else the hole stays as it was.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from . import _holes_kernels as _hk
from ._forked import map_forked
from ._hole_close import (
    _chords_avoiding,
    _edge_keys,
    _EdgeSet,
    _fits,
    _in_sorted,
    _rim_keys,
    _rim_keys_of,
    facing,
)
from ._hole_cross import crossing_faces, crossing_of
from ._hole_loops import fill_loop, outer_loops, rim_plane, simple_cycles

__all__ = ["LOST", "refill_crossed"]

#: A hole's whole fill is replaced only when at least this share of its triangles were left
#: out for crossing: it had folded over itself (the synthetic cylinders' sides, seeds
#: 0-49: 18 of the 19 fills left open lost 5.1-99.7 %, one 2.5 %, which stays open; a
#: fill of 10,708 triangles where the refill takes 180); a fill that
#: lost fewer was the better surface but there (punched views syn225 seed 4 and syn135
#: seed 9: 1.7 and 2.1 %, their holes refilled whole at 0.288 and 0.284 % RMS where the
#: view-plane patches, the crossing triangles left out, had 0.107 and 0.173 %; bun090
#: seed 6: 0.4 %, 0.273 against 0.147 %).
LOST = 0.04

#: :class:`_Near`: faces whose view-plane box reaches more than this many times the
#: median's are tested against every fill.
_BIG = 4.0


class _Remaining(_EdgeSet):
    """The mesh's edges without those only the faces taken out had."""

    def __init__(self, keys: np.ndarray, gone: np.ndarray) -> None:
        super().__init__(keys)
        self._gone = gone

    def contains(self, keys: np.ndarray) -> np.ndarray:
        return super().contains(keys) & ~_in_sorted(np.asarray(keys, np.int64), self._gone)


def _half_edges(faces: np.ndarray) -> np.ndarray:
    """(3F, 2) half-edges in :func:`~asrbf_mesh._hole_close._edge_keys`' order."""
    return np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])


def _region_loops(faces: np.ndarray, mine: np.ndarray, keys: np.ndarray, count: np.ndarray,
                  bnd: np.ndarray, part: np.ndarray, border: np.ndarray,
                  rim: np.ndarray | None, seeds: np.ndarray
                  ) -> tuple[list[np.ndarray], np.ndarray, bool] | None:
    """Return the boundary cycles that open once ``faces[mine]`` are taken out, or None.

    ``keys``/``count``: the mesh's sorted edge keys and how many faces hold each;
    ``bnd``: its boundary half-edges, ``part``: each vertex's stretch of boundary
    (-1: on none). The cycles are walked over the taken faces' edges another face
    holds (in that face's direction) and the open stretches that touch them or hold an
    edge of ``seeds`` (sorted edge keys); those that hold a newly opened edge or an open
    one of ``seeds`` are returned, split at pinches, but those along ``border`` (sorted
    keys: the outer borders; the fill had closed a bit of it, which opens again), with
    the keys of the edges no face keeps and whether the border changes. None when such
    a border cycle holds an edge of ``rim`` (sorted keys of the hole's rim edges; None:
    not known, then no border cycle is taken) that was not on the border before, when
    the edges do not close into cycles (an inconsistently oriented neighbourhood) or an
    edge has three faces.
    """
    he = _half_edges(faces[mine])
    uk, inv, taken = np.unique(_edge_keys(faces[mine]), return_inverse=True,
                               return_counts=True)
    left = count[np.searchsorted(keys, uk)] - taken
    if np.any(left > 1):
        return None
    opened = he[(left == 1)[inv]][:, ::-1]
    rim_open = bnd[_in_sorted(_rim_keys_of(bnd), seeds)]
    if len(opened) + len(rim_open) == 0:
        return None
    touched = np.unique(part[np.r_[faces[mine].ravel(), rim_open.ravel()]])
    was_open = bnd[np.isin(part[bnd[:, 0]], touched[touched >= 0])]
    was_open = was_open[~_in_sorted(_rim_keys_of(was_open), uk)]
    edges = np.vstack([opened, was_open])
    cycles = _hk.walk_cycles(edges[np.lexsort((edges[:, 1], edges[:, 0]))])
    if sum(len(c) for c in cycles) != len(edges):
        return None
    new = np.unique(_rim_keys_of(np.vstack([opened, rim_open])))
    cycles = [s for c in cycles for s in simple_cycles(c) if _in_sorted(_rim_keys(s), new).any()]
    along = [_in_sorted(_rim_keys(c), border).any() for c in cycles]
    if any(a and (rim is None or (_in_sorted(k, rim) & ~_in_sorted(k, border)).any())
           for a, k in zip(along, map(_rim_keys, cycles), strict=True)):
        return None
    cycles = [c for a, c in zip(along, cycles, strict=True) if not a]
    return (cycles, uk[left == 0], any(along)) if cycles else None


class _Near:
    """The faces near a place in the view plane, for a quick crossing test of a fill.

    Faces are found by their boxes' centres in a k-d tree, searched as far as the fill's
    box reaches plus the largest box of a face (the few faces larger than
    :data:`_BIG` times the median are always taken); only those faces and the fill go
    to :func:`~asrbf_mesh._hole_cross.crossing_faces`, on their own vertices. A Kinect
    frame meshed as its grid (568,000 faces, 126-133 fills tried; both profiled beside
    other work): 4.3 s when each fill's test took every face's box and every vertex,
    2.2 s so.
    """

    def __init__(self, local: np.ndarray, faces: np.ndarray) -> None:
        t = local[faces][:, :, :2]
        self.local, self.faces = local, faces
        self.lo, self.hi = t.min(axis=1), t.max(axis=1)
        reach = 0.5 * np.linalg.norm(self.hi - self.lo, axis=1)
        limit = _BIG * float(np.median(reach)) if len(reach) else 0.0
        self.big = np.flatnonzero(reach > limit)
        small = np.flatnonzero(reach <= limit)
        self.small = small
        self.reach = float(reach[small].max()) if len(small) else 0.0
        self.tree = cKDTree(0.5 * (self.lo[small] + self.hi[small]))

    def crosses(self, v: np.ndarray, t: np.ndarray, skip: np.ndarray) -> bool:
        """Tell whether the fill ``t`` crosses a face but those of ``skip`` (taken out).

        ``t``: mesh vertex ids, ``-1 - k`` for new vertex ``k`` at ``v`` (view frame).
        """
        rim = np.unique(t[t >= 0])
        pts = np.vstack([self.local[rim], v])
        tt = np.where(t < 0, len(rim) - t - 1, np.searchsorted(rim, t))
        lo, hi = pts[tt.ravel(), :2].min(axis=0), pts[tt.ravel(), :2].max(axis=0)
        found = self.tree.query_ball_point(0.5 * (lo + hi),
                                           0.5 * float(np.linalg.norm(hi - lo)) + self.reach)
        cand = np.union1d(self.small[np.asarray(found, dtype=np.int64)], self.big)
        cand = cand[np.all((self.hi[cand] >= lo) & (self.lo[cand] <= hi), axis=1)]
        cand = np.setdiff1d(cand, skip)
        if len(cand) == 0:
            return bool(len(crossing_faces(pts, tt, 0)))
        ids, inv = np.unique(self.faces[cand], return_inverse=True)
        # the near faces' vertices, the fill's rim among them, then the fill's new ones
        allv = np.union1d(ids, rim)
        sub_pts = np.vstack([self.local[allv], v])
        near = np.searchsorted(allv, ids)[inv.reshape(-1, 3)]
        fill = np.where(t < 0, len(allv) - t - 1, np.searchsorted(allv, np.maximum(t, 0)))
        sub = np.vstack([near, fill])
        return bool(len(crossing_faces(sub_pts, sub, len(near))))


def _refill(cycles: list[np.ndarray], vertices: np.ndarray, R: np.ndarray,
            step_of: Callable[[np.ndarray], float], scan_points: np.ndarray,
            tree: cKDTree, known: _EdgeSet, near: _Near, skip: np.ndarray,
            wall_facing: float) -> tuple[np.ndarray, np.ndarray] | None:
    """Fill each cycle in 3D (new vertices numbered -1, -2, ... across them), or None.

    A cycle takes the first of its rim's plane fill, the faired disk and the
    minimum-area triangulation by chords that joins the mesh manifold, faces the view by
    ``wall_facing`` at least and crosses no face near it (``near``, but ``skip``).
    """
    local = near.local
    new_v, new_t, n_new = [], [], 0
    for c in cycles:
        step = step_of(local[np.column_stack([c, np.roll(c, -1)])][:, :, :2])
        # a rim its plane cannot hold is filled by the disk already
        plane = rim_plane(vertices[c], step) is not None
        for how in ("plane", "disk", "chords") if plane else ("disk", "chords"):
            if how == "chords":
                v, t = np.zeros((0, 3)), _chords_avoiding(c, vertices, known)
            else:
                v, t, _ = fill_loop(c, vertices, step, scan_points, tree, disk=how == "disk")
            if len(t) == 0 or not _fits(t, c, known):
                continue
            vl = v @ R
            rim = np.unique(t[t >= 0])
            tt = np.where(t < 0, len(rim) - t - 1, np.searchsorted(rim, np.maximum(t, 0)))
            if (facing(np.vstack([local[rim], vl]), tt) >= wall_facing
                    and not near.crosses(vl, t, skip)):
                break
        else:
            return None
        new_t.append(np.where(t < 0, t - n_new, t))
        new_v.append(v)
        n_new += len(v)
    return np.vstack(new_v), np.vstack(new_t)


def refill_crossed(vertices: np.ndarray, faces: np.ndarray, owner: np.ndarray,
                   outer: list[np.ndarray], todo: dict[int, np.ndarray | None],
                   lost: dict[int, float], R: np.ndarray,
                   step_of: Callable[[np.ndarray], float], scan_points: np.ndarray,
                   wall_facing: float, n_keep: int
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[np.ndarray],
                              dict[int, tuple[int, int, bool]]]:
    """Fill again, as loops in 3D, the holes of ``todo`` that their fills left open.

    ``todo``: each hole's index and its rim's sorted edge keys (None: not known);
    ``lost``: each one's share of fill triangles left out for crossing; a hole is first
    closed where its fill left it open, and its whole fill goes only when :data:`LOST`
    of it or more was left out;
    ``owner``: each face's hole (-1: the scan's); ``step_of``: a loop's fill spacing from
    its rim edges' ends in the view plane, (E, 2, 2); ``n_keep``: the vertices kept
    whatever uses them (the scan's). Holes whose regions share a vertex are not both
    taken. Returns the vertices, faces, owners and outer borders after the refills, and
    for each hole filled again what it adds (vertices, faces) and whether that replaces
    its fill (else it adds to it).
    """
    local = vertices @ R
    k_all = _edge_keys(faces)
    keys, count = np.unique(k_all, return_counts=True)
    bnd = _half_edges(faces)[count[np.searchsorted(keys, k_all)] == 1]
    border = np.unique(np.concatenate([np.zeros(0, np.int64)] + [_rim_keys(o) for o in outer]))
    tree = cKDTree(scan_points)
    near = _Near(local, faces)
    part = np.full(len(vertices), -1)
    if len(bnd):  # each vertex's stretch of boundary (joined at shared vertices)
        ids, e = np.unique(bnd, return_inverse=True)
        n_ids = len(ids)
        graph = coo_matrix((np.ones(len(bnd)), (e[:, 0], e[:, 1])), shape=(n_ids, n_ids))
        part[ids] = connected_components(graph, directed=False)[1]
    state = (faces, owner, keys, count, bnd, part, border, todo, lost, vertices, R,
             step_of, scan_points, tree, near, wall_facing)
    holes = list(todo)
    n_own = np.bincount(owner[owner >= 0], minlength=max(holes) + 1)
    tried = map_forked(_attempts, state, holes, cost=[n_own[i] + len(
        todo[i] if todo[i] is not None else ()) for i in holes])
    taken = np.zeros(len(vertices), dtype=bool)
    plans: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
    reborder = set()  # the holes whose fills had closed a bit of an outer border
    for i, attempts in zip(holes, tried, strict=True):  # in order: the first one's region
        for mine, region, fill, changes_border in attempts:
            if taken[region].any():  # a neighbour's region: not both
                break
            if fill is not None:
                plans[i] = (mine, *fill)
                taken[region] = True
                if changes_border:
                    reborder.add(i)
                break
    done: dict[int, tuple[int, int, bool]] = {}
    while plans:  # keep the refills that cross nothing (dropping one may free another)
        out_v, out_f, out_o, first = _apply(vertices, faces, owner, plans)
        crossed = _crossing_new(out_v @ R, out_f, first)
        if not crossed.any():
            done = {i: (len(p[1]), len(p[2]), len(p[0]) > 0) for i, p in plans.items()}
            vertices, faces, owner = out_v, out_f, out_o
            break
        for i in np.unique(out_o[first:][crossed]).tolist():
            del plans[i]
    vertices, faces, owner, outer = _drop_unused(vertices, faces, owner, outer, n_keep)
    if reborder.intersection(done):
        outer = outer_loops(faces, len(vertices))
    return vertices, faces, owner, outer, done


def _attempts(state: tuple, i: int) -> list[tuple[np.ndarray, np.ndarray, Any, bool]]:
    """Hole ``i``'s refills, until one holds: (faces out, region, fill or None, border).

    First what its fill left open, its fill kept; then, where :data:`LOST` of its fill
    or more was left out for crossing, the whole hole, its fill out. A job of :func:`map_forked`
    (``state``: what :func:`refill_crossed` shares): whether a region is taken by an
    earlier hole is judged after, in order, as if the holes had been tried one by one.
    """
    (faces, owner, keys, count, bnd, part, border, todo, lost, vertices, R, step_of,
     scan_points, tree, near, wall_facing) = state
    none = np.zeros(0, np.int64)
    own = np.flatnonzero(owner == i)
    rim = none if todo[i] is None else todo[i]
    tries = [(none, np.union1d(rim, _edge_keys(faces[own])))]
    if lost[i] >= LOST:  # a fill folded over itself goes whole
        tries.append((own, none if len(own) else rim))
    out = []
    for mine, seeds in tries:
        found = _region_loops(faces, mine, keys, count, bnd, part, border, todo[i], seeds)
        if found is None:
            continue
        region = np.unique(np.concatenate([faces[own].ravel(), *found[0]]))
        fill = _refill(found[0], vertices, R, step_of, scan_points, tree,
                       _Remaining(keys, found[1]), near, mine, wall_facing)
        out.append((mine, region, fill, found[2]))
        if fill is not None:
            break
    return out


def _apply(vertices: np.ndarray, faces: np.ndarray, owner: np.ndarray,
           plans: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]]
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """Return the mesh with each planned hole's faces replaced by its refill (last)."""
    drop = np.concatenate([p[0] for p in plans.values()])
    kept = np.delete(faces, drop, axis=0)
    own = np.delete(owner, drop)
    n = len(vertices)
    add_v, add_f, add_o = [vertices], [kept], [own]
    for i, (_, v, t) in plans.items():
        add_f.append(np.where(t < 0, n - t - 1, t))
        add_v.append(v)
        add_o.append(np.full(len(t), i))
        n += len(v)
    return np.vstack(add_v), np.vstack(add_f), np.concatenate(add_o), len(kept)


def _crossing_new(local: np.ndarray, faces: np.ndarray, first: int) -> np.ndarray:
    """Whether each face from ``first`` on crosses another face."""
    return crossing_of(local, faces, np.arange(first, len(faces)))


def _drop_unused(vertices: np.ndarray, faces: np.ndarray, owner: np.ndarray,
                 outer: list[np.ndarray], n_keep: int
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[np.ndarray]]:
    """Drop the vertices no face uses (the first ``n_keep`` and the outer borders' stay)."""
    used = np.zeros(len(vertices), dtype=bool)
    used[:n_keep] = True
    used[faces.ravel()] = True
    for loop in outer:
        used[loop] = True
    if used.all():
        return vertices, faces, owner, outer
    slot = np.cumsum(used) - 1
    return vertices[used], slot[faces], owner, [slot[loop] for loop in outer]
