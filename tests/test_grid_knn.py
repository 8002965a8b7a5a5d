"""Compiled spatial queries of the tail refinement: k nearest samples and greedy spread."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from asrbf_mesh._grid_knn import _nearest, plane_slopes, point_grid, spread


def _clouds() -> dict[str, np.ndarray]:
    rng = np.random.default_rng(0)
    return {
        "uniform": rng.random((600, 2)),
        "on a line": np.c_[rng.random(300), np.zeros(300)],
        "copies": np.repeat(rng.random((60, 2)), 4, axis=0),
        "cluster and strays": np.r_[rng.random((400, 2)) * 0.01, [[5.0, 5.0], [5.0, 4.0]]],
        "grid": np.stack(np.meshgrid(np.arange(25.0), np.arange(20.0)), -1).reshape(-1, 2),
        "few": rng.random((5, 2)),
    }


@pytest.mark.parametrize("name", list(_clouds()))
def test_the_grid_finds_the_k_nearest_points(name: str) -> None:
    xy = _clouds()[name]
    grid = point_grid(xy)
    k = min(8, len(xy))
    best_d, best_i = np.empty(k), np.empty(k, np.int64)
    for q in range(len(xy)):
        held = _nearest.py_func(xy, xy[q], k, *grid, best_d, best_i)
        truth = np.sort(((xy - xy[q]) ** 2).sum(axis=1))[:k]
        assert held == k
        np.testing.assert_allclose(best_d, truth, rtol=0, atol=1e-15)
        np.testing.assert_allclose(((xy[best_i] - xy[q]) ** 2).sum(axis=1), best_d, atol=1e-15)


@pytest.mark.parametrize("name", ["uniform", "cluster and strays", "grid"])
def test_plane_slopes_are_least_squares_planes_through_the_nearest_samples(name) -> None:
    xy = _clouds()[name]
    rng = np.random.default_rng(1)
    z = 0.3 * xy[:, 0] - 0.7 * xy[:, 1] + 0.01 * rng.normal(size=len(xy))
    at = np.arange(0, len(xy), 3)
    got = plane_slopes(xy, z, at, 8, 2.0, 0.5, *point_grid(xy))
    _, near = cKDTree(xy).query(xy[at], k=8)
    ref = []
    for m, nb in enumerate(near):
        if name == "grid":  # ties among equal distances: the grid's own neighbours
            d, i = np.empty(8), np.empty(8, np.int64)
            _nearest.py_func(xy, xy[at[m]], 8, *point_grid(xy), d, i)
            nb = i
        d, dz = xy[nb] - xy[nb].mean(axis=0), z[nb] - z[nb].mean()
        s = np.linalg.solve(d.T @ d + 1e-12 * np.eye(2), d.T @ dz) * [2.0, 0.5]  # ridged
        ref.append(s @ s)
    np.testing.assert_allclose(got, ref, rtol=1e-7, atol=1e-12)


def test_a_flat_or_degenerate_neighbourhood_has_no_slope() -> None:
    xy = np.repeat([[0.5, 0.5]], 10, axis=0)
    got = plane_slopes(xy, np.zeros(10), np.arange(10), 8, 1.0, 1.0, *point_grid(xy))
    assert np.all(np.isfinite(got)) and np.all(got == 0.0)


@pytest.mark.parametrize("radius", [0.0, 0.03, 0.1, 0.5, 5.0])
def test_spread_is_the_greedy_subset_in_order(radius: float) -> None:
    xy = _clouds()["uniform"]
    kept: list[int] = []
    for i in range(len(xy)):  # the rule, by brute force
        if all(np.hypot(*(xy[i] - xy[j])) > radius for j in kept):
            kept.append(i)
    assert spread(xy, radius).tolist() == kept
    assert spread(np.zeros((0, 2)), radius).tolist() == []


@pytest.mark.parametrize("name", list(_clouds()))
def test_knn_and_nearest_3d_match_a_kd_tree(name: str) -> None:
    from asrbf_mesh._grid_knn import knn, nearest_3d

    xy = _clouds()[name]
    rng = np.random.default_rng(2)
    k = min(4, len(xy))
    at = np.arange(0, len(xy), 2)
    d, i = knn(xy, at, k)
    ref_d, _ = cKDTree(xy).query(xy[at], k=k)
    np.testing.assert_array_equal(d, ref_d.reshape(d.shape))
    np.testing.assert_allclose(np.hypot(*(xy[i] - xy[at, None]).transpose(2, 0, 1)), d,
                               atol=1e-15)
    pts = np.c_[xy, rng.normal(size=len(xy))]  # depth: the 3D nearest need not be near in xy
    q = np.c_[rng.random((50, 2)) * np.ptp(xy, axis=0) + xy.min(axis=0), rng.normal(size=50)]
    got = nearest_3d(pts, q)
    ref_d, _ = cKDTree(pts).query(q)
    np.testing.assert_allclose(np.linalg.norm(pts[got] - q, axis=1), ref_d, rtol=1e-12)
    with pytest.raises(ValueError, match="k must be"):
        knn(xy, at, len(xy) + 1)


def test_components_by_union_find_match_scipy() -> None:
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    from asrbf_mesh._segment_kernels import components

    rng = np.random.default_rng(3)
    faces = rng.integers(0, 400, size=(150, 3))
    comp, used = components(500, faces)
    a, b = faces.ravel(), faces[:, [1, 2, 0]].ravel()
    _, ref = connected_components(coo_matrix((np.ones(len(a)), (a, b)), shape=(500, 500)),
                                  directed=False)
    # the same partition; labels are each component's smallest point
    assert all(len(set(comp[ref == c])) == 1 for c in np.unique(ref))
    assert len(np.unique(comp)) == len(np.unique(ref))
    assert np.all(comp <= np.arange(500)) and np.all(comp[comp] == comp)
    assert used.tolist() == np.isin(np.arange(500), faces).tolist()


def test_a_far_stray_point_does_not_put_the_others_in_one_cell() -> None:
    # the grid spans the points' robust box; the stray sits in a border cell, found exactly
    from asrbf_mesh._grid_knn import knn

    rng = np.random.default_rng(4)
    xy = np.r_[rng.random((2000, 2)), [[1e9, 0.5]], [[-3e12, -7e11]]]
    lo, h, gx, gy, start, items = point_grid(xy)
    assert gx * gy >= 500 and np.diff(start).max() < 40
    d, _ = knn(xy, np.arange(len(xy)), 3)
    ref, _ = cKDTree(xy).query(xy, k=3)
    np.testing.assert_array_equal(d, ref)


def test_jump_pairs_are_the_same_with_a_far_stray_point() -> None:
    from asrbf_mesh._segment_kernels import jump_pairs

    x, y = np.meshgrid(np.arange(60.0), np.arange(50.0))
    pts = np.c_[x.ravel(), y.ravel(), np.where(x.ravel() < 30, 0.0, 10.0)]
    stray = np.r_[pts, [[1e9, 3.0, 0.0]]]
    got = jump_pairs(stray, 1.5, 5.0, 2.0)
    assert len(got) > 40
    np.testing.assert_array_equal(got, jump_pairs(pts, 1.5, 5.0, 2.0))


@pytest.mark.parametrize("case", range(12))
def test_nearest_feature_is_scipys_feature_transform_ties_included(case: int) -> None:
    from scipy import ndimage

    from asrbf_mesh._grid_knn import nearest_feature

    rng = np.random.default_rng(case)
    for _ in range(25):
        ny, nx = (int(v) for v in rng.integers(1, 50, 2))
        kind = case % 4
        if kind == 0:  # sparse or dense random cells
            f = rng.random((ny, nx)) < rng.choice([0.003, 0.03, 0.3, 0.9])
        elif kind == 1:  # a lattice: cells equidistant from several features everywhere
            f = np.zeros((ny, nx), dtype=bool)
            f[int(rng.integers(3))::int(rng.integers(2, 7)),
              int(rng.integers(3))::int(rng.integers(2, 7))] = True
        elif kind == 2:  # a row and a broken column
            f = np.zeros((ny, nx), dtype=bool)
            f[rng.integers(ny), :] = True
            f[:, rng.integers(nx)] |= rng.random(ny) < 0.5
        else:  # disks: a piece map's occupied cells around holes
            yy, xx = np.mgrid[:ny, :nx]
            f = np.ones((ny, nx), dtype=bool)
            for _ in range(3):
                cy, cx, r = rng.integers(ny), rng.integers(nx), rng.integers(1, 12)
                f &= (yy - cy) ** 2 + (xx - cx) ** 2 > r * r
        if not f.any():
            f[rng.integers(ny), rng.integers(nx)] = True
        want = ndimage.distance_transform_edt(~f, return_distances=False, return_indices=True)
        assert np.array_equal(nearest_feature(f), want)


def test_nearest_feature_needs_a_2d_raster_with_a_feature() -> None:
    from asrbf_mesh._grid_knn import nearest_feature

    with pytest.raises(ValueError, match="no True cell"):
        nearest_feature(np.zeros((3, 3), dtype=bool))
    with pytest.raises(ValueError, match="2D"):
        nearest_feature(np.ones(4, dtype=bool))


@pytest.mark.parametrize("serial_below", [1, 10**9])
def test_jump_pairs_are_every_pair_close_in_the_plane_and_far_in_depth(
        serial_below: int, monkeypatch) -> None:
    """Against brute force, on points with many jumps, split over threads or not."""
    from asrbf_mesh import _network_kernels
    from asrbf_mesh._segment_kernels import jump_pairs

    monkeypatch.setattr(_network_kernels, "SERIAL_BELOW", serial_below)

    rng = np.random.default_rng(3)
    xy = rng.random((3000, 2)) * 10
    z = np.where(xy[:, 0] > 5, 4.0, 0.0) + rng.normal(0, 0.05, 3000)  # a cliff at x = 5
    z[rng.choice(3000, 40, replace=False)] += 9.0  # and spikes
    pts = np.c_[xy, z]
    r, slope, jump = 0.4, 5.0, 1.0
    d2 = ((xy[:, None] - xy[None]) ** 2).sum(-1)
    dz = np.abs(z[:, None] - z[None])
    want = np.argwhere(np.triu((d2 <= r * r) & (dz > jump) & (dz * dz > slope * slope * d2), 1))
    got = jump_pairs(pts, r, slope, jump)
    assert len(got) > 100
    np.testing.assert_array_equal(got, want)
