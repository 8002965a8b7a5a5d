"""Isolated points: found, reported, kept out of the frame and the surface (issue 14, outliers)."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pytest

import asrbf_mesh as am
from asrbf_mesh._outliers import DISTANCE_REL, isolated_points
from asrbf_mesh.cli import main

DATA = Path(__file__).parent / "data"


def surface(n: int = 60) -> np.ndarray:
    """A smooth 60 x 60 height field of amplitude +-1 on a unit grid (the issue's example)."""
    x, y = np.meshgrid(np.arange(float(n)), np.arange(float(n)))
    return np.c_[x.ravel(), y.ravel(), (np.sin(x / 9) * np.cos(y / 7)).ravel()]


def rms(net: am.Network, pts: np.ndarray) -> float:
    return float(np.sqrt(np.mean((net.evaluate(pts[:, :2]) - pts[:, 2]) ** 2)))


@pytest.mark.parametrize(("axis", "value"), [(2, 1e6), (0, 1e6), (1, -1e6), (2, 300.0)])
def test_a_stray_point_is_found(axis: int, value: float) -> None:
    pts = surface()
    pts[777, axis] = value
    assert np.flatnonzero(isolated_points(pts)).tolist() == [777]


def test_a_pair_and_a_triple_of_strays_are_found() -> None:
    pts = surface()
    pts[[5, 6, 7], 2] = [5e3, 5e3 + 1, 5e3 + 2]  # three strays close to one another
    assert np.flatnonzero(isolated_points(pts)).tolist() == [5, 6, 7]


def test_real_scans_have_no_isolated_point() -> None:
    """The threshold holds with margin on real data: the bunny crop and the face map."""
    for scan in (am.load_scan(DATA / "bun000_crop.ply"), am.load_scan(am.face_map_path())):
        assert not isolated_points(scan.points).any()
        # the largest distance of a real point's 3rd neighbour is far below the threshold
        from scipy.spatial import cKDTree

        from asrbf_mesh._outliers import robust_box

        lo, ext = robust_box(scan.points)
        u = (scan.points - lo) / ext
        d, _ = cKDTree(u).query(u, k=4)
        assert d[:, -1].max() < 0.5 * DISTANCE_REL * np.sqrt(3)


def test_small_and_flat_inputs_have_no_isolated_point() -> None:
    assert not isolated_points(np.zeros((4, 3))).any()
    assert not isolated_points(np.zeros((40, 3))).any()  # zero diagonal


@pytest.mark.parametrize(("axis", "value"), [(2, 1e6), (0, 1e6)])
def test_a_fit_leaves_the_stray_out_and_equals_the_clean_fit(axis: int, value: float) -> None:
    """One point at z = 1e6 gave RMS in the thousands on the others; at x = 1e6, 0.47."""
    clean = surface()
    pts = clean.copy()
    pts[1234, axis] = value
    with pytest.warns(am.OutlierWarning, match=r"^1 isolated point \(0\.0278 % .*left out"):
        net = am.fit(pts, seed=0, progress=False)
    others = np.delete(clean, 1234, axis=0)
    reference = am.fit(others, seed=0, progress=False)
    assert np.array_equal(net.weights, reference.weights)  # the clean scan's fit, bit for bit
    assert np.array_equal(net.centers, reference.centers)
    assert rms(net, others) < 0.02
    assert net.info["outliers"] == 1 and net.info["n_points"] == len(others)
    assert net.fit_info.outliers == 1


def test_a_clean_fit_has_no_outlier_record() -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error", am.OutlierWarning)
        net = am.fit(surface(), seed=0, progress=False)
    assert "outliers" not in net.info and net.fit_info.outliers is None


def test_cli_reports_the_stray_and_every_command_works(tmp_path: Path, capsys) -> None:
    pts = surface()
    pts[100, 0] = 1e6  # far away in x: the footprint must not span it either
    scan = tmp_path / "stray.xyz"
    np.savetxt(scan, pts)
    net = tmp_path / "n.asrbf"
    assert main(["fit", str(scan), "-o", str(net), "--json"]) == 0
    out, err = capsys.readouterr()
    assert json.loads(out)["n_points"] == len(pts) - 1
    assert err.count("\n") == 1 and "1 isolated point" in err and "(1e+06, 1, " in err
    assert main(["reconstruct", str(net), "-o", str(tmp_path / "r.ply"), "--footprint",
                 str(scan)]) == 0
    mesh = am.load_scan(tmp_path / "r.ply", height_field=False)
    assert np.ptp(mesh.points[:, 0]) < 100  # on the surface's footprint, not out to 1e6
    assert main(["fill-holes", str(scan), "-o", str(tmp_path / "f.ply")]) == 0
    assert main(["lod", str(scan), "-o", str(tmp_path / "lod"), "--levels", "2",
                 "--no-metro"]) == 0


def test_a_sparse_scan_keeps_its_points() -> None:
    """A hundred random points: the corners are far from their neighbours, not strays."""
    for seed in range(20):
        pts = np.random.default_rng(seed).random((100, 3))
        assert not isolated_points(pts).any(), seed


def test_a_streamed_fit_warns_about_far_points(tmp_path: Path) -> None:
    """--stream cannot leave strays out in O(K + block) memory: it says so instead."""
    pts = surface()
    np.save(tmp_path / "clean.npy", pts)
    with warnings.catch_warnings():
        warnings.simplefilter("error", am.OutlierWarning)
        am.fit_stream(tmp_path / "clean.npy", seed=0, chunk=8192, progress=False)
    pts[1234, 0] = 1e6
    np.save(tmp_path / "stray.npy", pts)
    with pytest.warns(am.OutlierWarning, match=r"a few points lie far from the rest.*x axis"):
        am.fit_stream(tmp_path / "stray.npy", seed=0, chunk=8192, progress=False)


def _isolated_by_the_rule(points: np.ndarray, k: int = 3) -> np.ndarray:
    """The rule itself, every point's k-th neighbour from a k-d tree (the reference)."""
    from scipy.spatial import cKDTree

    from asrbf_mesh._outliers import DENSITY_FACTOR, robust_box

    lo, ext = robust_box(points)
    u = (points - lo) / ext
    dk = cKDTree(u).query(u, k=k + 1)[0][:, -1]
    return dk > max(DISTANCE_REL * np.sqrt(points.shape[1]), DENSITY_FACTOR * np.median(dk))


def _point_sets() -> list[np.ndarray]:
    rng = np.random.default_rng(7)
    sets = [surface(), am.load_scan(DATA / "bun000_crop.ply").points]
    for seed in range(12):
        r = np.random.default_rng(seed)
        n = int(r.integers(5, 4000))
        pts = r.random((n, 3)) * r.uniform(0.01, 100.0, 3)
        kind = seed % 4
        if kind == 1:  # strays, some in groups, some astronomically far
            far = r.choice(n, size=min(n, 7), replace=False)
            pts[far] += r.normal(0, 1, (len(far), 3)) * 10.0 ** r.integers(1, 12, (len(far), 1))
        elif kind == 2:  # clusters and duplicates
            pts[: n // 2] = pts[r.integers(0, 5, n // 2)]
        elif kind == 3:  # a sparse cloud: the median rule decides
            pts = r.random((int(r.integers(5, 60)), 3))
        sets.append(pts)
    sets.append(rng.random((500, 2)))  # the footprint's 2D points
    xy = rng.random((3000, 2))
    xy[:4] = [5.0, 5.0]  # four copies of one stray: neighbours of one another
    sets.append(xy)
    grid = surface(30)
    grid[100] = [1e300, 0.0, 0.0]  # beyond any grid cell
    sets.append(grid)
    return sets


def test_the_grid_shortcut_gives_the_rules_answer_on_every_set() -> None:
    for pts in _point_sets():
        assert np.array_equal(isolated_points(pts), _isolated_by_the_rule(pts))
