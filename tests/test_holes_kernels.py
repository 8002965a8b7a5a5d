"""The compiled helpers of hole filling against the library code they stand in for."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage
from scipy.interpolate import RBFInterpolator

from asrbf_mesh import _holes_kernels as hk


def _once_reference(edges: np.ndarray) -> np.ndarray:
    e = np.sort(edges, axis=1)
    _, inv, counts = np.unique(e, axis=0, return_inverse=True, return_counts=True)
    return counts[inv.ravel()] == 1


def test_once_counts_pairs_either_way_round() -> None:
    rng = np.random.default_rng(0)
    for _ in range(100):
        e = rng.integers(0, 12, size=(rng.integers(1, 40), 2))
        assert np.array_equal(hk.once(e), _once_reference(e))
    assert hk.once(np.array([[0, 1], [1, 0], [1, 2]])).tolist() == [False, False, True]
    assert hk.once(np.zeros((0, 2), np.int64)).shape == (0,)
    with pytest.raises(ValueError, match="vertex ids"):
        hk.once(np.array([[0, -1]]))


def test_face_faults_find_copies_and_edges_whose_faces_disagree() -> None:
    from collections import Counter

    rng = np.random.default_rng(0)
    for _ in range(200):
        f = rng.integers(0, int(rng.integers(3, 40)), (int(rng.integers(1, 120)), 3))
        f = f[(f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 0] != f[:, 2])]
        copy, turned, over = hk.face_faults(f)
        seen: set = set()
        want = []
        for row in f.tolist():
            want.append(tuple(sorted(row)) in seen)
            seen.add(tuple(sorted(row)))
        np.testing.assert_array_equal(copy, want)  # the first of each set stays
        und: Counter = Counter()
        way: Counter = Counter()
        for a, b, c in f.tolist():
            for x, y in ((a, b), (b, c), (c, a)):
                und[min(x, y), max(x, y)] += 1
                way[x, y] += 1
        assert turned == sum(1 for (x, y), n in und.items()
                             if n == 2 and (way[x, y] == 2 or way[y, x] == 2))
        assert over == sum(1 for n in und.values() if n > 2)


def test_distance_to_false_is_scipys_euclidean_transform() -> None:
    rng = np.random.default_rng(1)
    for _ in range(150):
        mask = rng.random(rng.integers(1, 30, size=2)) < rng.uniform(0.3, 0.999)
        if mask.all():
            continue
        assert np.array_equal(hk.distance_to_false(mask), ndimage.distance_transform_edt(mask))
    with pytest.raises(ValueError, match="no False"):
        hk.distance_to_false(np.ones((3, 3), bool))


def test_walk_cycles_follows_the_first_way_out() -> None:
    # loops 1-5-6 and 5-2-3 pinched at 5: walked from 1, the walk takes 5's first way
    # out (to 2) round the second loop, then the way left (to 6) home
    e = np.array([[1, 5], [2, 3], [3, 5], [5, 2], [5, 6], [6, 1]])
    assert [c.tolist() for c in hk.walk_cycles(e)] == [[1, 5, 2, 3, 5, 6]]
    # a loop back at its start closes there
    e = np.array([[0, 1], [0, 3], [1, 2], [2, 0], [3, 4], [4, 0]])
    assert [c.tolist() for c in hk.walk_cycles(e)] == [[0, 1, 2], [0, 3, 4]]
    # an open walk (no way back to its start) is dropped
    assert hk.walk_cycles(np.array([[0, 1], [1, 2]])) == []
    with pytest.raises(ValueError, match="sorted"):
        hk.walk_cycles(np.array([[1, 0], [0, 1]]))


def test_thin_plate_matches_scipy_and_rays_meet_it() -> None:
    rng = np.random.default_rng(2)
    uv = rng.uniform(-1, 1, (300, 2))
    h = 0.1 * np.sin(3 * uv[:, 0]) + 0.05 * uv[:, 1] ** 2
    spline = hk.thin_plate(uv, h)
    ref = RBFInterpolator(uv, h, kernel="thin_plate_spline")
    q = rng.uniform(-0.8, 0.8, (500, 2))
    flat = hk.ray_depths(q, np.zeros(3), np.eye(3)[:2], np.eye(3)[2], 1.0, spline, 1e-12, 1e-6)
    assert np.abs(flat - ref(q)).max() < 1e-9
    # a plane tilted by 0.5 rad: each ray's point lies on the surface
    t = 0.5
    axes = np.array([[np.cos(t), 0.0, np.sin(t)], [0.0, 1.0, 0.0]])
    normal = np.array([-np.sin(t), 0.0, np.cos(t)])
    z = hk.ray_depths(q, np.zeros(3), axes, normal, 2.0, spline, 1e-10, 1e-6)
    p = np.column_stack([q, z])
    assert np.all(np.isfinite(z))
    assert np.abs(p @ normal - 2.0 * ref(p @ axes.T / 2.0)).max() < 1e-8
    # too few points, all on a line: no spline
    assert hk.thin_plate(uv[:2], h[:2]) is None
    assert hk.thin_plate(np.column_stack([uv[:, 0], uv[:, 0]]), h) is None
    # smoothing: scipy's smoothing spline, which no longer passes through the data
    smooth = hk.thin_plate(uv, h, 1e-3)
    ref = RBFInterpolator(uv, h, kernel="thin_plate_spline", smoothing=1e-3)
    flat = hk.ray_depths(q, np.zeros(3), np.eye(3)[:2], np.eye(3)[2], 1.0, smooth, 1e-12, 1e-6)
    assert np.abs(flat - ref(q)).max() < 1e-9
    at = hk.ray_depths(uv, np.zeros(3), np.eye(3)[:2], np.eye(3)[2], 1.0, smooth, 1e-12, 1e-6)
    assert np.abs(at - h).max() > 1e-6
    # the cubic spline, and the mean of the two
    for share in (1.0, 0.5):
        mixed = hk.thin_plate(uv, h, 1e-3, cubic=share)
        cub = RBFInterpolator(uv, h, kernel="cubic", smoothing=1e-3)
        flat = hk.ray_depths(q, np.zeros(3), np.eye(3)[:2], np.eye(3)[2], 1.0, mixed, 1e-12,
                             1e-6)
        assert np.abs(flat - (share * cub(q) + (1 - share) * ref(q))).max() < 1e-9


def test_the_quintic_spline_matches_scipy_and_carries_a_quadratic_into_a_hole() -> None:
    """``thin_plate(quintic=True)``: scipy's quintic with its quadratic term; on a ring
    around a hole in a paraboloid it fills the hole with the paraboloid, where the thin
    plate and cubic mix flattens it."""
    rng = np.random.default_rng(7)
    uv = rng.uniform(-1, 1, (1200, 2))
    uv = uv[np.hypot(*uv.T) > 0.8]  # a ring: nothing within 0.8 of the centre
    h = 0.4 * uv[:, 0] ** 2 + 0.1 * uv[:, 0] * uv[:, 1] - 0.2 * uv[:, 1] ** 2 + 0.3 * uv[:, 0]
    q = rng.uniform(-0.5, 0.5, (200, 2))
    truth = 0.4 * q[:, 0] ** 2 + 0.1 * q[:, 0] * q[:, 1] - 0.2 * q[:, 1] ** 2 + 0.3 * q[:, 0]
    at = {}
    for quintic in (False, True):
        spline = hk.thin_plate(uv, h, 1e-4, 0.5, quintic=quintic)
        at[quintic] = hk.ray_depths(q, np.zeros(3), np.eye(3)[:2], np.eye(3)[2], 1.0, spline,
                                    1e-12, 1e-6)
    ref = RBFInterpolator(uv, h, kernel="quintic", degree=2, smoothing=1e-4)
    assert np.abs(at[True] - ref(q)).max() < 1e-8
    assert np.abs(at[True] - truth).max() < 1e-9  # a quadratic is reproduced
    assert np.abs(at[False] - truth).max() > 1e-4  # the thin plate and cubic sag
    # too few points for a quadratic term, or all on a conic: no spline
    assert hk.thin_plate(uv[:5], h[:5], quintic=True) is None
    line = np.column_stack([uv[:, 0], 2 * uv[:, 0]])
    assert hk.thin_plate(line, h, quintic=True) is None


def test_a_ring_one_quadratic_fits_to_its_noise_is_curved() -> None:
    """``_hole_patch._curved``: a cylinder's or dome's ring with noise is one quadratic
    within a few noise levels; a rough ring (a scanned surface's bumps) is not; a ring of
    few points or without noise never is."""
    from asrbf_mesh._hole_patch import _CURVED_MIN, _curved, _ring_noise

    rng = np.random.default_rng(3)
    uv = rng.uniform(-1, 1, (900, 2))
    uv = uv[np.hypot(*uv.T) > 0.5]
    shaft = 0.5 * uv[:, 0] ** 2 + 0.002 * rng.standard_normal(len(uv))
    rough = shaft + 0.02 * np.sin(9 * uv[:, 0]) * np.cos(7 * uv[:, 1])
    assert _curved(uv, shaft, _ring_noise(uv, shaft))
    assert not _curved(uv, rough, _ring_noise(uv, rough))
    assert not _curved(uv[:_CURVED_MIN - 1], shaft[:_CURVED_MIN - 1], 1e-4)
    assert not _curved(uv, 0.5 * uv[:, 0] ** 2, 0.0)


def test_a_rings_noise_is_measured_and_a_smooth_ring_has_none() -> None:
    """The fill's thin plate smooths by the ring's noise (``_hole_patch._ring_noise``):
    the variance of heights about local quadratic fits, near the true one for Gaussian
    noise on a curved surface, near zero without noise."""
    from asrbf_mesh._hole_patch import _ring_noise

    rng = np.random.default_rng(4)
    uv = rng.uniform(-1, 1, (1200, 2))
    surface = 0.3 * uv[:, 0] ** 2 - 0.2 * uv[:, 0] * uv[:, 1] + 0.1 * np.sin(2 * uv[:, 1])
    assert _ring_noise(uv, surface) < 1e-8
    for sigma in (1e-3, 1e-2):
        got = _ring_noise(uv, surface + rng.normal(0.0, sigma, len(uv)))
        assert 0.7 < np.sqrt(got) / sigma < 1.3, (sigma, np.sqrt(got))
    assert _ring_noise(uv[:20], surface[:20]) == 0.0  # too few to tell


def test_inside_any_closed_counts_corners_and_edges() -> None:
    xy = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    faces = np.array([[0, 1, 2]])
    pts = np.array([[0.2, 0.2], [0.0, 0.0], [0.5, 0.0], [0.5, 0.5], [0.6, 0.6], [-0.1, 0.2]])
    cand = np.zeros(len(pts), np.int64)
    assert hk.inside_any(pts, xy, faces, cand).tolist() == [True, False, False, False,
                                                           False, False]
    assert hk.inside_any(pts, xy, faces, cand, closed=True).tolist() == [True, True, True,
                                                                        True, False, False]


def test_grid_triangle_depths_take_each_vertex_from_a_triangle_of_its_piece() -> None:
    from asrbf_mesh._holes_kernels import grid_triangle_depths

    g = np.array([0.0, 1.0, 2.0])  # a 3 x 3 grid, nodes row-major: node = 3 j + i
    corners = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0]])
    square = np.column_stack([corners, corners[:, 0] + 2.0 * corners[:, 1]])  # z = x + 2 y
    xyz = np.vstack([square, square[[0, 1, 3]] + [0.0, 0.0, 10.0]])  # the same, 10 higher
    faces = np.array([[0, 1, 2], [0, 2, 3],   # piece 0: the square
                      [4, 5, 6],              # piece 1: its lower-left half, 10 higher
                      [1, 2, 3]])             # no piece: never used
    piece = np.array([0, 0, 1, -1])
    key = np.array([0 * 9 + 4,    # piece 0, node (1, 1): 3
                    1 * 9 + 4,    # piece 1, node (1, 1): on its hypotenuse, 13
                    1 * 9 + 8,    # piece 1, node (2, 2): outside its triangle
                    -1,           # skipped
                    0 * 9 + 2])   # piece 0, node (2, 0): a corner, 2
    depth, tri = grid_triangle_depths(g, g, xyz, faces, piece, key)
    assert np.allclose(depth[[0, 1, 4]], [3.0, 13.0, 2.0])
    assert np.isnan(depth[[2, 3]]).all() and tri[[2, 3]].tolist() == [-1, -1]
    assert tri[0] in (0, 1) and tri[1] == 2 and tri[4] == 0
    with pytest.raises(ValueError, match="one piece per triangle"):
        grid_triangle_depths(g, g, xyz, faces, piece[:2], key)
    with pytest.raises(ValueError, match="indexes a point"):
        grid_triangle_depths(g, g, xyz, faces + 10, piece, key)
