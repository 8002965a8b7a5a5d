"""The pymeshlab adapter: Metro distances with known answers, repair, holes, decimation."""

from __future__ import annotations

import numpy as np
import pytest
from _grids import height_grid, mm_grid

import asrbf_mesh as am
from asrbf_mesh.errors import AsrbfError
from asrbf_mesh.evaluate import _meshlab as ml

NX, NY = 60, 50  # samples along x (80 mm) and y (60 mm)


def grid_mesh(func, nx: int = NX, ny: int = NY) -> am.Mesh:
    """A gridded height field in mm: x in [100, 180], y in [20, 80], z = 5 + 20 func."""
    return am.Mesh(*mm_grid(func, nx, ny))


@pytest.fixture(scope="module")
def franke_mesh(syn) -> am.Mesh:
    return grid_mesh(syn.franke)


@pytest.fixture(scope="module")
def flat_mesh() -> am.Mesh:
    return grid_mesh(lambda u, v: np.zeros_like(u), 30, 20)


def boundary_vertices(faces: np.ndarray) -> np.ndarray:
    e = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    uniq, count = np.unique(e, axis=0, return_counts=True)
    return np.unique(uniq[count == 1])


# ----------------------------------------------------------------------------- hausdorff


def test_identical_meshes_are_at_distance_zero(franke_mesh: am.Mesh) -> None:
    d = ml.hausdorff(franke_mesh, franke_mesh)
    diag = d["diagonal"]
    for key in ("hausdorff", "mean", "rms"):
        assert d[key] <= 1e-9 * diag
    assert d["a_to_b"]["max"] <= 1e-9 * diag and d["b_to_a"]["max"] <= 1e-9 * diag


def test_translated_plane_is_at_the_translation_both_ways(flat_mesh: am.Mesh) -> None:
    t = 0.75
    moved = am.Mesh(flat_mesh.vertices + [0.0, 0.0, t], flat_mesh.faces)
    d = ml.hausdorff(moved, flat_mesh)
    for direction in ("a_to_b", "b_to_a"):
        for key in ("max", "min", "mean", "rms"):
            assert d[direction][key] == pytest.approx(t, rel=1e-9)
    assert d["hausdorff"] == pytest.approx(t) and d["mean"] == pytest.approx(t)
    assert d["rms"] == pytest.approx(t)
    assert d["diagonal"] == pytest.approx(100.0)  # 80 x 60 mm, flat
    assert d["hausdorff_pct"] == pytest.approx(100 * t / 100.0)
    assert d["mean_pct"] == pytest.approx(d["rms_pct"])


def test_translated_curved_surface_is_within_the_translation(franke_mesh: am.Mesh) -> None:
    t = 0.5
    moved = am.Mesh(franke_mesh.vertices + [0.0, 0.0, t], franke_mesh.faces)
    d = ml.hausdorff(moved, franke_mesh)
    for direction in ("a_to_b", "b_to_a"):
        # the closest point is t * cos(slope) away, never farther than t
        assert d[direction]["max"] <= t * (1 + 1e-9)
        assert 0.8 * t < d[direction]["mean"] <= t
    assert d["hausdorff"] == pytest.approx(t, rel=1e-6)  # flat spots exist (the peaks)


def test_sub_patch_is_near_one_way_only(franke_mesh: am.Mesh) -> None:
    v, f = franke_mesh.vertices, franke_mesh.faces
    centre = v[f].mean(axis=1)
    inner = (np.abs(centre[:, 0] - 140) < 15) & (np.abs(centre[:, 1] - 50) < 10)
    patch = am.Mesh(*ml.compact(v, f[inner]))
    d = ml.hausdorff(patch, franke_mesh)
    assert d["a_to_b"]["max"] <= 1e-9 * d["diagonal"]  # the patch lies on the scan
    assert d["b_to_a"]["max"] > 20.0  # the scan's corners are far from the patch (mm)
    assert d["b_to_a"]["mean"] > 5.0
    assert d["hausdorff"] == d["b_to_a"]["max"]
    back = ml.hausdorff(franke_mesh, patch)  # percentages follow the reference's diagonal
    assert back["hausdorff"] == pytest.approx(d["hausdorff"])
    assert back["diagonal"] < d["diagonal"]
    assert back["hausdorff_pct"] > d["hausdorff_pct"]


def test_point_set_reference_measures_points_to_surface_only(franke_mesh: am.Mesh) -> None:
    pts = franke_mesh.vertices + [0.0, 0.0, 0.0]
    d = ml.hausdorff(franke_mesh, pts)
    assert d["a_to_b"] is None
    assert d["b_to_a"]["n_samples"] == len(pts)
    assert d["hausdorff"] <= 1e-9 * d["diagonal"]
    lifted = pts + [0.0, 0.0, 2.0]
    flat = grid_mesh(lambda u, v: np.zeros_like(u), 30, 20)
    d2 = ml.hausdorff(flat, np.c_[lifted[:, :2], np.full(len(pts), 7.0)])
    assert d2["mean"] == pytest.approx(2.0) and d2["hausdorff"] == pytest.approx(2.0)


def test_sample_counts_defaults_and_determinism(franke_mesh: am.Mesh, flat_mesh: am.Mesh) -> None:
    d = ml.hausdorff(flat_mesh, franke_mesh, samples=500)
    assert d["a_to_b"]["n_vertex_samples"] == flat_mesh.n_vertices
    assert d["a_to_b"]["n_area_samples"] == 500
    assert d["b_to_a"]["n_vertex_samples"] == franke_mesh.n_vertices
    assert d["n_samples"] == flat_mesh.n_vertices + franke_mesh.n_vertices + 1000
    default = ml.hausdorff(flat_mesh, franke_mesh)
    assert default["a_to_b"]["n_area_samples"] == max(
        4 * max(flat_mesh.n_vertices, franke_mesh.n_vertices), 10_000)
    again = ml.hausdorff(flat_mesh, franke_mesh, samples=500)
    assert again == d  # seeded sampling: the same figures on every call
    other = ml.hausdorff(flat_mesh, franke_mesh, samples=500, seed=1)
    assert other["mean"] == pytest.approx(d["mean"], rel=0.05)
    assert other["mean"] == pytest.approx(default["mean"], rel=0.05)


def test_unreferenced_vertices_are_not_part_of_the_surface(flat_mesh: am.Mesh) -> None:
    stray = np.vstack([flat_mesh.vertices, [[140.0, 50.0, 500.0]]])
    d = ml.hausdorff(am.Mesh(stray, flat_mesh.faces), flat_mesh)
    assert d["hausdorff"] <= 1e-9


def test_hausdorff_rejects_bad_input(flat_mesh: am.Mesh) -> None:
    with pytest.raises(am.ScanError, match="a has no faces"):
        ml.hausdorff(am.Mesh(flat_mesh.vertices, np.empty((0, 3))), flat_mesh)
    with pytest.raises(am.ConfigError, match="samples must be an integer >= 1"):
        ml.hausdorff(flat_mesh, flat_mesh, samples=0)
    with pytest.raises(am.ConfigError, match="seed must be an integer >= 0"):
        ml.hausdorff(flat_mesh, flat_mesh, seed=-1)
    with pytest.raises(am.ScanError, match=r"b must be an \(N, 3\) array"):
        ml.hausdorff(flat_mesh, np.zeros((4, 2)))
    with pytest.raises(am.ScanError, match="b must hold at least 1 point"):
        ml.hausdorff(flat_mesh, np.zeros((0, 3)))
    with pytest.raises(am.ScanError, match="b contain NaN"):
        ml.hausdorff(flat_mesh, np.full((4, 3), np.nan))


# ----------------------------------------------------------------------------- repair, holes


def bowtie() -> tuple[np.ndarray, np.ndarray]:
    """Two triangles touching at vertex 0 only (non-manifold), plus a duplicate face."""
    v = np.array([[0.0, 0, 0], [1, 0, 0], [1, 1, 0], [-1, 0, 0], [-1, -1, 0], [5, 5, 5]])
    f = np.array([[0, 1, 2], [0, 3, 4], [0, 1, 2]])
    return v, f


def test_repair_splits_non_manifold_vertices() -> None:
    v, f = bowtie()
    before = ml.topological_measures(am.Mesh(v, f))
    assert before["non_two_manifold_vertices"] >= 1
    rv, rf = ml.repair_non_manifold(v, f)
    assert len(rf) == 2  # the duplicate is gone
    assert len(rv) == 6  # 5 referenced vertices, vertex 0 split in two; the stray one dropped
    np.testing.assert_array_equal(rv[:5], v[:5])
    after = ml.topological_measures(am.Mesh(rv, rf))
    assert after["non_two_manifold_vertices"] == 0 and after["is_mesh_two_manifold"]
    assert after["number_holes"] == 2
    kept, _ = ml.repair_non_manifold(v, f, drop_unreferenced=False)
    assert len(kept) == 7


def test_repair_rejects_bad_faces() -> None:
    with pytest.raises(AsrbfError, match="faces must be a non-empty"):
        ml.repair_non_manifold(np.zeros((3, 3)), np.array([[0, 1, 3]]))


def holed_grid(n: int = 20) -> am.Mesh:
    """A flat n x n grid without the faces of one interior 2 x 2 block (a 8-edge hole)."""
    keep = np.ones((n - 1, n - 1), bool)
    keep[8:10, 8:10] = False
    return am.Mesh(*height_grid(lambda u, v: 0.1 * u * v, n, n, keep=keep))


def test_close_holes_fills_small_holes_only() -> None:
    mesh = holed_grid()
    out = ml.close_holes(mesh, max_hole_edges=20)
    np.testing.assert_array_equal(out.vertices[: mesh.n_vertices], mesh.vertices)
    assert out.n_faces > mesh.n_faces
    new = out.faces[mesh.n_faces:]
    assert len(new) >= 6  # an 8-gon takes 6 triangles
    assert set(np.flatnonzero(out.vertex_quality)) == set(np.unique(new).tolist())
    topo = ml.topological_measures(out)
    assert topo["number_holes"] == 1  # only the outer border (76 edges) is left
    same = ml.close_holes(mesh, max_hole_edges=6)  # the 8-edge hole is too large
    assert same.n_faces == mesh.n_faces and not same.vertex_quality.any()


def test_close_holes_validates() -> None:
    with pytest.raises(AsrbfError, match="max_hole_edges must be an integer >= 3"):
        ml.close_holes(holed_grid(), max_hole_edges=2)


# ----------------------------------------------------------------------------- decimation


def test_quadric_collapse_reaches_the_target_and_keeps_the_border(franke_mesh) -> None:
    free = ml.quadric_edge_collapse(franke_mesh, target_faces=800, preserve_border=False)
    assert abs(free.n_faces - 800) <= 10
    kept = ml.quadric_edge_collapse(franke_mesh, target_faces=800, preserve_border=True)
    assert abs(kept.n_faces - 800) <= 10
    border = franke_mesh.vertices[boundary_vertices(franke_mesh.faces)]
    # every border vertex of the scan is still a vertex of the decimated mesh
    d = np.min(np.linalg.norm(border[:, None] - kept.vertices[None], axis=2), axis=1)
    assert d.max() < 1e-9
    # and the parameters of one call do not leak into the next
    again = ml.quadric_edge_collapse(franke_mesh, target_faces=800, preserve_border=False)
    assert again.n_faces == free.n_faces
    np.testing.assert_allclose(again.vertices, free.vertices)


def test_quadric_collapse_validates(franke_mesh) -> None:
    with pytest.raises(am.ConfigError, match="target_faces must be an integer >= 1"):
        ml.quadric_edge_collapse(franke_mesh, target_faces=0)


# ----------------------------------------------------------------------------- reconstruction


def test_screened_poisson_faces_the_scanner(franke_mesh: am.Mesh) -> None:
    pts = franke_mesh.vertices
    out = ml.screened_poisson(pts, depth=5)
    assert out.n_faces > 100 and out.vertex_quality is not None
    assert out.vertex_normals is not None
    # the patch of the Poisson surface nearest the data faces +z (the scanner side)
    near = np.linalg.norm(out.vertices[:, None, :] - pts[::50][None], axis=2).min(axis=1) < 2.0
    assert near.sum() > 50
    assert np.mean(out.vertex_normals[near, 2] > 0) > 0.9


def test_screened_poisson_validates() -> None:
    with pytest.raises(AsrbfError, match="more than k_normals=10 points"):
        ml.screened_poisson(np.random.default_rng(0).random((8, 3)))
    with pytest.raises(AsrbfError, match="depth must be an integer >= 1"):
        ml.screened_poisson(np.random.default_rng(0).random((80, 3)), depth=0)


def test_ball_pivoting_meshes_the_points(franke_mesh: am.Mesh) -> None:
    pts = franke_mesh.vertices
    out = ml.ball_pivoting(pts)
    assert out.n_vertices == len(pts)
    np.testing.assert_allclose(out.vertices, pts)
    assert out.n_faces > 0.8 * franke_mesh.n_faces
    explicit = ml.ball_pivoting(pts, radius_rel=0.02)
    assert explicit.n_faces > 0.8 * franke_mesh.n_faces
    with pytest.raises(AsrbfError, match="radius_rel must be a fraction"):
        ml.ball_pivoting(pts, radius_rel=2.0)


def test_pymeshlab_failures_become_asrbf_errors() -> None:
    import pymeshlab

    ms = pymeshlab.MeshSet()
    with pytest.raises(AsrbfError, match="pymeshlab get_hausdorff_distance failed"):
        ml._apply(ms, "get_hausdorff_distance", sampledmesh=0, targetmesh=1)


def test_hausdorff_takes_scans(franke_mesh: am.Mesh) -> None:
    with_faces = am.Scan(franke_mesh.vertices, franke_mesh.faces)
    d = ml.hausdorff(with_faces, with_faces, samples=200)
    assert d["hausdorff"] <= 1e-9 * d["diagonal"] and d["a_to_b"] is not None
    cloud = am.Scan(franke_mesh.vertices)
    d = ml.hausdorff(franke_mesh, cloud)
    assert d["a_to_b"] is None and d["b_to_a"]["n_samples"] == cloud.n_points


def test_area_samples_are_stratified_by_area() -> None:
    # two triangles of areas 1 and 3: a stratified draw gives each its share to within one
    # sample (a plain Monte Carlo draw of 400 misses 100 / 300 by about 9 on average)
    v = np.array([[0.0, 0, 0], [1, 0, 0], [0, 2, 0], [5, 0, 0], [8, 0, 0], [5, 2, 0]])
    f = np.array([[0, 1, 2], [3, 4, 5]])
    for seed in range(5):
        pts = ml._surface_samples(v, f, 400, np.random.default_rng(seed))
        first = int(np.count_nonzero(pts[:, 0] < 2.5))
        assert abs(first - 100) <= 1 and len(pts) == 400
