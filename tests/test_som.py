"""The SOM baseline (paper section 5.4): grid choice, training, our vertices, comparison."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import Delaunay

import asrbf_mesh as am
from asrbf_mesh.errors import AsrbfError, ConfigError, ScanError
from asrbf_mesh.evaluate._metro import MetroResult
from asrbf_mesh.evaluate._som import (
    SomComparison,
    SomMap,
    _ball_pivoting,
    compare_som,
    network_vertices,
    som_grid,
    train_som,
)

SHORT = 5_000  # training steps for small maps in tests (the default is 500 per node)


@pytest.fixture(scope="module")
def franke_scan(franke_points: np.ndarray) -> am.Scan:
    """The Franke points with a Delaunay triangulation of their (x, y): a holeless scan."""
    return am.Scan(franke_points, faces=Delaunay(franke_points[:, :2]).simplices)


@pytest.fixture(scope="module")
def comparison(franke_scan: am.Scan, franke_net: am.Network) -> SomComparison:
    return compare_som(franke_scan, franke_net, seed=0, iterations=SHORT, samples=5_000,
                       progress=False)


# ----------------------------------------------------------------------------- som_grid


@pytest.mark.parametrize(("k", "grid"), [
    (1056, (33, 32)), (1901, (44, 43)), (522, (23, 23)), (1527, (39, 39)),  # paper, Table 4
    (1, (1, 1)), (2, (2, 1)), (3, (2, 2)), (4, (2, 2)), (6, (3, 2)), (7, (3, 2)),
    (8, (3, 3)), (12, (4, 3)), (727, (27, 27)), (1564, (40, 39)), (3189, (57, 56)),
])
def test_som_grid_is_the_closest_near_square_grid(k: int, grid: tuple[int, int]) -> None:
    assert som_grid(k) == grid


@pytest.mark.parametrize("k", [1, 2, 3, 5, 17, 99, 100, 101, 997, 1901, 10_007])
def test_som_grid_is_near_square_and_no_near_square_grid_is_closer(k: int) -> None:
    rows, cols = som_grid(k)
    assert rows - cols in (0, 1)
    best = min(abs(r * c - k) for r in range(1, 200) for c in (r - 1, r) if c >= 1)
    assert abs(rows * cols - k) == best


def test_som_grid_tie_goes_to_the_square_grid() -> None:
    assert som_grid(3) == (2, 2)  # 2 x 1 and 2 x 2 are both one node off
    assert som_grid(18) == (4, 4)  # 4 x 4 and 5 x 4 are both two off
    assert som_grid(14) == (4, 4)  # 4 x 3 and 4 x 4 are both two off


@pytest.mark.parametrize("k", [0, -3, 2.5, True, "9", None])
def test_som_grid_rejects_non_positive_integers(k: object) -> None:
    with pytest.raises(ConfigError, match="k must be an integer >= 1"):
        som_grid(k)  # type: ignore[arg-type]


# ----------------------------------------------------------------------------- train_som


def test_train_som_is_deterministic_per_seed(syn) -> None:
    pts = syn.points(syn.franke, 30)
    a = train_som(pts, 36, seed=3, iterations=2_000)
    b = train_som(pts, 36, seed=3, iterations=2_000)
    c = train_som(pts, 36, seed=4, iterations=2_000)
    assert np.array_equal(a.nodes, b.nodes) and np.array_equal(a.dead, b.dead)
    assert not np.array_equal(a.nodes, c.nodes)


def test_train_som_result_fields(syn) -> None:
    pts = syn.points(syn.franke, 30)
    som = train_som(pts, 36, seed=0, iterations=SHORT)
    assert isinstance(som, SomMap)
    assert som.shape == (6, 6) and som.nodes.shape == (36, 3) and som.n_nodes == 36
    assert som.iterations == SHORT and som.seconds > 0 and som.seed == 0
    assert som.hits.sum() == len(pts)
    assert np.array_equal(som.dead, som.hits == 0)
    assert som.n_dead == int(som.dead.sum())
    assert som.live_nodes.shape == (36 - som.n_dead, 3)
    assert not som.nodes.flags.writeable
    d = som.to_dict()
    assert d["shape"] == [6, 6] and d["n_nodes"] == 36 and d["iterations"] == SHORT


def test_train_som_default_iterations_are_500_per_node(syn) -> None:
    som = train_som(syn.points(syn.plane, 10), 4, seed=0)
    assert som.shape == (2, 2) and som.iterations == 2_000


@pytest.mark.parametrize(("n", "steps"), [(4, 300), (36, 4_000), (110, 3_000)])
def test_train_som_equals_minisom_bit_for_bit(syn, n: int, steps: int) -> None:
    # the compiled loop is MiniSom's algorithm: same start, schedule, winner and update
    from minisom import MiniSom

    pts = syn.points(syn.franke, 25)
    rows, cols = som_grid(n)
    centre = pts.mean(axis=0)
    scale = np.sqrt(np.linalg.eigvalsh(np.cov(pts.T)).max())
    x = (pts - centre) / scale
    ref = MiniSom(rows, cols, 3, sigma=1.0, learning_rate=0.5,
                  decay_function="asymptotic_decay", sigma_decay_function="asymptotic_decay",
                  neighborhood_function="gaussian", topology="rectangular",
                  activation_distance="euclidean", random_seed=0)
    ref.pca_weights_init(x)
    order = np.arange(steps) % len(x)
    np.random.default_rng(7).shuffle(order)
    for t in range(steps):
        ref.update(x[order[t]], ref.winner(x[order[t]]), t, steps)
    som = train_som(pts, n, seed=7, iterations=steps)
    assert np.array_equal(som.nodes, ref.get_weights().reshape(-1, 3) * scale + centre)


def test_som_nodes_stay_on_a_plane(syn) -> None:
    # PCA initialization puts the nodes on the data's plane; every update is a convex
    # step toward a point of it: the nodes never leave the plane
    pts = syn.points(syn.plane, 30)
    som = train_som(pts, 36, seed=0, iterations=3_000)
    dev = som.nodes[:, 2] - syn.truth(syn.plane, som.nodes[:, :2])
    assert np.abs(dev).max() < 1e-9


def test_som_nodes_lie_near_a_curved_height_field(syn) -> None:
    pts = syn.points(syn.franke, 30)  # depth range about 24 mm, 80 x 60 mm
    som = train_som(pts, 36, seed=0, iterations=SHORT)
    live = som.live_nodes
    dev = np.abs(live[:, 2] - syn.truth(syn.franke, live[:, :2]))
    assert np.median(dev) < 0.5 and dev.max() < 3.0  # mm; nodes are local means
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    assert np.all((live >= lo - 1e-9) & (live <= hi + 1e-9))
    assert som.quantization_error < 8.0  # mm, about one node spacing


def test_train_som_accepts_a_scan(franke_scan: am.Scan) -> None:
    a = train_som(franke_scan, 16, seed=0, iterations=500)
    b = train_som(franke_scan.points, 16, seed=0, iterations=500)
    assert np.array_equal(a.nodes, b.nodes)


@pytest.mark.parametrize(("points", "kwargs", "error", "match"), [
    (np.zeros((50, 2)), {}, ScanError, r"\(N, 3\) array"),
    (np.full((50, 3), np.nan), {}, ScanError, "NaN or infinite"),
    (np.ones((50, 3)), {}, ScanError, "coincide"),
    (np.random.default_rng(0).random((50, 3)), {"n_nodes": 3}, ConfigError, "n_nodes must be"),
    (np.random.default_rng(0).random((50, 3)), {"n_nodes": 64}, ScanError,
     "at least 64 points"),
    (np.random.default_rng(0).random((50, 3)), {"iterations": 0}, ConfigError,
     "iterations must be"),
    (np.random.default_rng(0).random((50, 3)), {"seed": -1}, ConfigError, "seed must be"),
    (np.random.default_rng(0).random((50, 3)), {"seed": 1.5}, ConfigError, "seed must be"),
    (np.random.default_rng(0).random((50, 3)), {"seed": "a"}, ConfigError, "seed must be"),
])
def test_train_som_rejects_bad_input(points, kwargs, error, match) -> None:
    kw = {"n_nodes": 9} | kwargs
    with pytest.raises(error, match=match):
        train_som(points, **kw)


# ----------------------------------------------------------------------------- our vertices


def test_network_vertices_are_n_points_of_the_network_surface(
        franke_net: am.Network, franke_scan: am.Scan) -> None:
    v = network_vertices(franke_net, 150, franke_scan, seed=0)
    assert v.shape == (150, 3)
    assert np.allclose(v[:, 2], franke_net.evaluate(v[:, :2]), atol=1e-9)
    lo, hi = franke_scan.points.min(axis=0), franke_scan.points.max(axis=0)
    assert np.all((v[:, :2] >= lo[:2] - 1e-9) & (v[:, :2] <= hi[:2] + 1e-9))
    assert len(np.unique(v, axis=0)) == 150
    assert np.array_equal(v, network_vertices(franke_net, 150, franke_scan, seed=0))


def test_network_vertices_are_evenly_spread(franke_net: am.Network,
                                            franke_scan: am.Scan) -> None:
    from scipy.spatial import cKDTree

    v = network_vertices(franke_net, 200, franke_scan)
    d, _ = cKDTree(v).query(v, k=2)
    nn = d[:, 1]
    assert nn.min() > 0.4 * np.median(nn)  # farthest-point sampling: no clumps


def test_network_vertices_leave_out_the_holes(franke_net: am.Network,
                                              franke_scan: am.Scan) -> None:
    pts = franke_scan.points
    hole = np.hypot(pts[:, 0] - 140.0, pts[:, 1] - 50.0) < 12.0  # a 24 mm hole
    keep = ~hole
    sub = pts[keep]
    holed = am.Scan(sub, faces=Delaunay(sub[:, :2]).simplices)
    tri = holed.faces
    long = np.linalg.norm(sub[tri][:, :, :2] - np.roll(sub[tri], 1, axis=1)[:, :, :2],
                          axis=2).max(axis=1) > 5.0
    holed = am.Scan(sub, faces=tri[~long])
    v = network_vertices(franke_net, 200, holed)
    r = np.hypot(v[:, 0] - 140.0, v[:, 1] - 50.0)
    assert r.min() > 10.0


def test_network_vertices_reject_bad_input(franke_net: am.Network,
                                           franke_scan: am.Scan) -> None:
    with pytest.raises(AsrbfError, match="n must be an integer >= 3"):
        network_vertices(franke_net, 2, franke_scan)
    with pytest.raises(AsrbfError, match="net must be an asrbf_mesh.Network"):
        network_vertices("net", 10, franke_scan)  # type: ignore[arg-type]
    with pytest.raises(ScanError, match="NaN or infinite"):
        network_vertices(franke_net, 10, np.full((10, 3), np.inf))


# ----------------------------------------------------------------------------- compare_som


def test_compare_som_counts(comparison: SomComparison, franke_net: am.Network) -> None:
    c = comparison
    k = franke_net.n_neurons
    assert c.n_neurons == k
    assert c.som_shape == som_grid(k) and c.som_nodes == c.som_shape[0] * c.som_shape[1]
    assert c.som_dead == c.som_map.n_dead and c.dead_nodes == "dropped"
    # equal vertex counts: ours has as many vertices as the SOM's live nodes
    assert c.som_mesh.n_vertices == c.som_nodes - c.som_dead
    assert c.asrbf_mesh.n_vertices == c.som_mesh.n_vertices
    assert c.asrbf_mesh.n_faces > 0 and c.som_mesh.n_faces > 0
    assert set(c.seconds) == {"fit", "som", "vertices", "ball_pivoting", "metro"}
    assert c.seconds["fit"] == 0.0


def test_compare_som_metrics_are_finite_and_ours_is_better(comparison: SomComparison) -> None:
    # Also true with the full default SOM schedule (500 steps per node, measured:
    # SOM 3.29 / 0.085 / 0.27 % vs ours 2.66 / 0.055 / 0.17 %, Hausdorff / mean / RMS)
    c = comparison
    for r in (c.asrbf, c.som):
        assert isinstance(r, MetroResult)
        for key in ("hausdorff", "mean", "rms", "hausdorff_pct", "mean_pct", "rms_pct"):
            assert np.isfinite(getattr(r, key)) and getattr(r, key) > 0
        assert r.mean <= r.rms <= r.hausdorff
    assert c.asrbf_wins == {"hausdorff": True, "mean": True, "rms": True}
    assert c.asrbf.rms < 0.8 * c.som.rms


def test_compare_som_to_dict(comparison: SomComparison) -> None:
    import json

    d = comparison.to_dict()
    for key in ("n_neurons", "som_nodes", "som_shape", "som_dead", "asrbf", "som", "seconds"):
        assert key in d
    for side in ("asrbf", "som"):
        for key in ("hausdorff", "mean", "rms", "hausdorff_pct", "mean_pct", "rms_pct",
                    "n_samples", "diagonal"):
            assert key in d[side]
    assert d["som_shape"] == list(comparison.som_shape)
    json.dumps(d)


def test_compare_som_keep_dead_meshes_every_node(franke_scan: am.Scan,
                                                 franke_net: am.Network) -> None:
    c = compare_som(franke_scan, franke_net, iterations=500, samples=2_000, keep_dead=True)
    assert c.dead_nodes == "kept"
    assert c.som_mesh.n_vertices == c.som_nodes == c.asrbf_mesh.n_vertices


def test_compare_som_fits_when_no_network_is_given(syn) -> None:
    pts = syn.points(syn.bump, 25)
    scan = am.Scan(pts, faces=Delaunay(pts[:, :2]).simplices)
    c = compare_som(scan, seed=1, iterations=1_000, samples=2_000, progress=False)
    assert c.seconds["fit"] > 0
    assert c.n_neurons == am.fit(scan, seed=1, progress=False).n_neurons


def test_compare_som_rejects_bad_input(franke_points: np.ndarray,
                                       franke_net: am.Network,
                                       franke_scan: am.Scan) -> None:
    with pytest.raises(ScanError, match="needs a scan with faces"):
        compare_som(am.Scan(franke_points), franke_net)
    with pytest.raises(ScanError, match="scan must be an asrbf_mesh.Scan"):
        compare_som(franke_points, franke_net)  # type: ignore[arg-type]
    with pytest.raises(AsrbfError, match="net must be an asrbf_mesh.Network"):
        compare_som(franke_scan, "net")  # type: ignore[arg-type]
    tiny = am.Network(0.0, np.array([[0.5, 0.5]]), np.array([0.3]), np.array([1.0]),
                      franke_net.frame, franke_net.config)
    with pytest.raises(AsrbfError, match="at least 4"):
        compare_som(franke_scan, tiny)


def test_a_ball_pivoting_mesh_without_faces_is_an_error() -> None:
    line = np.column_stack([np.linspace(0.0, 1.0, 20), np.zeros(20), np.zeros(20)])
    with pytest.raises(AsrbfError, match="ball pivoting made no triangle of the 20 SOM nodes"):
        _ball_pivoting(line, "SOM nodes")
