"""Filling a hole at a fold of the surface (an occlusion), one layer of surface at a time.

Where the surface folds over itself in the view (an ear in front of the head), a hole's
rim runs over two layers of surface; each layer is filled on its own, up to the fold,
from its own surroundings, and the fold's silhouette stays a boundary.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from . import _holes_kernels as _hk
from ._hole_find import Hole, chains
from ._hole_patch import (
    EMPTY,
    Ctx,
    Patch,
    away_from,
    close_patch,
    grid_samples,
    ring_reach,
    triangulate,
)

__all__ = ["fill_layers"]

# a triangle whose normal is within acos(0.1) = 84 degrees of the view plane is seen edge-on:
# at an occlusion fold such triangles bridge the depth jump between two layers of surface
_EDGE_ON = 0.1


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
        tris, extra = triangulate(xy[c], seg, "pQ")
        if len(extra) == 0 and len(tris):
            return c, tris, (a, b)
    return None


_Layer = tuple[int, np.ndarray, np.ndarray]  # number, triangles, vertices


def _fold_layers(hole: Hole, ctx: Ctx, reach: float) -> tuple[np.ndarray, list[_Layer]] | None:
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


def _fill_chain(chain: np.ndarray, loop: bool, hole: Hole, ctx: Ctx, layer_faces: np.ndarray,
                layer_verts: np.ndarray, reach: float) -> tuple[np.ndarray, np.ndarray, set]:
    """Fill one layer's rim chain closed by its chord.

    Returns (new vertices, triangles, rim edges that belong to the fold's silhouette:
    chain ends trimmed at the fold, or a chain whose polygon the layer already covers).
    """
    def edges_of(c: np.ndarray) -> set[tuple[int, int]]:
        return set(map(tuple, np.sort(np.column_stack([c[:-1], c[1:]]), axis=1).tolist()))

    found = _simple_polygon(ctx.xy, chain, loop)
    if found is None:  # this layer's rim crosses itself too: leave it open
        return *EMPTY, set()
    c, tris, (a, b) = found
    silhouette = edges_of(chain[:a + 1]) | edges_of(chain[len(chain) - b - 1:]) if a or b else set()
    poly = ctx.xy[c]
    seg = np.column_stack([np.arange(len(c)), np.roll(np.arange(len(c)), -1)])
    g = grid_samples(poly.min(0), poly.max(0), ctx.spacing)
    if len(g):
        _, cand = cKDTree(poly[tris].mean(axis=1)).query(g, k=min(8, len(tris)))
        g = g[_hk.inside_any(g, poly, tris, cand)]
        g = away_from(g, poly, seg, 0.6 * ctx.spacing)
    pts = np.vstack([poly, g])
    tris, extra = triangulate(pts, seg, "pYQ")
    if len(extra):
        return *EMPTY, silhouette
    ring = np.unique(np.concatenate(ctx.scan_tree.query_ball_point(poly, reach)))
    ring = ring[np.isin(ring, layer_verts)]
    v, t, _ = close_patch(pts, c, seg, tris, hole.size, ctx, layer_faces,
                     cKDTree(ctx.xy[layer_faces].mean(axis=1)), None, ring, substrate=False)
    if len(t) == 0:  # the layer's own triangles cover the whole polygon: nothing is open
        silhouette |= edges_of(c)
    return v, t, silhouette


def fill_layers(hole: Hole, ctx: Ctx) -> Patch | None:
    """Fill a hole at a fold of the surface, one layer at a time.

    At an occlusion fold the hole's rim runs over two (or more) layers of surface, one
    in front of the other: in the view plane their rims cross, or one layer covers the
    other's hole. The layers are the pieces of the scan around the hole once the
    triangles seen edge-on (the fold's wall) are set aside; each layer's part of the rim
    is closed by its chord (the unseen fold edge) and filled like a hole of its own,
    from that layer's own surroundings only. The fold's silhouette stays a boundary, as
    it is in the scan, unless the wall between two layers' fills is closed
    (:mod:`~asrbf_mesh._hole_wall`). Returns None when the rim lies on one layer.

    ``_holes._fill_one`` takes this fill with the wall between its layers closed
    (:func:`~asrbf_mesh._hole_wall.close_wall`) wherever that joins the mesh manifold and
    crosses no scan face, not only where one patch cannot close the rim (a rim crossing
    itself in the view plane): a disk punched across an occlusion (bun090's ear and the
    head behind it) or across a cliff has a rim that is a simple polygon in the view
    plane, and one surface over it ramps from one layer to the other (bun090 punched with
    seed 13: 0.719 -> 0.247 % RMS).
    """
    reach = ring_reach(hole.size, ctx.spacing)
    split = _fold_layers(hole, ctx, reach)
    if split is None:
        return None
    edge_layer, layers = split
    new_v: list[np.ndarray] = []
    new_t: list[np.ndarray] = []
    n_new = 0
    done: set[tuple[int, int]] = set()
    for k, layer_faces, layer_verts in layers:
        for chain, loop in chains(_layer_rim(hole.edges[edge_layer == k], layer_verts,
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
        return Patch(*EMPTY, len(hole.edges), note, len(layers))
    on_layer = np.sort(hole.edges[edge_layer >= 0], axis=1)
    missing = sum(tuple(r) not in done for r in on_layer.tolist())
    return Patch(np.vstack(new_v), np.vstack(new_t), missing, note, len(layers))
