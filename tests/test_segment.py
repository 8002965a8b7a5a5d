"""Segmentation into smooth height-field pieces (piecewise networks, first block)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from _grids import grid_faces, height_grid

import asrbf_mesh as am
from asrbf_mesh._validate import strict_json

NX, NY = 40, 20  # a range grid of unit spacing; the cliff runs along x = 20


def smooth(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    return 2.0 * np.sin(x / 9.0) * np.cos(y / 7.0)


def cliff(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The smooth surface, raised by ten spacings where x >= 20 (a vertical cliff)."""
    return smooth(x, y) + np.where(x >= 19.5, 10.0, 0.0)


def grid(func, nx: int = NX, ny: int = NY) -> tuple[np.ndarray, np.ndarray]:
    return height_grid(func, nx, ny, x=(0.0, nx - 1.0), y=(0.0, ny - 1.0))


def with_fragment() -> tuple[np.ndarray, np.ndarray]:
    """The smooth grid plus a floating 5 x 2 fragment beside it, 5 spacings away, 30 up."""
    pts, faces = grid(smooth)
    fx, fy = np.meshgrid(np.arange(5.0) + NX + 4, np.arange(2.0) + 5)
    frag = np.c_[fx.ravel(), fy.ravel(), np.full(10, 30.0)]
    return np.vstack([pts, frag]), np.vstack([faces, grid_faces(5, 2) + len(pts)])


def test_a_range_grid_saved_as_points_is_triangulated_by_its_lattice() -> None:
    from asrbf_mesh._footprint import lattice_faces

    pts, _ = grid(cliff)
    pts = pts * [0.25, 0.25, 1.0] + [1000.0, -7.0, 0.0]  # steps 0.25, offset
    faces = lattice_faces(pts)
    assert faces is not None and len(faces) == 2 * (NX - 1) * (NY - 1)
    a, b, c = pts[faces[:, 0]], pts[faces[:, 1]], pts[faces[:, 2]]
    cross = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    assert (cross > 0).all()  # counter-clockwise from +z
    assert np.isclose(cross.sum() / 2, (NX - 1) * (NY - 1) * 0.0625)
    # each cell's split takes the diagonal with the smaller depth change: the triangle's
    # diagonal (its long edge p-q) against the cell's other one (r and the fourth corner)
    depth = {tuple(np.round(v[:2], 6)): v[2] for v in pts}
    for tri in pts[faces]:
        side = np.linalg.norm(tri[[1, 2, 0], :2] - tri[:, :2], axis=1)
        k = int(np.argmax(side))  # edge k joins corners k and k + 1
        p, q, r = tri[k], tri[(k + 1) % 3], tri[(k + 2) % 3]
        fourth = depth[tuple(np.round(p[:2] + q[:2] - r[:2], 6))]
        assert abs(p[2] - q[2]) <= abs(r[2] - fourth)
    # in any order, the same triangles; missing points leave their cells open
    rng = np.random.default_rng(0)
    order = rng.permutation(len(pts))
    again = lattice_faces(pts[order])
    assert sorted(map(tuple, np.sort(order[again], axis=1))) == sorted(
        map(tuple, np.sort(faces, axis=1)))
    keep = np.ones(len(pts), bool)
    keep[[NX + 5, 3 * NX + 7]] = False  # two inner points
    holed = lattice_faces(pts[keep])
    assert len(holed) == len(faces) - 2 * 4  # four cells lose one triangle each, twice
    # float32 coordinates are still a lattice, and so is any scale
    assert lattice_faces(pts.astype(np.float32).astype(np.float64)) is not None
    for scale in (1e-250, 1e250):
        np.testing.assert_array_equal(lattice_faces(pts * scale), faces)


@pytest.mark.parametrize("change", ["random", "jitter", "copy", "aspect", "sparse", "few",
                                    "tiny gap"])
def test_points_that_are_no_lattice_get_none(change: str) -> None:
    from asrbf_mesh._footprint import lattice_faces

    pts, _ = grid(smooth)
    rng = np.random.default_rng(1)
    if change == "random":
        pts = rng.random((800, 3))
    elif change == "jitter":
        pts = pts + [0.01, 0.0, 0.0] * rng.standard_normal(pts.shape)
    elif change == "copy":
        pts = np.vstack([pts, pts[7]])
    elif change == "aspect":
        pts = pts * [2.0, 1.0, 1.0]
    elif change == "sparse":
        pts = pts[::5]
    elif change == "tiny gap":  # a step of 1e-300 would make 1e300 nodes a row
        pts = np.vstack([pts, pts[0] + [1e-300, 0.5, 0.0]])
    else:
        pts = pts[:3]
    assert lattice_faces(pts) is None


def _cloud(pts: np.ndarray, how: str) -> np.ndarray:
    """The grid's points as a bare cloud: as they are (a lattice) or jittered off it."""
    if how == "cloud":
        return pts
    return pts + 1e-3 * np.random.default_rng(2).standard_normal(pts.shape) * [1, 1, 0]


@pytest.mark.parametrize("cloud", [False, True], ids=["faces", "cloud"])
def test_a_smooth_surface_is_one_piece(cloud: bool) -> None:
    pts, faces = grid(smooth)
    seg = am.segment(pts if cloud else am.Scan(pts, faces))
    assert seg.n_pieces == 1 and not seg.small.any()
    assert seg.labels.tolist() == [0] * len(pts)
    assert seg.source == ("cloud" if cloud else "faces")


@pytest.mark.parametrize("cloud", [False, "cloud", "jittered"])
def test_a_cliff_splits_the_scan_in_two_pieces(cloud) -> None:
    pts, faces = grid(cliff)
    seg = am.segment(_cloud(pts, cloud) if cloud else am.Scan(pts, faces))
    assert seg.n_pieces == 2 and not seg.small.any()
    truth = (pts[:, 0] >= 19.5).astype(np.int64)  # point 0 (x = 0) is in piece 0
    np.testing.assert_array_equal(seg.labels, truth)
    assert seg.sizes.tolist() == [20 * NY, 20 * NY]
    assert seg.n_cut > 0


def spiral(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """A ramp that winds once around (19.7, 20.3), ten spacings up: a cliff along one ray
    from the centre to the border, and one connected surface around the cliff's end."""
    return 10.0 * (np.arctan2(y - 20.3, x - 19.7) % (2 * np.pi)) / (2 * np.pi)


@pytest.mark.parametrize("cloud", [False, "cloud", "jittered"])
def test_a_piece_wrapping_around_a_cliff_end_is_split(cloud) -> None:
    from asrbf_mesh._segment_kernels import jump_pairs

    pts, faces = grid(spiral, 40, 40)
    seg = am.segment(_cloud(pts, cloud) if cloud else am.Scan(pts, faces))
    # the cut triangles leave one piece around the centre; rule 4 splits it
    assert seg.n_split >= 1 and seg.to_dict()["n_split"] == seg.n_split
    big = np.flatnonzero(~seg.small)
    assert len(big) == 2 and seg.sizes[big].sum() >= 0.98 * len(pts)
    for piece in big:  # no part holds a jump any more: each is a height field
        own = pts[seg.labels == piece]
        assert len(jump_pairs(own, 2.0, np.tan(np.radians(80.0)), 5.0)) == 0
    unsplit = am.segment(am.Scan(pts, faces), jump_factor=1e6)  # no jump at all
    assert unsplit.n_split == 0


def test_the_split_spiral_fits_far_better_with_fewer_neurons() -> None:
    pts, faces = grid(spiral, 40, 40)
    scan = am.Scan(pts, faces)
    single = am.fit(scan, seed=0, pieces=1, progress=False)
    pieces = am.fit(scan, seed=0, progress=False)
    assert pieces.n_pieces >= 2 and pieces.n_neurons < single.n_neurons
    assert pieces.info["ebar"] < 0.3 * single.info["ebar"]


def test_the_prototype_rule_splits_the_cliff_too() -> None:
    pts, faces = grid(cliff)
    seg = am.segment(am.Scan(pts, faces), wall_angle_deg=72.5, jump_factor=3.0)
    np.testing.assert_array_equal(seg.labels, (pts[:, 0] >= 19.5).astype(np.int64))


def test_the_cliff_is_found_along_another_view_axis() -> None:
    pts, faces = grid(cliff)
    seg = am.segment(am.Scan(pts[:, [2, 0, 1]], faces), view_axis="x")  # depth along x
    np.testing.assert_array_equal(seg.labels, (pts[:, 0] >= 19.5).astype(np.int64))


@pytest.mark.parametrize("cloud", [False, True], ids=["faces", "cloud"])
def test_a_floating_fragment_is_its_own_small_piece(cloud: bool) -> None:
    pts, faces = with_fragment()
    seg = am.segment(pts if cloud else am.Scan(pts, faces))
    assert seg.n_pieces == 2
    assert seg.sizes.tolist() == [NX * NY, 10]
    assert seg.small.tolist() == [False, True]
    assert (seg.labels[-10:] == 1).all() and (seg.labels[:-10] == 0).all()
    assert seg.indices(1).tolist() == list(range(NX * NY, NX * NY + 10))
    # with a lower threshold the fragment is not small
    assert not am.segment(pts, min_piece_points=10).small.any()


def test_every_point_gets_a_piece() -> None:
    pts, faces = grid(cliff)
    # points used by no triangle: an extra point near each side, and the faces of one
    # column left out; each joins the piece of its nearest kept vertex
    extra = np.array([[3.3, 4.4, smooth(3.3, 4.4)], [30.2, 7.1, cliff(30.2, 7.1)]])
    pts2 = np.vstack([pts, extra])
    keep = np.ones((NY - 1, NX - 1), dtype=bool)
    keep[:, 0] = False
    seg = am.segment(am.Scan(pts2, grid_faces(NX, NY, keep)))
    truth = (pts2[:, 0] >= 19.5).astype(np.int64)
    np.testing.assert_array_equal(seg.labels, truth)
    assert seg.sizes.sum() == len(pts2) and seg.labels.min() == 0


@pytest.mark.parametrize("points", [[[0.0, 0.0, 0.0]], [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]],
                                    [[0.0, 0.0, 0.0], [1.0, 1.0, 0.0], [2.0, 2.0, 5.0]],
                                    [[1.0, 1.0, 0.0]] * 4])
def test_scans_without_a_surface_are_one_piece(points: list) -> None:
    seg = am.segment(points)
    assert seg.n_pieces == 1 and seg.labels.tolist() == [0] * len(points)
    assert seg.small.tolist() == [True]


def test_same_input_same_labels_in_a_stable_order() -> None:
    rng = np.random.default_rng(3)
    pts, _ = grid(cliff)
    pts = pts + rng.normal(0, 0.05, pts.shape)
    pts = np.vstack([pts, with_fragment()[0][-10:]])
    first = am.segment(pts)
    again = am.segment(pts.copy())
    np.testing.assert_array_equal(first.labels, again.labels)
    # pieces are numbered by their smallest point index
    _, where = np.unique(first.labels, return_index=True)
    assert (np.diff(where) > 0).all() and first.labels[0] == 0


def test_the_result_is_frozen_and_summarised() -> None:
    pts, faces = with_fragment()
    seg = am.segment(am.Scan(pts, faces), min_piece_points=11)
    with pytest.raises(ValueError):
        seg.labels[0] = 5
    with pytest.raises(AttributeError):
        seg.n_cut = 3  # type: ignore[misc]
    d = json.loads(strict_json(seg.to_dict()))
    assert d["n_pieces"] == 2 and d["sizes"] == [NX * NY, 10]
    assert d["n_small"] == 1 and d["points_in_small"] == 10
    assert d["min_piece_points"] == 11 and d["view_axis"] == "z"
    assert d["wall_angle_deg"] == 80.0 and d["jump_factor"] == 5.0
    assert "2 pieces" in repr(seg)
    assert isinstance(seg, am.Segmentation)


@pytest.mark.parametrize(("kw", "name"), [
    ({"view_axis": "w"}, "view_axis"),
    ({"view_axis": None}, "view_axis"),
    ({"wall_angle_deg": 0}, "wall_angle_deg"),
    ({"wall_angle_deg": 95.0}, "wall_angle_deg"),
    ({"wall_angle_deg": float("nan")}, "wall_angle_deg"),
    ({"wall_angle_deg": "steep"}, "wall_angle_deg"),
    ({"jump_factor": 1.0}, "jump_factor"),
    ({"jump_factor": float("inf")}, "jump_factor"),
    ({"min_piece_points": 0}, "min_piece_points"),
    ({"min_piece_points": 2.5}, "min_piece_points"),
    ({"min_piece_points": True}, "min_piece_points"),
])
def test_bad_parameters_raise_config_errors_naming_them(kw: dict, name: str) -> None:
    pts, _ = grid(smooth, 5, 5)
    with pytest.raises(am.ConfigError, match=f"^{name} "):
        am.segment(pts, **kw)


@pytest.mark.parametrize("points", [np.zeros((0, 3)), [[0.0, np.nan, 1.0]], [[1.0, 2.0]]])
def test_bad_points_raise_scan_errors(points) -> None:
    with pytest.raises(am.ScanError):
        am.segment(points)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_close_components_match_scipy_on_the_pairs_graph(seed: int) -> None:
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    from asrbf_mesh._segment_kernels import close_components

    rng = np.random.default_rng(seed)
    xy = np.vstack([rng.uniform(0, 10, (300, 2)), rng.normal(3, 0.3, (200, 2))])
    gap = 0.45
    pairs = cKDTree(xy).query_pairs(gap, output_type="ndarray")
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(500, 500))
    want = connected_components(graph, directed=False)[1]
    got = close_components(xy, gap)
    assert got.tolist() == want.tolist()
    assert len(np.unique(got)) > 5  # the case has several components to tell apart


def test_close_components_find_copies_a_billionth_of_the_extent_apart() -> None:
    """The grid holds 1.4e9 cells a side here (triangulate's test for copies of a point)."""
    from asrbf_mesh._segment_kernels import close_components

    rng = np.random.default_rng(5)
    xy = rng.uniform(0, 100, (2000, 2))
    copies = rng.choice(2000, 40, replace=False)
    near = xy[copies] + rng.uniform(-2e-8, 2e-8, (40, 2))  # within 1e-9 of the extent
    pts = np.vstack([xy, near])
    got = close_components(pts, 1e-9 * 100)
    want = np.arange(2040)
    want[2000:] = copies
    assert got.tolist() == np.unique(want, return_inverse=True)[1].tolist()


def test_smooth_fits_match_numpy_least_squares() -> None:
    """The compiled rule 1b against a k-d tree and numpy's least squares, row by row."""
    from scipy.spatial import cKDTree

    from asrbf_mesh._grid_knn import point_grid
    from asrbf_mesh._segment_kernels import smooth_fits

    rng = np.random.default_rng(2)
    xy = rng.uniform(0, 1, (3000, 2))
    z = np.sin(3 * xy[:, 0]) + np.where(xy[:, 1] > 0.5, 0.3, 0.0) + rng.normal(0, 0.002, 3000)
    tree = cKDTree(xy)
    near_cliff = np.flatnonzero(np.abs(xy[:, 1] - 0.5) < 0.03)
    # small triangles: a point and its two nearest, half of them at the step
    rows = tree.query(xy[np.r_[rng.choice(3000, 300), rng.choice(near_cliff, 300)]], k=3)[1]
    got = smooth_fits(xy, z, rows, 16, 0.1, point_grid(xy))
    _, nb = tree.query(xy[rows].mean(axis=1), k=16)
    want = []
    for t, n in zip(rows, nb, strict=True):
        p = xy[n] - xy[t].mean(axis=0)
        p /= np.linalg.norm(p, axis=1).max()
        a = np.c_[np.ones(16), p, p[:, 0] ** 2, p[:, 0] * p[:, 1], p[:, 1] ** 2]
        zn = z[n] - z[n].mean()
        res = zn - a @ np.linalg.lstsq(a, zn, rcond=None)[0]
        want.append(np.sqrt((res ** 2).mean()) < 0.1 * np.ptp(z[t]))
    assert got.tolist() == want
    assert 50 < got.sum() < 550  # both answers occur (measured: 172 of 600)
    pairs = smooth_fits(xy, z, rows[:200, :2], 16, 0.1, point_grid(xy))  # rule 4's pairs
    assert pairs.shape == (200,)
    with pytest.raises(ValueError, match="indexes no point"):
        smooth_fits(xy, z, np.array([[0, 1, 3000]]), 16, 0.1, point_grid(xy))


def test_close_components_reject_bad_input() -> None:
    from asrbf_mesh._segment_kernels import close_components

    assert close_components(np.zeros((0, 2)), 1.0).shape == (0,)
    with pytest.raises(ValueError):
        close_components(np.array([[0.0, np.nan]]), 1.0)
    with pytest.raises(ValueError):
        close_components(np.zeros((3, 2)), 0.0)
    far = np.array([[0.0, 0.0], [1e12, 0.0], [0.5, 0.0]])  # too many cells: the pairs
    assert close_components(far, 1.0).tolist() == [0, 1, 0]


def quantised_ramp() -> tuple[np.ndarray, np.ndarray]:
    """A gentle ramp (slope 0.4) whose depths come in levels 8 apart, as a depth camera's:
    a riser every 20 columns, steeper than the wall angle and longer than 5 median edges."""
    return height_grid(lambda x, y: np.round(0.4 * x / 8.0) * 8.0, 2000, 3,
                       x=(0.0, 1999.0), y=(0.0, 2.0))


def test_steps_of_a_few_depth_quanta_are_not_cut() -> None:
    pts, faces = quantised_ramp()
    seg = am.segment(am.Scan(pts, faces))
    assert seg.n_pieces == 1 and seg.n_cut == 0
    every = am.segment(am.Scan(pts, faces), min_step=0.0)  # each riser cut
    assert every.n_pieces == 101 and every.n_cut > 0
    assert seg.to_dict()["min_step"] == pytest.approx(0.01 * float(np.ptp(np.percentile(
        pts[:, 2], [1, 99]))))


def test_a_cliff_below_the_minimum_step_is_not_cut() -> None:
    pts, faces = grid(cliff)
    assert am.segment(am.Scan(pts, faces), min_step=9.0).n_pieces == 2
    assert am.segment(am.Scan(pts, faces), min_step=15.0).n_pieces == 1
    with pytest.raises(am.ConfigError, match="min_step"):
        am.segment(pts, min_step=-1.0)


def steep_sine(noise: float = 0.0) -> np.ndarray:
    """A 100 x 100 grid of the unit square, z = sin(3 pi x) cos(3 pi y): slopes up to 13."""
    g = np.linspace(0.0, 1.0, 100)
    x, y = np.meshgrid(g, g)
    z = np.sin(3 * np.pi * x) * np.cos(3 * np.pi * y)
    z = z + noise * np.random.default_rng(0).standard_normal(z.shape)
    return np.c_[x.ravel(), y.ravel(), z.ravel()]


@pytest.mark.parametrize("noise", [0.0, 0.005])
def test_a_steep_smooth_surface_is_one_piece(noise: float) -> None:
    # its slopes pass the wall angle (13,792 triangles cut into 24 pieces, 180 with the
    # noise, before rule 1b); a quadratic fits the points around each of them
    seg = am.segment(steep_sine(noise))
    assert seg.n_pieces == 1
    # the cliff next to the same slopes is still cut
    pts = steep_sine()
    pts[:, 2] += np.where(pts[:, 0] >= 0.5, 3.0, 0.0)
    assert am.segment(pts).n_pieces == 2


def test_values_that_merely_repeat_are_not_depth_levels() -> None:
    from asrbf_mesh._segment import depth_quanta

    rng = np.random.default_rng(0)
    assert depth_quanta(np.repeat(np.sort(rng.random(300)), 3)) is None  # uneven gaps
    q = depth_quanta(np.repeat(np.arange(300) * 0.25, 3))  # a camera's even levels
    assert q is not None and float(q.at(np.array([10.0]))[0]) == 0.25


def test_steep_smooth_bumps_hold_no_cliff_to_split() -> None:
    # eight Gaussian bumps, slopes up to 8.6: every flank holds rule 4's jump pairs (two
    # points two spacings apart, steeper than the wall angle, far apart in depth), and
    # the splits cut the grid into 36 pieces before those pairs took the smoothness test
    rng = np.random.default_rng(0)
    g = np.linspace(0.0, 1.0, 100)
    x, y = np.meshgrid(g, g)
    z = sum(np.exp(-((x - a) ** 2 + (y - b) ** 2) / 0.01) for a, b in rng.random((8, 2)))
    assert am.segment(np.c_[x.ravel(), y.ravel(), z.ravel()]).n_pieces == 1


def test_a_noisy_steep_smooth_surface_is_one_piece(monkeypatch) -> None:
    # noise of 1 % of the depth range makes triangles steep; rule 1b's quadratic misses
    # its points by that noise, more than a tenth of a noisy triangle's depth extent: 465
    # pieces on 100 x 100 before the scan's noise scale was allowed for
    import asrbf_mesh._segment as S

    rng = np.random.default_rng(5)
    g = np.linspace(0.0, 1.0, 70)
    x, y = np.meshgrid(g, g)
    z = np.sin(3 * np.pi * x) * np.cos(3 * np.pi * y) + 0.02 * rng.standard_normal(x.shape)
    pts = np.c_[x.ravel(), y.ravel(), z.ravel()]
    assert 0.01 < S._Smooth(pts).noise() < 0.02  # the quadratic's residual: ~0.8 sigma
    assert am.segment(pts).n_pieces == 1
    monkeypatch.setattr(S, "NOISE_SMOOTH", 0.0)
    assert am.segment(pts).n_pieces > 20


def test_a_noisy_cliff_still_splits() -> None:
    rng = np.random.default_rng(6)
    pts, faces = grid(cliff)
    noisy = pts + np.array([0.0, 0.0, 0.05]) * rng.standard_normal(pts.shape)
    for scan in (noisy, am.Scan(noisy, faces)):
        seg = am.segment(scan)
        assert seg.n_pieces == 2
        np.testing.assert_array_equal(seg.labels, (pts[:, 0] >= 19.5).astype(np.int64))


@pytest.mark.parametrize("sampling", ["random", "rows three times apart"])
def test_an_irregularly_sampled_smooth_cloud_is_one_piece(sampling: str) -> None:
    # points strewn at random (a LiDAR tile) have Delaunay edges about 2.3 times their
    # median nearest-neighbour distance: measured against that distance, half the edges
    # were long, and 20,000 points fell apart into thousands of pieces
    rng = np.random.default_rng(0)
    if sampling == "random":
        xy = rng.uniform(0, 100, size=(20_000, 2))
    else:
        gx, gy = np.meshgrid(np.arange(0, 100, 3.0), np.arange(0, 100, 1.0))
        xy = np.column_stack([gx.ravel(), gy.ravel()]) + rng.normal(0, 0.05, (gx.size, 2))
    pts = np.column_stack([xy, 3 * np.sin(xy[:, 0] / 20) * np.cos(xy[:, 1] / 30)])
    seg = am.segment(pts)
    assert seg.sizes.max() >= 0.99 * len(pts)
