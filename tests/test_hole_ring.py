"""The spline of a view-plane hole fill sees the rim's own surface, not a layer near it."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from asrbf_mesh._hole_patch import RING_EDGE, own_ring
from asrbf_mesh._surface import grid_faces


def _two_layers(gap: float):
    """A plane z = 0 (20 x 20, spacing 1) and a strip 20 x 4 at z = -gap over its rows 8-11,
    joined to the plane's row 12 by a strip of wall triangles (a range grid's triangles
    across an occlusion)."""
    x, y = np.meshgrid(np.arange(20.0), np.arange(20.0))
    front = np.column_stack([x.ravel(), y.ravel(), np.zeros(x.size)])
    bx, by = np.meshgrid(np.arange(20.0), 8.0 + np.arange(4.0))
    back = np.column_stack([bx.ravel(), by.ravel(), np.full(bx.size, -gap)])
    faces = [grid_faces(20, 20), grid_faces(20, 4) + 400]
    top = 400 + 3 * 20 + np.arange(20)  # the strip's last row (y = 11)
    row = 12 * 20 + np.arange(20)  # the plane's row y = 12
    faces.append(np.column_stack([top[:-1], top[1:], row[:-1]]))
    faces.append(np.column_stack([top[1:], row[1:], row[:-1]]))
    pts = np.vstack([front, back])
    return SimpleNamespace(xy=pts[:, :2], depth=pts[:, 2], faces=np.vstack(faces),
                           spacing=1.0, cache={})


def _ring(ctx, rim):
    near = np.linalg.norm(ctx.xy[:, None, :] - ctx.xy[rim][None], axis=2).min(axis=1) <= 9
    return np.setdiff1d(np.flatnonzero(near), rim)


def test_a_layer_joined_across_an_occlusion_is_left_out_of_the_ring() -> None:
    ctx = _two_layers(gap=30.0)  # the wall's edges: 30 spacings
    rim = np.array([3 * 20 + 10, 3 * 20 + 11, 4 * 20 + 11, 4 * 20 + 10])  # around (10.5, 3.5)
    ring = _ring(ctx, rim)
    assert (ring >= 400).any()  # the strip is near the rim in the view plane
    got = own_ring(ctx, ring, rim)
    np.testing.assert_array_equal(got, ring[ring < 400])


def test_a_steep_sheet_of_the_same_surface_stays_in_the_ring() -> None:
    ctx = _two_layers(gap=RING_EDGE - 1.0)  # a steep slope, not a jump: edges of 7 spacings
    rim = np.array([3 * 20 + 10, 3 * 20 + 11, 4 * 20 + 11, 4 * 20 + 10])
    ring = _ring(ctx, rim)
    np.testing.assert_array_equal(own_ring(ctx, ring, rim), ring)


def test_a_ring_mostly_elsewhere_is_kept_whole() -> None:
    """When the rim's own surface holds fewer than half the ring, the ring stays as found."""
    ctx = _two_layers(gap=30.0)
    rim = np.array([19 * 20 + 0, 19 * 20 + 1])  # a corner of the plane
    ring = np.r_[np.arange(400, 480), 18 * 20 + np.arange(3)]
    np.testing.assert_array_equal(own_ring(ctx, ring, rim), ring)


def test_a_fill_vertex_far_past_its_ring_takes_the_membrane_of_the_rest() -> None:
    """A new depth past the ring's depths by more than _REACH hole sizes (a ray that met a
    steep plane's spline far off) is replaced within them; the others are kept bit for bit."""
    from asrbf_mesh._hole_patch import _REACH, _depth_bounds, _within_reach

    x, y = np.meshgrid(np.arange(6.0), np.arange(6.0))
    depth = 0.1 * x.ravel()  # a tilted plane, depths 0 ... 0.5
    ctx = SimpleNamespace(depth=depth)
    rim = np.array([7, 8, 9, 10, 16, 22, 28, 27, 26, 25, 19, 13])  # around (2.5, 2.5)
    ring = np.arange(36)
    lo, hi = _depth_bounds(ctx, ring, 2.0)
    assert (lo, hi) == (-_REACH * 2.0, 0.5 + _REACH * 2.0)
    # four new vertices inside, the rim's 12 first: a fan of triangles over a 2 x 2 grid
    tris = np.array([[0, 1, 12], [1, 2, 13], [2, 3, 13], [3, 4, 13], [4, 5, 15],
                     [5, 6, 15], [6, 7, 15], [7, 8, 14], [8, 9, 14], [9, 10, 14],
                     [10, 11, 12], [11, 0, 12], [1, 13, 12], [12, 13, 15], [12, 15, 14],
                     [4, 15, 13], [7, 14, 15], [10, 12, 14]])
    sane = np.array([0.15, 0.25, 0.2, 0.3])
    assert _within_reach(ctx, ring, 2.0, tris, rim, sane) is sane  # nothing to do
    wild = sane.copy()
    wild[1] = -40.0  # 20 hole sizes off
    got = _within_reach(ctx, ring, 2.0, tris, rim, wild)
    assert np.array_equal(np.delete(got, 1), np.delete(sane, 1))
    assert depth.min() <= got[1] <= depth.max()
    wild[:] = np.nan  # none left to lean on: the rim's membrane
    got = _within_reach(ctx, ring, 2.0, tris, rim, wild)
    assert np.isfinite(got).all() and (got >= depth[rim].min()).all() \
        and (got <= depth[rim].max()).all()
