"""Metro distances with known answers, per-sample output and the `asrbf metro` command."""

from __future__ import annotations

import json

import numpy as np
import pytest
from _grids import height_grid

import asrbf_mesh as am
from asrbf_mesh.cli import main
from asrbf_mesh.errors import AsrbfError
from asrbf_mesh.evaluate import MetroResult, metro


def sheet(n: int = 30, size: float = 10.0, z=lambda x, y: 0.02 * x * y) -> am.Mesh:
    return am.Mesh(*height_grid(z, n, n, x=(0, size), y=(0, size)))


def flat(n: int = 20, size: float = 10.0) -> am.Mesh:
    return sheet(n, size, lambda x, y: np.zeros_like(x))


def test_identical_meshes_are_at_zero() -> None:
    m = sheet()
    r = metro(m, m, samples=2000)
    assert isinstance(r, MetroResult)
    assert r.hausdorff < 1e-5 and r.mean < 1e-6 and r.rms < 1e-6
    assert r.a_to_b is not None and r.a_to_b.n_area_samples == 2000
    assert r.n_samples == r.a_to_b.n_samples + r.b_to_a.n_samples


def test_translation_along_the_normal_is_its_length_both_ways() -> None:
    m = flat()
    t = 0.37
    moved = am.Mesh(m.vertices + [0.0, 0.0, t], m.faces)
    r = metro(moved, m, samples=3000)
    for d in (r.a_to_b, r.b_to_a):
        assert d.max == pytest.approx(t, rel=1e-5)
        assert d.min == pytest.approx(t, rel=1e-5)
        assert d.mean == pytest.approx(t, rel=1e-5)
    assert r.hausdorff == pytest.approx(t, rel=1e-5)
    diag = np.linalg.norm(m.vertices.max(0) - m.vertices.min(0))
    assert r.hausdorff_pct == pytest.approx(100 * t / diag, rel=1e-5)


def test_oblique_translation_of_a_closed_surface() -> None:
    # a closed box moved by t: the Hausdorff distance is |t| (a corner moves by t)
    v = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float) * 4
    f = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                  [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
    t = np.array([0.1, -0.2, 0.15])
    r = metro(am.Mesh(v + t, f), am.Mesh(v, f), samples=5000)
    # vertex samples are exactly |t| away from the moved corners... at most |t| anywhere
    assert r.hausdorff <= np.linalg.norm(t) + 1e-6
    assert r.hausdorff >= 0.2 - 1e-6  # the largest component is reached on the faces


def test_sub_patch_is_zero_one_way_and_positive_the_other() -> None:
    m = sheet(n=30)
    keep = (m.vertices[m.faces][:, :, 0] < 5.0).all(axis=1)
    part = am.Mesh(m.vertices, m.faces[keep])
    r = metro(part, m, samples=3000)
    assert r.a_to_b.max < 1e-5
    assert r.b_to_a.max > 4.0  # the far corner of the sheet is ~5 away from the half
    assert r.hausdorff == pytest.approx(r.b_to_a.max)


def test_same_seed_same_figures_and_seed_matters() -> None:
    a, b = sheet(), sheet(z=lambda x, y: 0.02 * x * y + 0.05 * np.sin(x))
    r1, r2 = metro(a, b, seed=3), metro(a, b, seed=3)
    assert r1.to_dict() == r2.to_dict()
    assert metro(a, b, seed=4).mean != r1.mean


def test_per_sample_arrays_and_vertex_error() -> None:
    a = sheet()
    b = flat(n=40)
    r = metro(a, b, samples=500, per_sample=True)
    pts, d = r.a_to_b.points, r.a_to_b.distances
    assert pts.shape == (a.n_vertices + 500, 3) and d.shape == (a.n_vertices + 500,)
    # against the plane z = 0 every distance is the height
    np.testing.assert_allclose(d, np.abs(pts[:, 2]), atol=1e-5)
    np.testing.assert_allclose(r.vertex_error, np.abs(a.vertices[:, 2]), atol=1e-5)
    em = r.error_mesh()
    np.testing.assert_array_equal(em.vertex_quality, r.vertex_error)
    with pytest.raises(AsrbfError, match="per_sample"):
        _ = metro(a, b, samples=100).vertex_error


def test_point_set_reference_is_one_way() -> None:
    m = flat()
    pts = m.vertices + [0.0, 0.0, 0.2]
    r = metro(m, pts)
    assert r.a_to_b is None
    assert r.b_to_a.mean == pytest.approx(0.2, rel=1e-5)
    assert r.to_dict()["a_to_b"] is None


def test_bad_inputs() -> None:
    m = flat()
    with pytest.raises(AsrbfError, match="must be a Mesh"):
        metro(m.vertices, m)
    with pytest.raises(AsrbfError, match="samples"):
        metro(m, m, samples=0)


def test_cli_metro_json_and_outputs(tmp_path, capsys) -> None:
    a, b = tmp_path / "a.ply", tmp_path / "b.ply"
    am.save_mesh(sheet(), a)
    am.save_mesh(flat(n=40), b)
    err, npz = tmp_path / "err.ply", tmp_path / "samples.npz"
    code = main(["metro", str(a), str(b), "--samples", "800", "--json", "--error-mesh", str(err),
                 "--samples-out", str(npz)])
    assert code == 0
    out = json.loads(capsys.readouterr().out)
    for key in ("hausdorff", "mean", "rms", "hausdorff_pct", "mean_pct", "rms_pct",
                "n_samples"):
        assert np.isfinite(out[key])
    assert out["hausdorff"] == pytest.approx(2.0, rel=1e-4)  # 0.02 * 10 * 10
    back = am.load_scan(err)
    assert back.n_points == 900
    with np.load(npz) as z:
        assert z["a_to_b_distances"].shape == (900 + 800,)
    # text output, and a clear error for a faceless mesh
    assert main(["metro", str(a), str(b), "--samples", "100"]) == 0
    assert "symmetric" in capsys.readouterr().out
    cloud = tmp_path / "cloud.xyz"
    np.savetxt(cloud, sheet().vertices)
    assert main(["metro", str(cloud), str(b)]) == 2
    assert "point set without faces" in capsys.readouterr().err


def _cube() -> am.Mesh:
    v = np.array([[x, y, z] for x in (0.0, 1.0) for y in (0.0, 1.0) for z in (0.0, 1.0)])
    f = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                  [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
    return am.Mesh(v, f)


def test_metro_measures_small_meshes(tmp_path) -> None:
    """A cube (8 points) and a single triangle are meshes: metro fits nothing, so any mesh
    with a face (and any point reference with a point) is measured."""
    cube = _cube()
    am.save_mesh(am.Mesh(cube.vertices * 1.1, cube.faces), tmp_path / "big.ply")
    big = am.load_scan(tmp_path / "big.ply", min_points=1, height_field=False)
    r = metro(big, cube, samples=500)
    assert r.hausdorff == pytest.approx(np.sqrt(3) * 0.1, rel=1e-5)
    tri = am.Mesh(np.eye(3), np.array([[0, 1, 2]]))
    assert metro(tri, tri).hausdorff == pytest.approx(0.0, abs=1e-6)
    r = metro(tri, np.array([[0.0, 0.0, 1.0]]))
    assert r.a_to_b is None and r.b_to_a.n_samples == 1


def test_metro_command_measures_small_meshes(tmp_path, capsys) -> None:
    cube = _cube()
    am.save_mesh(cube, tmp_path / "cube.ply")
    am.save_mesh(am.Mesh(cube.vertices * 1.1, cube.faces), tmp_path / "big.ply")
    assert main(["metro", str(tmp_path / "big.ply"), str(tmp_path / "cube.ply"),
                 "--samples", "500"]) == 0


def test_metro_command_takes_a_one_point_reference(tmp_path, capsys) -> None:
    """A one-point reference has no diagonal: the percentages are n/a, never a crash."""
    cube = _cube()
    am.save_mesh(cube, tmp_path / "cube.ply")
    (tmp_path / "one.xyz").write_text("0 0 1\n")
    assert main(["metro", str(tmp_path / "cube.ply"), str(tmp_path / "one.xyz")]) == 0
    out = capsys.readouterr().out
    assert "n/a" in out and "nan" not in out.lower().replace("n/a", "")
