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
