"""A hole over two layers of surface joined by a wall: each layer filled, then the wall.

Where a hole's rim runs over two layers of surface joined by a wall seen edge-on (a disk
punched across a cliff or an occlusion, bun090's ear in front of its head; a sheet
folded under itself with a hole through both layers and the wall), one surface over the
hole ramps from one layer to the other, off both. Each layer's part of the rim is filled
from that layer's own surroundings up to the wall
(:func:`~asrbf_mesh._hole_layers.fill_layers`); what is left between the layers' fills,
the punched part of the wall, is closed by chords (the least-area triangulation of each
cycle left open, no new vertex: the wall as the scan has it, a ruled strip). The whole
is taken only when it joins the mesh manifold and crosses no face of the scan (a spiral
ramp's layers wind around each other: its wall, closed so, ran through the ramp);
otherwise the fill stays as it was.

Two doors: :func:`close_wall` for a hole of the view plane whose rim is one simple
polygon there (the one surface over it closed the rim: the layers both face the view),
and :func:`fill_across_wall` for a loop of the loop stage (a fold: the back layer covers
the hole in the view plane, so only the boundary loop finds it).
"""

from __future__ import annotations

import numpy as np

from . import _holes_kernels as _hk
from ._hole_close import (
    _KEY,
    _agree_with_scan,
    _chords_avoiding,
    _edge_keys,
    _EdgeSet,
    _fits,
)
from ._hole_find import Hole
from ._hole_layers import fill_layers
from ._hole_patch import Ctx, Patch
from ._hole_refill import _half_edges, _Near

__all__ = ["close_wall", "fill_across_wall"]

def _open_cycles(half: np.ndarray) -> list[np.ndarray] | None:
    """Cycles of the half-edges whose reverse is not among ``half``, in their direction.

    Walked by :func:`~asrbf_mesh._holes_kernels.walk_cycles` (as the boundary loops are);
    None when they do not all close into simple cycles (a vertex left more than once: a
    pinch; a walk with no way out: a fill running a rim edge the mesh's way).
    """
    key = half[:, 0] * _KEY + half[:, 1]
    open_ = half[~np.isin(key, half[:, 1] * _KEY + half[:, 0])]
    if len(np.unique(open_[:, 0])) < len(open_):
        return None
    cycles = _hk.walk_cycles(open_[np.lexsort((open_[:, 1], open_[:, 0]))])
    return cycles if sum(len(c) for c in cycles) == len(open_) else None


def _scan_near(ctx: Ctx) -> _Near:
    """Return the scan's faces in the view frame for the crossing test (built once)."""
    if "near" not in ctx.cache:  # a Kinect frame's 400,000 faces: 0.3 s
        ctx.cache["near"] = _Near(np.column_stack([ctx.xy, ctx.depth]), ctx.faces)
    return ctx.cache["near"]


def _scan_edges(ctx: Ctx) -> _EdgeSet:
    """Return the scan's edges, sorted keys (built once)."""
    if "edges" not in ctx.cache:
        ctx.cache["edges"] = np.unique(_edge_keys(ctx.faces))
    return _EdgeSet(ctx.cache["edges"])


def _close_between(rim: np.ndarray, tris: np.ndarray, points: np.ndarray,
                   known: _EdgeSet) -> np.ndarray | None:
    """Orient the layers' fill against the rim, then close what it leaves open by chords.

    ``rim``: the hole's rim as (E, 2) half-edges in their faces' direction; ``tris``: the
    fill (ids into ``points``, the rim's and the fill's vertices); ``known``: the edges
    the mesh has. Returns the fill and the walls' triangles, or None. Each part of the
    fill is turned as a view-plane patch is (:func:`~asrbf_mesh._hole_close._agree_with_scan`).
    """
    tris, wrong = _agree_with_scan(tris, np.sort(rim[:, 0] * _KEY + rim[:, 1]),
                                   np.zeros(0, np.int64))
    if wrong:  # a part that runs rim edges both ways
        return None
    cycles = _open_cycles(np.vstack([rim, _half_edges(tris)]))
    if cycles is None:
        return None
    avoid = known.with_keys(_edge_keys(tris))
    walls = [_chords_avoiding(c, points, avoid) for c in cycles]
    if any(len(w) == 0 for w in walls):
        return None
    out = np.vstack([tris, *walls])
    rest = _open_cycles(np.vstack([rim, _half_edges(out)]))
    _, count = np.unique(_edge_keys(out), return_counts=True)
    return out if rest == [] and count.max() <= 2 else None


def close_wall(hole: Hole, layered: Patch, ctx: Ctx) -> Patch | None:
    """Return the layers' fill of a view-plane hole with the wall between them closed.

    ``hole.edges`` run in their faces' direction; ``layered`` is
    :func:`~asrbf_mesh._hole_layers.fill_layers`' patch (local ids: scan >= 0, new -1 - k);
    None when that does not join manifold or crosses the scan.
    """
    if len(layered.tris) == 0:
        return None
    n = len(ctx.xy)
    points = np.vstack([np.column_stack([ctx.xy, ctx.depth]), layered.verts])
    tris = np.where(layered.tris < 0, n - layered.tris - 1, layered.tris).astype(np.int64)
    out = _close_between(hole.edges.astype(np.int64), tris, points, _scan_edges(ctx))
    if out is None:
        return None
    out = np.where(out >= n, n - out - 1, out)
    if _scan_near(ctx).crosses(layered.verts, out, np.zeros(0, np.int64)):
        return None
    return layered._replace(tris=out, missing=0)  # the chords closed what it missed


def fill_across_wall(loop: np.ndarray, size: float, step: float, vertices: np.ndarray,
                     ctx: Ctx, R: np.ndarray, known: _EdgeSet
                     ) -> tuple[np.ndarray, np.ndarray, int] | None:
    """Fill a loop of scan vertices layer by layer, then the wall between the layers.

    ``loop`` runs in its faces' direction (as :func:`~asrbf_mesh._hole_loops.fill_loop`
    takes it); ``vertices`` are the mesh's (world units; the scan's first, so that a scan
    vertex's id is its index in ``ctx``), ``R`` the view frame's rotation, ``known`` the
    mesh's edges. Returns the new vertices (world units), triangles (mesh ids >= 0,
    new vertex ``k`` as ``-1 - k``) and the number of layers filled, or None when the
    loop lies on one layer, the fill does not close it manifold or crosses the scan.
    """
    n_scan = len(ctx.xy)
    if len(loop) < 6 or int(loop.max()) >= n_scan:
        return None
    rim = np.column_stack([loop, np.roll(loop, -1)]).astype(np.int64)
    patch = fill_layers(Hole(-1, rim, size), ctx)
    if patch is None or len(patch.tris) == 0:  # what it missed the chords may close
        return None
    n = len(vertices)
    tris = np.where(patch.tris < 0, n - patch.tris - 1, patch.tris).astype(np.int64)
    out = _close_between(rim, tris, np.vstack([vertices, patch.verts @ R.T]), known)
    if out is None or not _fits(out, loop, known):
        return None
    out = np.where(out >= n, n - out - 1, out)  # new vertices as -1 - k
    if _scan_near(ctx).crosses(patch.verts, out, np.zeros(0, np.int64)):
        return None
    return patch.verts @ R.T, out, patch.layers
