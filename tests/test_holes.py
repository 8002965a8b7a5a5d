"""Hole filling on analytic height fields with holes at known places."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest
from _grids import height_grid

import asrbf_mesh as am
from asrbf_mesh._holes import fill_holes
from asrbf_mesh._igl import boundary_loops, point_mesh_distance
from asrbf_mesh._surface import grid_faces
from asrbf_mesh.cli import main
from asrbf_mesh.errors import ConfigError, ScanError
from asrbf_mesh.evaluate import punch_holes


def grid_scan(fn, nx=70, ny=50, size=(70.0, 50.0), seed=0) -> am.Scan:
    """A range-grid-like scan in mm: vertices on a lightly jittered grid, two triangles a cell."""
    return am.Scan(*height_grid(fn, nx, ny, x=(0, size[0]), y=(0, size[1]), jitter=0.1,
                                seed=seed))


def plane(x, y):
    return 0.2 * x - 0.1 * y + 5.0


def paraboloid(x, y):
    return 20.0 - 0.01 * ((x - 35.0) ** 2 + (y - 25.0) ** 2)


def franke(x, y):
    u, v = x / 70.0, y / 50.0
    return 10.0 * (0.75 * np.exp(-((9 * u - 2) ** 2 + (9 * v - 2) ** 2) / 4)
                   + 0.75 * np.exp(-((9 * u + 1) ** 2) / 49 - (9 * v + 1) / 10)
                   + 0.5 * np.exp(-((9 * u - 7) ** 2 + (9 * v - 3) ** 2) / 4)
                   - 0.2 * np.exp(-((9 * u - 4) ** 2) - (9 * v - 7) ** 2))


def edges_count(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    e = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    return np.unique(e, axis=0, return_counts=True)


def signed_areas(mesh: am.Mesh) -> np.ndarray:
    v = mesh.vertices[mesh.faces]
    e1, e2 = v[:, 1, :2] - v[:, 0, :2], v[:, 2, :2] - v[:, 0, :2]
    return 0.5 * (e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])


@pytest.fixture(scope="module", params=[plane, paraboloid, franke], ids=lambda f: f.__name__)
def punched(request):
    scan = grid_scan(request.param)
    p = punch_holes(scan, count=3, radius_rel=(0.05, 0.08), seed=1)
    return request.param, scan, p, fill_holes(p.scan, seed=0, progress=False)


def test_every_punched_hole_is_closed_near_the_truth(punched) -> None:
    fn, scan, p, res = punched
    assert res.holes_found == 3 and res.holes_filled == 3 and not res.holes_skipped
    d = point_mesh_distance(p.truth, res.mesh)
    # measured: plane 0.0055 / paraboloid 0.0060 / Franke 0.019 mm mean (depth ranges 3-19 mm;
    # the full network with the harmonic rim blend gave 0.061 on the plane)
    tol = {"plane": 0.02, "paraboloid": 0.02, "franke": 0.06}[fn.__name__]
    assert d.mean() < tol
    # filled vertices lie on the true surface too
    new = res.mesh.vertices[res.mesh.vertex_quality > 0]
    assert len(new) == res.vertices_added > 0
    assert np.abs(new[:, 2] - fn(new[:, 0], new[:, 1])).mean() < tol


def test_scan_is_untouched_and_fill_is_manifold(punched) -> None:
    _, _, p, res = punched
    m = res.mesh
    n, f = p.scan.n_points, len(p.scan.faces)
    np.testing.assert_array_equal(m.vertices[:n], p.scan.points)
    np.testing.assert_array_equal(m.faces[:f], p.scan.faces)
    added = np.ones(len(m.vertices) - n)
    np.testing.assert_array_equal(m.vertex_quality, np.r_[np.zeros(n), added])
    _, counts = edges_count(m.faces)
    assert counts.max() == 2  # manifold: no edge with three faces
    assert np.all(signed_areas(m) > 0)  # no flipped triangle
    # watertight inside the footprint: the only boundary left is the outer border
    loops = boundary_loops(m.faces)
    assert len(loops) == 1
    assert len(np.unique(m.vertices.round(9), axis=0)) == len(m.vertices)  # no duplicates
    assert len(np.unique(m.faces)) == len(m.vertices)  # every added vertex used


def test_outer_border_is_never_filled() -> None:
    scan = grid_scan(franke)
    # a notch cut into the border is not a hole
    xy = scan.points[:, :2]
    keep = np.linalg.norm(xy - [35.0, 0.0], axis=1) > 6.0
    remap = np.full(len(xy), -1)
    remap[keep] = np.arange(keep.sum())
    f = remap[scan.faces]
    notched = am.Scan(scan.points[keep], f[(f >= 0).all(1)])
    res = fill_holes(notched, seed=0, progress=False)
    assert res.holes_found == 0 and res.faces_added == 0
    _, counts = edges_count(notched.faces)
    assert res.border_edges == int((counts == 1).sum())
    border = max(boundary_loops(notched.faces), key=len)
    after = boundary_loops(res.mesh.faces)
    assert any(set(lp.tolist()) == set(border.tolist()) for lp in after)


def test_faces_repeating_a_vertex_are_left_out_and_the_holes_beside_them_filled() -> None:
    scan = grid_scan(paraboloid)
    spoiled = np.array(scan.faces)
    # an interior triangle in every tenth cell loses its third corner: [a, b, a] covers
    # nothing, and its edges a-b and b-a hid the missing triangle's edge a-b
    centres = scan.points[spoiled].mean(axis=1)[:, :2]
    inside = np.flatnonzero(np.all((centres > 5.0) & (centres < [65.0, 45.0]), axis=1))
    pick: list[int] = []
    for f in inside[::7]:  # no two within 4 mm: each its own hole
        if all(np.linalg.norm(centres[f] - centres[g]) > 4.0 for g in pick):
            pick.append(int(f))
    spoiled[pick, 2] = spoiled[pick, 0]
    with pytest.warns(UserWarning, match=f"{len(pick)} faces with a repeated vertex left out$"):
        res = fill_holes(am.Scan(scan.points, spoiled), seed=0, progress=False)
    assert res.holes_found == len(pick) and res.holes_filled == len(pick)
    assert not np.any(res.mesh.faces[:, 0] == res.mesh.faces[:, 2])  # the spoiled ones
    _, counts = edges_count(res.mesh.faces)
    assert counts.max() == 2  # manifold
    border = max(boundary_loops(res.mesh.faces), key=len)
    assert int((counts == 1).sum()) == len(border)  # only the outer border open


def test_copied_and_turned_faces_are_mended_and_every_hole_filled() -> None:
    scan = grid_scan(franke)
    p = punch_holes(scan, count=3, radius_rel=(0.05, 0.08), seed=1)
    rng = np.random.default_rng(0)
    faces = np.array(p.scan.faces)
    turn = rng.random(len(faces)) < 0.05
    faces[turn] = faces[turn][:, [0, 2, 1]]  # against their neighbours
    copies = rng.choice(len(faces), 40, replace=False)
    spoiled = np.vstack([faces, faces[copies][:, [1, 2, 0]]])  # the same faces again
    with pytest.warns(UserWarning, match=f"40 copies of faces left out, {turn.sum()} faces "
                                         "turned to agree with their neighbours"):
        res = fill_holes(am.Scan(p.scan.points, spoiled), seed=0, progress=False)
    assert res.holes_found == 3 and res.holes_filled == 3
    m = res.mesh
    np.testing.assert_array_equal(m.faces[:len(faces)], p.scan.faces)  # mended
    _, counts = edges_count(m.faces)
    assert counts.max() == 2 and np.all(signed_areas(m) > 0)
    assert len(boundary_loops(m.faces)) == 1  # only the outer border open


def test_fins_go_while_their_edge_has_more_than_two_faces() -> None:
    from asrbf_mesh._hole_find import usable_faces

    # two triangles on edge 0-1, two fins on it (4 faces), and one fin on a border edge
    faces = np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4], [1, 0, 5], [2, 1, 6]])
    kept, fixes = usable_faces(faces)
    np.testing.assert_array_equal(kept, faces[[0, 1, 4]])  # the edge keeps two faces
    assert fixes["fins"] == 2
    # an edge of three faces none of which is a fin keeps all three
    fan = np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4], [2, 1, 5], [3, 0, 6], [4, 1, 7],
                    [2, 5, 8], [3, 6, 9], [4, 7, 10]])
    fan = np.vstack([fan, [[5, 1, 11], [6, 0, 12], [7, 1, 13]]])
    assert usable_faces(fan)[1]["fins"] == 0


def test_max_hole_size_skips_with_a_reason() -> None:
    scan = grid_scan(paraboloid)
    p = punch_holes(scan, count=2, radius_rel=(0.04, 0.09), seed=3)
    every = fill_holes(p.scan, seed=0, progress=False)
    sizes = sorted(h.size_abs for h in every.holes)
    assert len(sizes) == 2 and sizes[0] < sizes[1]
    limit = 0.5 * (sizes[0] + sizes[1])
    res = fill_holes(p.scan, every.network, max_hole_size=limit, progress=False)
    assert res.holes_found == 2 and res.holes_filled == 1
    (skip,) = res.holes_skipped
    assert "larger than max_hole_size" in skip["reason"] and skip["size_abs"] == sizes[1]
    pct = fill_holes(p.scan, every.network, max_hole_size="0.1%", progress=False)
    assert pct.holes_filled == 0 and len(pct.holes_skipped) == 2


def test_point_cloud_input_builds_its_own_footprint() -> None:
    scan = grid_scan(paraboloid)
    p = punch_holes(scan, count=2, radius_rel=(0.05, 0.07), seed=5)
    cloud = am.Scan(p.scan.points)
    res = fill_holes(cloud, seed=0, progress=False)
    assert res.holes_found == 2 and res.holes_filled == 2
    assert point_mesh_distance(p.truth, res.mesh).mean() < 0.1


def test_harmonic_blend_of_the_full_network_stays_available(punched) -> None:
    fn, _, p, res = punched
    lit = fill_holes(p.scan, res.network, blend="harmonic", lowpass_rel=None, progress=False)
    assert lit.holes_filled == 3
    assert point_mesh_distance(p.truth, lit.mesh).mean() < 1.0
    with pytest.raises(ConfigError, match="^blend must be one of"):
        fill_holes(p.scan, res.network, blend="cubic")


@pytest.mark.parametrize(("kwargs", "match"), [
    # "inf" used to say "must be positive": it is positive, but no length
    ({"max_hole_size": "inf"}, r"^max_hole_size must be a finite length > 0 or a percentage "
                               r"like '5%' \(omit it for no limit\), got 'inf'$"),
    ({"max_hole_size": float("inf")}, "^max_hole_size must be a finite length"),
    ({"max_hole_size": "big"}, "^max_hole_size must be a finite length"),
    ({"max_hole_size": "-3"}, "^max_hole_size must be a finite length"),
    ({"max_hole_size": "150%"}, r"^max_hole_size must be a percentage in \(0, 100\]"),
    ({"blend": None}, "^blend must be one of"),
    ({"lowpass_rel": 0.0}, "^lowpass_rel must be a finite number > 0.0, got 0.0$"),
    ({"lowpass_rel": float("nan")}, "^lowpass_rel must be a finite number"),
    ({"seed": -1}, "^seed must be an integer >= 0, got -1$"),
    ({"net": "net.asrbf"}, "^net must be a Network"),
])
def test_bad_parameters_raise_config_errors_naming_them(kwargs, match) -> None:
    scan = grid_scan(plane, nx=12, ny=10)
    kwargs = {"net": None} | kwargs
    with pytest.raises(ConfigError, match=match) as info:  # before any fit: no network needed
        fill_holes(scan, kwargs.pop("net"), progress=False, **kwargs)
    assert "\n" not in str(info.value)


def test_max_hole_size_takes_lengths_and_percentages(punched) -> None:
    _, _, p, res = punched
    diag = p.scan.bbox_diagonal
    for value in ("5%", 0.05 * diag, str(0.05 * diag), None):
        again = fill_holes(p.scan, res.network, max_hole_size=value, progress=False)
        assert [h.filled for h in again.holes] == [h.size_abs <= 0.05 * diag or value is None
                                                   for h in again.holes]


def test_an_array_of_points_is_filled_as_a_point_cloud() -> None:
    # am.fill_holes(array, net) used to raise AttributeError ('numpy.ndarray' has no 'points')
    scan = grid_scan(paraboloid)
    p = punch_holes(scan, count=2, radius_rel=(0.05, 0.07), seed=5)
    cloud = fill_holes(am.Scan(p.scan.points), seed=0, progress=False)
    res = am.fill_holes(np.array(p.scan.points), cloud.network)
    np.testing.assert_array_equal(res.mesh.vertices, cloud.mesh.vertices)
    np.testing.assert_array_equal(res.mesh.faces, cloud.mesh.faces)
    as_list = am.fill_holes(p.scan.points.tolist(), cloud.network)
    np.testing.assert_array_equal(as_list.mesh.faces, cloud.mesh.faces)
    mesh = am.fill_holes(am.Mesh(p.scan.points, p.scan.faces), cloud.network)
    assert mesh.holes_filled == 2 and mesh.mesh.n_faces > p.scan.n_faces


@pytest.mark.parametrize(("scan", "match"), [
    (np.zeros((10, 2)), r"^scan must be an \(N, 3\) array, got shape \(10, 2\)$"),
    ("scan.ply", "^scan must be a Scan, a Mesh or an .* got the path 'scan.ply': load it"),
    (object(), r"^scan must be an \(N, 3\) array of numbers, got object$"),
    (np.array([[0.0, 0, np.nan]] * 5), "^scan contain NaN or infinite"),
])
def test_bad_scans_raise_one_line_scan_errors_naming_scan(franke_net, scan, match) -> None:
    with pytest.raises(ScanError, match=match) as info:
        am.fill_holes(scan, franke_net)
    assert "\n" not in str(info.value)


def test_cli_fill_holes_json(tmp_path, capsys) -> None:
    scan = grid_scan(franke)
    p = punch_holes(scan, count=2, radius_rel=(0.05, 0.07), seed=2)
    src = am.save_mesh(am.Mesh(p.scan.points, p.scan.faces), tmp_path / "holed.ply")
    out = tmp_path / "filled.ply"
    assert main(["fill-holes", str(src), "-o", str(out), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    for key in ("holes_found", "holes_filled", "holes_skipped", "vertices_added", "faces_added",
                "seconds"):
        assert key in data
    assert data["holes_found"] == 2 and data["holes_filled"] == 2
    back = am.load_scan(out)
    assert back.n_points == p.scan.n_points + data["vertices_added"]
    assert len(back.faces) == len(p.scan.faces) + data["faces_added"]
    assert main(["fill-holes", str(src), "-o", str(src)]) == 2  # never overwrite the input
    assert "input" in capsys.readouterr().err


def test_cli_max_hole_size_inf_says_what_a_length_is(tmp_path, capsys) -> None:
    # used to say "max hole size must be positive, got 'inf'"
    scan = grid_scan(plane, nx=12, ny=10)
    src = am.save_mesh(am.Mesh(scan.points, scan.faces), tmp_path / "s.ply")
    out = tmp_path / "out.ply"
    assert main(["fill-holes", str(src), "-o", str(out), "--max-hole-size", "inf"]) == 2
    assert capsys.readouterr().err == (
        "asrbf: error: --max-hole-size must be a finite length > 0 or a percentage like '5%' "
        "(omit it for no limit), got 'inf'\n")
    assert not out.exists()


@pytest.mark.slow
def test_face_map_natural_holes_filled_border_kept() -> None:
    scan = am.load_scan(am.face_map_path())
    res = fill_holes(scan, seed=0, progress=False)
    # every hole is filled, the 4-vertex one whose diagonal is already a mesh edge too
    # (it takes the other diagonal: no edge gets a third face)
    refused = [h for h in res.holes if not h.filled]
    assert res.holes_found >= 15 and refused == []
    border = max(boundary_loops(scan.faces), key=len)  # the scan's outer border
    after = boundary_loops(res.mesh.faces)
    assert any(set(lp.tolist()) == set(border.tolist()) for lp in after)
    _, counts = edges_count(res.mesh.faces)
    open_edges = sum(h.rim_vertices for h in refused)
    assert counts.max() == 2
    assert int((counts == 1).sum()) == res.border_edges + open_edges


def folded_scan() -> tuple[am.Scan, np.ndarray]:
    """Two layers seen one over the other: a front sheet z = 30 + 0.1 x over x <= 42 and a
    back sheet z = 0.05 y over x >= 28 (half a cell apart in xy), joined by a vertical wall
    at x = 42 (triangles seen edge-on): the surface folds under itself for 28 <= x <= 42.
    Returns the scan and the truth of a disk of radius 5 at (35, 25) on both layers."""
    def sheet(x0, x1, off, z):
        xs, ys = np.arange(x0, x1 + 1e-9, 1.0) + off, np.arange(0.0, 50.0 + 1e-9, 1.0) + off
        x, y = np.meshgrid(xs, ys)
        return np.column_stack([x.ravel(), y.ravel(), z(x.ravel(), y.ravel())]), len(xs), len(ys)

    front, fx, fy = sheet(0.0, 42.0, 0.0, lambda x, y: 30.0 + 0.1 * x)
    back, bx, by = sheet(28.0, 70.0, 0.5, lambda x, y: 0.05 * y)
    faces = [grid_faces(fx, fy), grid_faces(bx, by) + len(front)]
    # the wall: front's last column (x = 42) down to back's column at x = 42.5
    top = np.arange(fy) * fx + (fx - 1)
    bottom = len(front) + np.arange(by) * bx + 14
    wall = [[top[j], bottom[j], top[j + 1]] for j in range(min(fy, by) - 1)]
    wall += [[top[j + 1], bottom[j], bottom[j + 1]] for j in range(min(fy, by) - 1)]
    pts = np.vstack([front, back])
    scan = am.Scan(pts, np.vstack([*faces, np.array(wall)]))
    inside = np.linalg.norm(pts[:, :2] - [35.0, 25.0], axis=1) <= 5.0
    keep = np.flatnonzero(~inside)
    remap = np.full(len(pts), -1)
    remap[keep] = np.arange(len(keep))
    f = remap[scan.faces]
    return am.Scan(pts[keep], f[(f >= 0).all(axis=1)]), pts[inside]


def test_hole_at_a_fold_is_filled_on_each_layer() -> None:
    holed, truth = folded_scan()
    with np.errstate(all="ignore"), pytest.warns(am.HeightFieldWarning):
        net = am.fit(holed, seed=0, progress=False)
    res = fill_holes(holed, net)
    (hole,) = [h for h in res.holes if np.linalg.norm(np.array(h.centre[:2]) - [35, 25]) < 5]
    assert hole.filled and hole.layers == 2, hole
    new = res.mesh.vertices[res.mesh.vertex_quality > 0]
    # every new vertex lies on one of the two sheets, none in between: each layer is filled
    # from its own surroundings by a thin plate, which reproduces a plane
    on_front = np.abs(new[:, 2] - (30.0 + 0.1 * new[:, 0])) < 1e-6
    on_back = np.abs(new[:, 2] - 0.05 * new[:, 1]) < 1e-6
    assert (on_front | on_back).all() and on_front.sum() > 20 and on_back.sum() > 20
    assert point_mesh_distance(truth, res.mesh).max() < 1e-6


def test_hole_across_a_cliff_is_filled_on_each_side() -> None:
    """A disk punched across a cliff (a step of 20 spacings from z = 0 to z = 20 at x = 24.5,
    bridged by triangles seen edge-on, as a range grid joins the two sides of an occlusion)
    lies on two layers although its rim is a simple polygon in the view plane: one surface
    across it ramped from one level to the other (its truth up to 10 units off); each side
    is filled from its own surroundings up to the wall (bun090's punched seed 13: a disk
    through the ear and the head behind it, 0.719 -> 0.249 % RMS)."""
    n = 50
    x, y = np.meshgrid(np.arange(n, dtype=float), np.arange(n, dtype=float))
    pts = np.column_stack([x.ravel(), y.ravel(), np.where(x.ravel() > 24.5, 20.0, 0.0)])
    inside = np.linalg.norm(pts[:, :2] - [24.5, 25.0], axis=1) <= 6.0
    keep = np.flatnonzero(~inside)
    remap = np.full(len(pts), -1)
    remap[keep] = np.arange(len(keep))
    f = remap[grid_faces(n, n)]
    holed = am.Scan(pts[keep], f[(f >= 0).all(axis=1)])
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = fill_holes(holed, seed=0, progress=False)
    (hole,) = [h for h in res.holes if np.linalg.norm(np.array(h.centre[:2]) - [24.5, 25]) < 6]
    assert hole.filled and hole.layers == 2, hole
    # each level is a plane: its thin plate reproduces it
    assert point_mesh_distance(pts[inside], res.mesh).max() < 1e-6
    _, counts = np.unique(np.sort(np.concatenate([res.mesh.faces[:, [0, 1]],
        res.mesh.faces[:, [1, 2]], res.mesh.faces[:, [2, 0]]]), axis=1), axis=0,
        return_counts=True)
    # the wall between the two fills is closed as well: only the outer border is open
    assert counts.max() == 2 and int((counts == 1).sum()) == res.border_edges


@pytest.mark.parametrize("seed", [1, 21, 40])
def test_hole_through_a_fold_and_its_wall_is_filled_on_each_layer_and_the_wall(
        seed: int, monkeypatch: pytest.MonkeyPatch) -> None:
    """A disk through both layers of a fold and the wall between them (the synthetic folds
    of the crash campaign): the back layer covers the hole in the view plane, so only its
    boundary loop finds it, and the loop's fill in its own plane stood across the fold
    (1.8, 3.3 and 3.5 units RMS off the truth on these seeds; 8 of the 50 folds were left
    open for crossing the scan). Each layer is filled up to the wall, the wall closed by
    chords between them: both sheets are planes, reproduced exactly."""
    from asrbf_mesh._hole_cross import crossing_faces
    from asrbf_mesh.evaluate import _synthetic_holes as sh

    cut, truth = sh._cut, []
    monkeypatch.setattr(sh, "_cut", lambda pts, faces, drop: (
        truth.append(pts[drop]), cut(pts, faces, drop))[1])
    holed = sh.synthetic_holes("fold", seed)
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = fill_holes(holed, seed=seed, progress=False)
    assert all(h.filled for h in res.holes), res.holes
    assert any(h.layers == 2 for h in res.holes), res.holes  # reported as filled on two
    assert point_mesh_distance(truth[0], res.mesh).max() < 1e-6
    m = res.mesh
    assert len(crossing_faces(m.vertices, m.faces, len(holed.faces))) == 0
    e = np.sort(np.concatenate([m.faces[:, [0, 1]], m.faces[:, [1, 2]], m.faces[:, [2, 0]]]),
                axis=1)
    _, counts = np.unique(e, axis=0, return_counts=True)
    assert counts.max() == 2 and int((counts == 1).sum()) == res.border_edges


@pytest.mark.parametrize("seed", [1, 7, 19])
def test_a_wall_that_would_cross_the_scan_is_not_closed(seed: int) -> None:
    """A spiral ramp's holes lie over two layers too (the ramp's step winds around the
    centre), but the wall between its layers' fills, closed by chords, runs through the
    ramp: that fill is refused and the hole filled as before. Taking the layers' fills
    and leaving the wall to the loop stage had left these holes open (its fills crossed
    the scan: 15-155 triangles)."""
    from asrbf_mesh._hole_cross import crossing_faces
    from asrbf_mesh.evaluate._synthetic_holes import synthetic_holes

    holed = synthetic_holes("spiral", seed)
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = fill_holes(holed, seed=seed, progress=False)
    assert all(h.filled for h in res.holes), [h.reason for h in res.holes]
    m = res.mesh
    assert len(crossing_faces(m.vertices, m.faces, len(holed.faces))) == 0


def test_point_location_takes_the_one_column_candidates_a_kdtree_gives_for_k_1() -> None:
    """``cKDTree.query(k=1)`` returns (M,) indices; ``np.atleast_2d`` made them one row of
    M columns, the compiled loop read rows past its array and bun090's punched seed 6
    died with SIGSEGV in ``_fill_chain``."""
    from scipy.spatial import cKDTree

    from asrbf_mesh import _holes_kernels as hk

    xy = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    tri = np.array([[0, 1, 2]])
    pts = np.random.default_rng(0).uniform(-0.2, 1.0, (500, 2))
    _, cand = cKDTree(xy[tri].mean(axis=1)).query(pts, k=1)
    assert cand.shape == (500,)
    inside = hk.inside_any(pts, xy, tri, cand)
    truth = (pts[:, 0] > 0) & (pts[:, 1] > 0) & (pts.sum(axis=1) < 1)
    np.testing.assert_array_equal(inside, truth)
    # "no neighbour" (index n) and negative indices are skipped, bad triangles refused
    assert not hk.inside_any(pts[:3], xy, tri, np.full((3, 2), 1)).any()
    with pytest.raises(ValueError, match="indexes a point that does not exist"):
        hk.inside_any(pts, xy, np.array([[0, 1, 3]]), cand)
    with pytest.raises(ValueError, match="indexes a point that does not exist"):
        hk.coverage(xy, np.array([[0, 1, -1]]), np.zeros(2), 0.1, 10, 10)


def cylinder_scan(hole: bool = True) -> tuple[am.Scan, np.ndarray]:
    """Three quarters of a cylinder (radius 10, axis y) seen along z, with a hole on its
    steep side: the rim folds over itself in the view plane."""
    th, y = np.meshgrid(np.linspace(-0.75 * np.pi, 0.75 * np.pi, 60), np.linspace(0, 30, 40))
    pts = np.c_[10 * np.sin(th).ravel(), y.ravel(), 10 * np.cos(th).ravel()]
    nx, ny = 60, 40
    j, i = np.mgrid[0:ny - 1, 0:nx - 1]
    v = (j * nx + i).ravel()
    faces = np.r_[np.c_[v, v + 1, v + nx + 1], np.c_[v, v + nx + 1, v + nx]]
    centre = np.array([10 * np.sin(0.55 * np.pi), 15.0, 10 * np.cos(0.55 * np.pi)])
    inside = np.linalg.norm(pts - centre, axis=1) < 4.0 if hole else np.zeros(len(pts), bool)
    keep = np.flatnonzero(~inside)
    remap = np.full(len(pts), -1)
    remap[keep] = np.arange(len(keep))
    f = remap[faces]
    return am.Scan(pts[keep], f[(f >= 0).all(axis=1)]), pts[inside]


def test_a_hole_whose_rim_folds_in_the_view_plane_is_closed_in_3d() -> None:
    from asrbf_mesh._hole_loops import boundary_cycles

    holed, truth = cylinder_scan()
    assert len(truth) > 20
    cycles = boundary_cycles(holed.faces)
    assert len(cycles) == 2  # the outer border and the hole
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = fill_holes(holed, seed=0, progress=False)
    assert any(h.filled for h in res.holes)
    _, counts = edges_count(res.mesh.faces)
    assert counts.max() == 2
    loops = boundary_loops(res.mesh.faces)
    assert len(loops) == 1  # only the outer border stays open
    new = res.mesh.vertices[res.mesh.vertex_quality > 0]
    radius = np.linalg.norm(new[:, [0, 2]], axis=1)
    assert np.abs(radius - 10).max() < 0.6  # on the cylinder, within 6 % of its radius
    assert point_mesh_distance(truth, res.mesh).max() < 0.6


def test_a_loop_whose_plane_fill_gives_nothing_is_closed_through_the_disk(monkeypatch) -> None:
    """The loop stage's first fill (in the rim's plane) may fail outright, not only be
    refused: a folded sheet's 3-vertex gap was left open so (the rim could not be
    triangulated in its plane). The disk fill must still be tried."""
    from asrbf_mesh import _holes

    holed, _ = cylinder_scan()

    def no_plane_fill(state, job):
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64), "the rim could not be triangulated"

    monkeypatch.setattr(_holes, "_loop_job", no_plane_fill)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = fill_holes(holed, seed=0, progress=False)
    assert all(h.filled for h in res.holes), [h.reason for h in res.holes]
    assert len(boundary_loops(res.mesh.faces)) == 1  # only the outer border stays open
    _, counts = edges_count(res.mesh.faces)
    assert counts.max() == 2


def test_a_fragment_keeps_its_border_open_while_the_hole_beside_it_is_closed() -> None:
    """Each connected part's longest boundary loop is its outer border: never capped."""
    x, y = np.meshgrid(np.arange(30.0), np.arange(30.0))
    pts = np.c_[x.ravel(), y.ravel(), 0.02 * (x * y).ravel()]
    n = 30
    j, i = np.mgrid[0:n - 1, 0:n - 1]
    v = (j * n + i).ravel()
    faces = np.r_[np.c_[v, v + 1, v + n + 1], np.c_[v, v + n + 1, v + n]]
    hole = np.hypot(x - 15, y - 15).ravel() < 4
    keep = np.flatnonzero(~hole)
    remap = np.full(len(pts), -1)
    remap[keep] = np.arange(len(keep))
    f = remap[faces]
    f = f[(f >= 0).all(axis=1)]
    # a 4 x 4 fragment floating 50 above and beside the grid
    fx, fy = np.meshgrid(np.arange(4.0) + 40, np.arange(4.0) + 5)
    frag = np.c_[fx.ravel(), fy.ravel(), np.full(16, 50.0)]
    fv = (np.mgrid[0:3, 0:3][0] * 4 + np.mgrid[0:3, 0:3][1]).ravel()
    ffaces = np.r_[np.c_[fv, fv + 1, fv + 5], np.c_[fv, fv + 5, fv + 4]] + len(keep)
    scan = am.Scan(np.vstack([pts[keep], frag]), np.vstack([f, ffaces]))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = fill_holes(scan, seed=0, progress=False)
    new = res.mesh.vertices[res.mesh.vertex_quality > 0]
    assert len(new) and np.all(new[:, 2] < 49)  # nothing added on the fragment
    loops = boundary_loops(res.mesh.faces)
    assert sorted(len(lp) for lp in loops) == [12, 4 * (n - 1)]  # the two outer borders


@pytest.mark.parametrize("make", ["cylinder", "face_seed_6", "face_seed_4"])
def test_fills_do_not_intersect_the_scan_or_themselves(make: str) -> None:
    """pymeshlab's self-intersection selection finds no face of the fill."""
    import pymeshlab

    if make == "cylinder":
        holed, _ = cylinder_scan()
    else:
        from asrbf_mesh.evaluate._punch_protocol import punch_protocol

        # seed 4: a fill there crossed the scan where the face folds (14 triangles)
        holed = punch_protocol(am.load_scan(am.face_map_path()), int(make[-1])).scan
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = fill_holes(holed, seed=0, progress=False)
    n_scan_faces = len(holed.faces)
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=res.mesh.vertices, face_matrix=res.mesh.faces))
    ms.compute_selection_by_self_intersections_per_face()
    selected = np.flatnonzero(ms.current_mesh().face_selection_array())
    new_bad = selected[selected >= n_scan_faces]
    assert len(new_bad) == 0, f"{len(new_bad)} fill faces intersect"


def test_crossing_faces_finds_new_faces_through_the_scan_and_only_those() -> None:
    """A new triangle piercing an old one is found; one beside it, or sharing a corner, is not."""
    from asrbf_mesh._hole_cross import crossing_faces, triangles_cross

    v = np.array([[0, 0, 0], [2, 0, 0], [0, 2, 0],  # an old triangle in z = 0
                  [0.5, 0.5, -1], [0.5, 0.5, 1], [1.5, 1.5, 1],  # pierces it
                  [5, 5, 0], [6, 5, 0], [5, 6, 0],  # far beside it
                  [-1, 0, 0], [0, -1, 0]], dtype=float)  # shares its corner 0
    f = np.array([[0, 1, 2], [3, 4, 5], [6, 7, 8], [0, 9, 10]])
    assert crossing_faces(v, f, 1).tolist() == [1]
    assert crossing_faces(v, f[[0, 2, 3]], 1).tolist() == []
    assert crossing_faces(v, f, 4).tolist() == []  # no new face
    # a new face on the same corners: by the same vertices, reversed, it crosses (a lone
    # triangle closed by its reverse); by copies of them (a crack's corners) it does not
    w = np.vstack([v, v[:3]])
    assert crossing_faces(w, np.array([[0, 1, 2], [0, 2, 1]]), 1).tolist() == [1]
    assert crossing_faces(w, np.array([[0, 1, 2], [11, 13, 12]]), 1).tolist() == []
    # a soup of small triangles: the grid proposes every pair a brute force finds
    rng = np.random.default_rng(3)
    soup = rng.random((300, 1, 3)) * [10, 10, 1] + rng.normal(0, 0.4, (300, 3, 3))
    crossed = np.zeros(300, dtype=bool)
    for a in range(150, 300):
        others = np.delete(np.arange(300), a)
        hit = triangles_cross(np.repeat(soup[a][None], 299, 0), soup[others])
        crossed[a] |= hit.any()
        crossed[others[hit & (others >= 150)]] = True
    got = crossing_faces(soup.reshape(-1, 3), np.arange(900).reshape(-1, 3), 150)
    assert got.tolist() == (np.flatnonzero(crossed[150:]) + 150).tolist() and len(got) > 20


def test_crossing_of_a_few_faces_agrees_with_brute_force() -> None:
    """crossing_of tests a few faces against the faces near them only: the same answer as
    every pair, long triangles (boxes over many cells) and tests among each other too."""
    from asrbf_mesh._hole_cross import crossing_of, triangles_cross

    rng = np.random.default_rng(5)
    soup = rng.random((400, 1, 3)) * [10, 10, 1] + rng.normal(0, 0.3, (400, 3, 3))
    soup[:6] = rng.random((6, 3, 3)) * [10, 10, 1]  # long ones, across the soup
    faces = np.arange(1200).reshape(-1, 3)
    for test in (rng.choice(400, 40, replace=False), np.arange(10), np.array([7])):
        want = [bool(triangles_cross(np.repeat(soup[t][None], 399, 0),
                                     np.delete(soup, t, axis=0)).any()) for t in test]
        got = crossing_of(soup.reshape(-1, 3), faces, test)
        assert got.tolist() == want
    assert crossing_of(soup.reshape(-1, 3), faces, np.arange(40)).sum() > 5  # it does cross


def test_triangles_cross_agrees_with_edge_through_triangle_tests() -> None:
    """Random pairs as an edge-through-triangle test says; contact at a common corner or
    edge is no crossing, a corner on a triangle with no corner in common is."""
    from asrbf_mesh._hole_cross import crossing_faces, triangles_cross

    def edge_through(a, b, t):  # Moller-Trumbore, segment a-b against triangle t
        e1, e2, d = t[1] - t[0], t[2] - t[0], b - a
        h = np.cross(d, e2)
        det = e1 @ h
        if abs(det) < 1e-14:
            return False
        s = a - t[0]
        u = (s @ h) / det
        qv = np.cross(s, e1)
        v = (d @ qv) / det
        return 0 <= u <= 1 and v >= 0 and u + v <= 1 and 0 <= (e2 @ qv) / det <= 1

    rng = np.random.default_rng(5)
    p = rng.normal(size=(2000, 3, 3))
    q = rng.normal(size=(2000, 3, 3)) + rng.normal(scale=0.7, size=(2000, 1, 3))
    want = [any(edge_through(a[i], a[(i + 1) % 3], b) for i in range(3))
            or any(edge_through(b[i], b[(i + 1) % 3], a) for i in range(3))
            for a, b in zip(p, q, strict=True)]
    assert 200 < sum(want) < 1800
    assert triangles_cross(p, q).tolist() == want
    t = np.array([[0, 0, 0], [2, 0, 0], [0, 2, 0]], dtype=float)
    others = np.array([[[0, 0, 0], [-1, 0, 0], [0, -1, 0]],  # a shared corner, one plane
                       [[0, 0, 0], [2, 0, 0], [1, -1, 1]],  # a shared edge, bent
                       [[0, 0, 0], [2, 0, 0], [1, 1, 0]],  # a shared edge, folded onto it
                       [[0, 0, 0], [1, 1, -1], [1, 1, 1]]], dtype=float)  # a corner, through
    assert triangles_cross(np.repeat(t[None], 4, 0), others).tolist() == [False, False,
                                                                          True, True]
    # two disjoint triangles of one plane 30 units out, which VCG's test selects
    a = np.array([[35.0, 31.0, 33.5], [35.5, 29.5, 33.55], [36.0, 30.0, 33.6]])
    b = np.array([[35.5, 28.5, 33.55], [36.5, 27.5, 33.65], [37.0, 30.0, 33.7]])
    assert not triangles_cross(a[None], b[None])[0]
    # a wall seen edge-on (x = y) and a triangle with a corner on it, none in common: the
    # surface touches itself (pymeshlab's selection finds it); moved off by 1e-6, parted
    wall = np.array([[0, 0, 0], [2, 2, 0], [1, 1, 2]], dtype=float)
    on = np.array([[1, 1, 0.5], [2, 0, 0.5], [2, 1, 0.5]])
    off = on + [1e-6, 0, 0]
    shared = np.array([[0, 0, 0], [2, 0, 0.5], [2, 1, 0.5]])  # its corner one of the wall's
    assert triangles_cross(np.repeat(wall[None], 3, 0),
                           np.stack([on, off, shared])).tolist() == [True, False, False]
    v = np.vstack([wall, on])
    assert crossing_faces(v, np.array([[0, 1, 2], [3, 4, 5]]), 1).tolist() == [1]


def test_a_hole_punched_into_a_narrow_gap_is_filled_up_to_the_gap() -> None:
    """A bay (a disk behind a mouth narrower than BAY_MOUTH spacings) is filled; the gap is not."""
    scan = grid_scan(franke, nx=70, ny=70, size=(70.0, 70.0))
    xy = scan.points[:, :2]
    column = np.arange(len(xy)) % 70
    gap = (column == 35) & (xy[:, 1] > 30.0)  # one column of samples: a 2-wide gap to the top
    disk = np.hypot(xy[:, 0] - 35.0, xy[:, 1] - 25.0) < 9.0
    keep = np.flatnonzero(~(gap | disk))
    remap = np.full(len(xy), -1)
    remap[keep] = np.arange(len(keep))
    f = remap[scan.faces]
    holed = am.Scan(scan.points[keep], f[(f >= 0).all(1)])
    res = fill_holes(holed, seed=0, progress=False)
    new = res.mesh.vertices[res.mesh.vertex_quality > 0]
    assert len(new) > 100 and res.holes_filled >= 1
    assert np.hypot(*(new[:, :2] - [35.0, 25.0]).T).min() < 1.0  # the disk is filled ...
    assert new[:, 1].max() < 40.0  # ... the gap beyond it is not
    truth = franke(new[:, 0], new[:, 1])
    assert np.sqrt(np.mean((new[:, 2] - truth) ** 2)) < 0.05 * np.ptp(scan.points[:, 2])
    # with bays only behind mouths narrower than a spacing, the disk is outside: no fill
    import asrbf_mesh._holes as holes_mod

    old = holes_mod.BAY_MOUTH
    try:
        holes_mod.BAY_MOUTH = 0.5
        assert fill_holes(holed, res.network, progress=False).faces_added == 0
    finally:
        holes_mod.BAY_MOUTH = old


def test_a_bay_found_on_blocks_is_filled_with_the_same_bytes(monkeypatch) -> None:
    """The bay test's scan with its raster's bays looked for on blocks first: the same fill.

    Rasters of over 4 million cells take that path (a Kinect frame); here it is forced.
    """
    import asrbf_mesh._footprint as footprint

    scan = grid_scan(franke, nx=70, ny=70, size=(70.0, 70.0))
    xy = scan.points[:, :2]
    gap = (np.arange(len(xy)) % 70 == 35) & (xy[:, 1] > 30.0)
    disk = np.hypot(xy[:, 0] - 35.0, xy[:, 1] - 25.0) < 9.0
    pins = np.hypot(xy[:, 0] - 15.0, xy[:, 1] - 50.0) < 3.0  # a plain hole beside it
    keep = np.flatnonzero(~(gap | disk | pins))
    remap = np.full(len(xy), -1)
    remap[keep] = np.arange(len(keep))
    f = remap[scan.faces]
    holed = am.Scan(scan.points[keep], f[(f >= 0).all(1)])
    net = am.fit(holed, seed=0, progress=False)
    whole = fill_holes(holed, net, progress=False)
    monkeypatch.setattr(footprint, "_COARSE_CELLS", 0)
    blocks = fill_holes(holed, net, progress=False)
    assert whole.holes_filled == 2 and whole.vertices_added > 100
    assert np.array_equal(whole.mesh.vertices, blocks.mesh.vertices)
    assert np.array_equal(whole.mesh.faces, blocks.mesh.faces)


def test_the_protocol_tells_notches_by_the_traced_borders_on_request() -> None:
    """libigl cuts the face map's border at pinch vertices: a notch then counts as enclosed."""
    from asrbf_mesh.evaluate._punch_protocol import punch_protocol

    scan = am.load_scan(am.face_map_path())
    igl_ = punch_protocol(scan, 0)
    traced = punch_protocol(scan, 0, border="traced")
    parts = punch_protocol(scan, 0, border="parts")
    assert np.array_equal(igl_.truth, traced.truth)
    assert traced.n_enclosed < igl_.n_enclosed
    assert not np.any(traced.enclosed & ~igl_.enclosed)
    assert not np.any(parts.enclosed & ~traced.enclosed)


def test_a_small_loop_takes_the_chords_the_mesh_lacks() -> None:
    from asrbf_mesh._hole_close import _KEY, _chords_avoiding

    v = np.array([[0.0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]])
    loop = np.array([0, 1, 2, 3])
    known = np.array([1 * _KEY + 3])  # the diagonal 1-3 is already a mesh edge
    t = _chords_avoiding(loop, v, known)
    assert len(t) == 2 and all({0, 2} <= set(tri.tolist()) for tri in t)
    both = np.array([1 * _KEY + 3, 0 * _KEY + 2])  # no diagonal left: nothing
    assert len(_chords_avoiding(loop, v, both)) == 0


def test_a_loop_whose_every_chord_is_taken_is_closed_by_a_centre_fan() -> None:
    from asrbf_mesh._hole_close import _centre_fan
    from asrbf_mesh._hole_loops import boundary_cycles
    from asrbf_mesh._surface import grid_faces

    # a 4 x 4 vertex grid with its middle cell's two triangles gone: a quad hole
    x, y = np.meshgrid(np.arange(4.0), np.arange(4.0))
    v = np.c_[x.ravel(), y.ravel(), 0.1 * x.ravel() * y.ravel()]
    faces = grid_faces(4, 4)
    faces = np.delete(faces, [8, 9], axis=0)  # cell (1, 1): vertices 5, 6, 9, 10
    loops = sorted(boundary_cycles(faces), key=len)
    loop = loops[0]
    assert sorted(loop.tolist()) == [5, 6, 9, 10]
    new_v, tris = _centre_fan(loop, v)
    assert new_v.shape == (1, 3) and np.allclose(new_v[0], v[loop].mean(axis=0))
    closed = np.vstack([faces, np.where(tris < 0, len(v) - tris - 1, tris)])
    # the quad is gone: only the outer border is left, and every edge runs once each way
    assert [len(c) for c in boundary_cycles(closed)] == [12]
    he = np.concatenate([closed[:, [0, 1]], closed[:, [1, 2]], closed[:, [2, 0]]])
    assert len(np.unique(he, axis=0)) == len(he)


def test_the_edge_set_knows_the_mesh_edges_and_the_added_ones() -> None:
    from asrbf_mesh._hole_close import _KEY, _edge_keys, _EdgeSet

    faces = np.array([[0, 1, 2], [2, 1, 3]])
    known = _EdgeSet(np.unique(_edge_keys(faces)))
    probe = np.array([0 * _KEY + 1, 1 * _KEY + 2, 0 * _KEY + 3, 3 * _KEY + 4, 9 * _KEY + 10])
    assert known.contains(probe).tolist() == [True, True, False, False, False]
    known.add(_edge_keys(np.array([[3, 4, 0]])))
    assert known.contains(probe).tolist() == [True, True, True, True, False]
    assert known.contains(probe.reshape(5, 1)).shape == (5, 1)
    assert not _EdgeSet(np.zeros(0, np.int64)).contains(probe).any()


def test_edges_used_once_match_a_count_by_pairs() -> None:
    from asrbf_mesh._hole_find import used_once

    rng = np.random.default_rng(3)
    e = rng.integers(0, 30, size=(400, 2))
    e = e[e[:, 0] != e[:, 1]]
    pairs = [tuple(sorted(p)) for p in e.tolist()]
    expect = [pairs.count(p) == 1 for p in pairs]
    assert used_once(e).tolist() == expect
    assert used_once(np.zeros((0, 2), np.int64)).shape == (0,)


def test_a_patch_turns_to_the_scans_orientation_and_drops_clashing_triangles() -> None:
    from asrbf_mesh._hole_find import boundary_edges
    from asrbf_mesh._holes import _KEY, _agree_with_scan, _edge_keys

    scan = np.array([[0, 1, 2]])  # one scan triangle: rim edges 0->1, 1->2, 2->0
    rim = boundary_edges(scan)[0]
    rim_keys = np.sort(rim[:, 0].astype(np.int64) * _KEY + rim[:, 1])
    none = np.zeros(0, np.int64)
    # a patch across the rim edge 1-2 running it the scan's way (1 -> 2): turned round
    patch = np.array([[1, 2, 3], [3, 2, 4]])
    out, dropped = _agree_with_scan(patch, rim_keys, none)
    assert dropped == 0 and out.tolist() == [[1, 3, 2], [3, 4, 2]]
    # the right way round already: untouched, the same object
    assert _agree_with_scan(out, rim_keys, none)[0] is out
    # a triangle on an edge two scan faces share would give it a third face: dropped
    two = np.array([[0, 1, 2], [2, 1, 5]])
    keys, uses = np.unique(_edge_keys(two), return_counts=True)
    out, dropped = _agree_with_scan(np.array([[1, 2, 6], [6, 2, 7]]),
                                    np.zeros(0, np.int64), keys[uses >= 2])
    assert dropped == 1 and out.tolist() == [[6, 2, 7]]


def test_a_hole_whose_dropped_triangles_left_no_gap_counts_as_filled() -> None:
    from asrbf_mesh._hole_loops import outer_loops
    from asrbf_mesh._holes import HoleInfo, _closed_after_all, _edge_keys, _still_open

    # a 4 x 4 grid of cells, each cut into two triangles; cell (1, 1) punched out
    ij = np.arange(25).reshape(5, 5)
    cells = [(i, j) for i in range(4) for j in range(4)]
    tri = [t for i, j in cells for t in ([ij[i, j], ij[i + 1, j], ij[i + 1, j + 1]],
                                          [ij[i, j], ij[i + 1, j + 1], ij[i, j + 1]])]
    full = np.array(tri)
    holed = np.array([t for (i, j), t in zip(np.repeat(cells, 2, axis=0).tolist(), tri,
                                             strict=True) if (i, j) != (1, 1)])
    cell = _edge_keys(np.array(tri[2 * 5: 2 * 5 + 2]))  # the edges of cell (1, 1)
    border = _edge_keys(full[:2])  # a corner cell: two of its edges on the outer border

    def run(faces: np.ndarray, keys: np.ndarray) -> bool:
        infos = [HoleInfo(0, 1.0, 1.0, (0.0, 0.0, 0.0), 4, False, "2 triangles would ...")]
        _closed_after_all({0: keys}, infos, _still_open(faces, outer_loops(faces, 25)))
        return infos[0].filled

    assert run(full, cell)  # every edge shared by two faces: closed
    assert not run(holed, cell)  # the cell's rim is still open: a gap
    assert run(holed, border)  # open edges on the outer border only: closed


def _bays_whole_raster(labels, outside, rho):
    """The bay labelling with every distance transform over the whole raster (reference)."""
    from scipy import ndimage

    from asrbf_mesh._footprint import _BAY_WIDTH

    pad = int(np.ceil(rho)) + 2
    out = np.pad(np.isin(labels, list(outside)), pad, constant_values=True)
    edt = ndimage.distance_transform_edt(out)
    fits = edt > rho
    core, n = ndimage.label(fits, structure=np.ones((3, 3), bool))
    beyond = np.unique(np.concatenate([core[0], core[-1], core[:, 0], core[:, -1]]))
    inner = fits & ~np.isin(core, beyond)
    widest = np.zeros(n + 1)
    np.maximum.at(widest, core[inner], edt[inner])
    inner &= widest[core] >= _BAY_WIDTH * rho
    if not inner.any():
        return labels
    reach = ndimage.distance_transform_edt(~(fits & ~inner)) <= rho
    dist, (ii, jj) = ndimage.distance_transform_edt(~inner, return_indices=True)
    bay = out & ~reach & (dist <= rho + 2.0)
    new = labels.copy()
    sl = (slice(pad, -pad), slice(pad, -pad))
    mask = bay[sl]
    _, inv = np.unique(core[ii, jj][sl][mask], return_inverse=True)
    new[mask] = int(labels.max()) + 1 + inv.ravel()
    return new


@pytest.mark.parametrize("case", range(6))
@pytest.mark.parametrize(("max_windows", "coarse_cells"), [(64, None), (0, None), (64, 0),
                                                           (0, 0)])
def test_bays_found_in_a_window_match_the_whole_raster(case: int, max_windows: int,
                                                       coarse_cells: int | None,
                                                       monkeypatch) -> None:
    """The bays' distance transforms run on windows around their cores: the same labels.

    With ``max_windows`` 0, one window around every core (what many cores get); with
    ``coarse_cells`` 0, the cores looked for on blocks first and measured in boxes
    around them (what a large raster gets: blocks of 2 x 2 cells for rho 5.5, 3 x 3 for
    rho 8; rho 3 stays on the whole raster).
    """
    from scipy import ndimage

    import asrbf_mesh._footprint as footprint
    from asrbf_mesh._footprint import _label_bays

    monkeypatch.setattr(footprint, "_MAX_WINDOWS", max_windows)
    if coarse_cells is not None:
        monkeypatch.setattr(footprint, "_COARSE_CELLS", coarse_cells)

    rng = np.random.default_rng(case)
    y, x = np.mgrid[0:120, 0:160]
    covered = np.ones((120, 160), bool)
    covered[:, :6] = covered[:, -6:] = covered[:6] = covered[-6:] = False  # the outside
    for _ in range(3):  # disks behind narrow or wide slits to the outside
        cy, cx, r = rng.integers(30, 90), rng.integers(35, 125), rng.integers(8, 22)
        covered &= np.hypot(y - cy, x - cx) >= r
        w = int(rng.integers(1, 12))
        covered[cy - w // 2: cy + w // 2 + 1, cx:] = False if case % 2 else covered[
            cy - w // 2: cy + w // 2 + 1, cx:]
        if case % 2 == 0:
            covered[cy:, cx - w // 2: cx + w // 2 + 1] = False
    labels, _ = ndimage.label(~covered, structure=np.ones((3, 3), bool))
    outside = frozenset(np.unique(np.concatenate(
        [labels[0], labels[-1], labels[:, 0], labels[:, -1]])).tolist()) - {0}
    for rho in (3.0, 5.5, 8.0):
        np.testing.assert_array_equal(_label_bays(labels, outside, rho),
                                      _bays_whole_raster(labels, outside, rho))


def test_simple_cycles_cut_a_walk_at_the_vertices_it_passes_twice() -> None:
    from asrbf_mesh._hole_loops import simple_cycles

    # a border 0..5 that passes vertex 2 twice, with the gap 2-6-7 pinched off it
    walk = np.array([0, 1, 2, 6, 7, 2, 3, 4, 5])
    got = sorted(map(list, simple_cycles(walk)), key=len)
    assert got == [[2, 6, 7], [0, 1, 2, 3, 4, 5]]
    # a slit (out and straight back) has no area: dropped; a simple cycle stays whole
    assert [c.tolist() for c in simple_cycles(np.array([0, 1, 2, 8, 2, 3]))] == [[0, 1, 2, 3]]
    assert [c.tolist() for c in simple_cycles(np.arange(5))] == [list(range(5))]


def test_a_gap_pinched_off_the_outer_border_is_closed_a_blob_is_not() -> None:
    from asrbf_mesh._hole_loops import split_loops
    from asrbf_mesh._holes import HoleInfo, _close_loops, _rim_keys, _winds_as_hole

    # a 6 x 6 grid of cells (counter-clockwise triangles): cell (1, 0) cut out of the
    # border, cell (2, 1) punched out: they share a vertex; the vertices renumbered so
    # that the border's walk runs through the punched cell at that pinch
    n = 7
    ij = np.arange(n * n).reshape(n, n)
    faces = np.array([t for i in range(n - 1) for j in range(n - 1)
                      if (i, j) not in {(1, 0), (2, 1)}
                      for t in ([ij[i, j], ij[i + 1, j], ij[i + 1, j + 1]],
                                [ij[i, j], ij[i + 1, j + 1], ij[i, j + 1]])])
    perm = np.random.default_rng(6).permutation(n * n)
    faces = perm[faces]
    grid = np.stack(np.meshgrid(np.arange(n), np.arange(n), indexing="ij"), -1).reshape(-1, 2)
    xyz = np.zeros((n * n, 3))
    xyz[perm, :2] = grid
    xyz[perm, 2] = 0.02 * (grid ** 2).sum(axis=1)
    outer, rest = split_loops(faces, n * n)
    assert not rest and len(outer[0]) == 30  # the gap is walked as part of the border
    cell = perm[[ij[2, 1], ij[3, 1], ij[3, 2], ij[2, 2]]]
    assert not _winds_as_hole(xyz[outer[0]], True)  # the border winds as a blob's

    def run(hole_keys: np.ndarray) -> tuple[bool, int]:
        infos = [HoleInfo(0, 1.0, 1.0, (2.5, 1.5, 0.0), 4, False, "2 rim edges ...")]
        v, f, border = _close_loops(xyz, faces, infos, [set(cell.tolist())], hole_keys,
                                    True, xyz, np.eye(3), 1.0, None, 10.0)
        assert len(v) == len(xyz) and len(border) == 1
        return infos[0].filled, len(f) - len(faces)

    assert run(np.sort(_rim_keys(cell))) == (True, 2)  # the gap is closed: two triangles
    assert run(np.zeros(0, np.int64)) == (False, 0)  # no hole's rim in it: left alone
    # the triangles' half-edges run clockwise around a hole (the cell taken the other
    # way round), counter-clockwise around a blob (the cell itself): never filled
    assert _winds_as_hole(xyz[cell[::-1]], True) and not _winds_as_hole(xyz[cell], True)
    assert _winds_as_hole(xyz[cell], False)


def wedge_scan(tau: float = 21.4, nx: int = 80, ny: int = 30
               ) -> tuple[am.Scan, np.ndarray]:
    """A perspective-like scan: its sampling 40 times coarser at one end than the other.

    Sample ``(u, v)`` of the grid sits at ``x = tau (e^(u/tau) - 1)``,
    ``y = (v - ny/2) e^(u/tau)``: locally square cells whose size grows with ``u``, as a
    depth frame's footprint grows with depth. Returns the scan with the triangles around
    ``(u, v) = (68, 15)`` removed (radius 5 samples) and those samples' mask.
    """
    u, v = (a.ravel() for a in np.meshgrid(np.arange(nx, dtype=float),
                                            np.arange(ny, dtype=float)))
    s = np.exp(u / tau)
    x, y = tau * (s - 1.0), (v - ny / 2) * s
    pts = np.c_[x, y, 30.0 * np.sin(x / 150.0) + 20.0 * np.cos(y / 120.0)]
    faces = grid_faces(nx, ny)
    gone = (u - 68.0) ** 2 + (v - 15.0) ** 2 < 25.0
    return am.Scan(pts, faces[~gone[faces].any(axis=1)]), gone


def test_a_hole_where_the_scan_is_sparse_is_filled_at_its_own_sampling(monkeypatch) -> None:
    import asrbf_mesh._holes as H

    scan, gone = wedge_scan()
    res = fill_holes(scan, seed=0, progress=False)
    assert res.holes_filled == res.holes_found == 1
    # about one new vertex per missing sample (69), not the scan's median spacing's
    # sixteen times as many
    assert 0.5 * gone.sum() <= res.vertices_added <= 1.5 * gone.sum()
    truth = point_mesh_distance(scan.points[gone], res.mesh)
    monkeypatch.setattr(H, "LOCAL_SPACING", np.inf)  # every hole at the scan's spacing
    dense = fill_holes(scan, seed=0, progress=False)
    assert dense.vertices_added > 10 * res.vertices_added
    # as close to the missing samples as the dense fill, within a tenth of the local spacing
    spacing = np.exp(68.0 / 21.4)
    assert np.sqrt(np.mean(truth ** 2)) <= np.sqrt(np.mean(
        point_mesh_distance(scan.points[gone], dense.mesh) ** 2)) + 0.1 * spacing


@pytest.mark.parametrize("case", range(25))
def test_bays_found_on_blocks_match_the_whole_raster_on_random_rasters(case: int,
                                                                       monkeypatch) -> None:
    """Random disks behind slits of every width, specks of coverage: the same bays both ways.

    The boxes grow where a core found on blocks reaches past them through a channel the
    blocks do not see; rho 4.5 and 6 use blocks of 2 x 2 cells, 7.5 and 12 of 3 x 3.
    """
    from scipy import ndimage

    import asrbf_mesh._footprint as footprint
    from asrbf_mesh._footprint import _label_bays

    rng = np.random.default_rng(case)
    h, w = rng.integers(100, 260, 2)
    y, x = np.mgrid[0:h, 0:w]
    covered = np.ones((h, w), bool)
    b = int(rng.integers(3, 10))
    covered[:, :b] = covered[:, -b:] = covered[:b] = covered[-b:] = False
    for _ in range(int(rng.integers(1, 7))):
        cy, cx, r = rng.integers(20, h - 20), rng.integers(20, w - 20), rng.integers(6, 30)
        covered &= np.hypot(y - cy, x - cx) >= r
        half = int(rng.integers(1, 25)) // 2
        rows, cols = slice(cy - half, cy + half + 1), slice(cx - half, cx + half + 1)
        slits = [(rows, slice(cx, None)), (rows, slice(None, cx)), (slice(cy, None), cols),
                 (slice(None, cy), cols)]
        covered[slits[int(rng.integers(4))]] = False
    covered |= rng.random((h, w)) < 0.002
    labels, _ = ndimage.label(~covered, structure=np.ones((3, 3), bool))
    outside = frozenset(np.unique(np.concatenate(
        [labels[0], labels[-1], labels[:, 0], labels[:, -1]])).tolist()) - {0}
    for rho in (4.5, 6.0, 7.5, 12.0):
        monkeypatch.setattr(footprint, "_COARSE_CELLS", 10**12)
        whole = _label_bays(labels, outside, rho)
        monkeypatch.setattr(footprint, "_COARSE_CELLS", 0)
        np.testing.assert_array_equal(_label_bays(labels, outside, rho), whole)


def test_a_loop_through_a_pinch_vertex_is_closed_cycle_by_cycle() -> None:
    from scipy.spatial import cKDTree

    from asrbf_mesh._hole_close import _KEY, _centre_fan, _edge_keys, _fill_cycles, _fits
    from asrbf_mesh._hole_loops import boundary_cycles
    from asrbf_mesh._surface import grid_faces

    # a 5 x 5 vertex grid without cells (1, 1) and (2, 2): two quad gaps meeting at
    # vertex 12, one loop of 8 edges that passes it twice
    x, y = np.meshgrid(np.arange(5.0), np.arange(5.0))
    v = np.c_[x.ravel(), y.ravel(), 0.05 * x.ravel() ** 2]
    faces = grid_faces(5, 5)
    cells = [(1, 1), (2, 2)]
    drop = [2 * (r * 4 + c) + k for r, c in cells for k in (0, 1)]
    faces = np.delete(faces, drop, axis=0)
    assert sorted(len(c) for c in boundary_cycles(faces)) == [4, 4, 16]
    loop = np.array([12, 7, 6, 11, 12, 17, 18, 13])  # both gaps, as one walk through 12
    keys = np.unique(_edge_keys(faces))
    # one fan around the whole loop gives the edge to the pinch vertex four faces
    _, fan = _centre_fan(loop, v)
    assert not _fits(fan, loop, keys)
    # both diagonals of both quads taken: chords cannot close them, fans per cycle do
    taken = np.unique(np.r_[keys, [6 * _KEY + 12, 7 * _KEY + 11, 12 * _KEY + 18,
                                   13 * _KEY + 17]])
    new_v, tris, reason = _fill_cycles(loop, v, 1.0, v, cKDTree(v), taken, np.eye(3), True)
    assert reason is None
    assert len(new_v) == 2 and sorted(np.unique(tris[tris < 0]).tolist()) == [-2, -1]
    assert _fits(tris, loop, taken)
    closed = np.vstack([faces, np.where(tris < 0, len(v) - tris - 1, tris)])
    assert [len(c) for c in boundary_cycles(closed)] == [16]  # the outer border only
    he = np.concatenate([closed[:, [0, 1]], closed[:, [1, 2]], closed[:, [2, 0]]])
    assert len(np.unique(he, axis=0)) == len(he)


def _grid_scan(z, keep=None):
    """A range grid (spacing 1) as a scan; ``keep(x, y)`` masks points; no triangle across
    a depth jump of more than 2."""
    ny, nx = z.shape
    y, x = np.mgrid[0:ny, 0:nx].astype(float)
    ok = np.ones(z.shape, bool) if keep is None else keep(x, y)
    idx = np.full(z.shape, -1)
    idx[ok] = np.arange(ok.sum())
    pts = np.c_[x[ok], y[ok], z[ok]]
    a, b, c, d = idx[:-1, :-1], idx[:-1, 1:], idx[1:, :-1], idx[1:, 1:]
    tris = np.vstack([np.stack([a, b, d], -1).reshape(-1, 3),
                      np.stack([a, d, c], -1).reshape(-1, 3)])
    tris = tris[(tris >= 0).all(1)]
    tris = tris[np.ptp(pts[tris, 2], axis=1) <= 2]
    return am.Scan(pts, tris)


def test_a_hole_larger_than_the_limit_is_split_into_its_bays() -> None:
    from asrbf_mesh._hole_find import find_holes

    # two disks (radius 10) joined by a channel 2 wide: one hole 56 across
    def keep(x, y):
        d1, d2 = np.hypot(x - 20, y - 30), np.hypot(x - 60, y - 30)
        channel = (np.abs(y - 30) < 1.2) & (x > 20) & (x < 60)
        return ~((d1 < 10) | (d2 < 10) | channel)

    scan = _grid_scan(np.zeros((60, 82)), keep)
    xy = scan.points[:, :2]
    whole, _, _ = find_holes(xy, scan.faces, 1.0, bay_mouth=8.0)
    assert len(whole) == 1 and whole[0].size > 56
    split, _, fp = find_holes(xy, scan.faces, 1.0, bay_mouth=8.0, max_size=40.0)
    small = [h for h in split if h.size <= 40.0]
    assert len(small) == 2 and all(20 <= h.size <= 32 for h in small)
    rest = [h for h in split if h.size > 40.0]
    assert [h.size for h in rest] == [whole[0].size]  # the channel keeps the whole's size
    res = fill_holes(scan, max_hole_size=40.0, seed=0, progress=False)
    done = [i for i in res.holes if i.filled]
    assert len(done) == 2 and all(i.vertices_added > 150 for i in done)
    left = [i for i in res.holes if not i.filled]
    assert len(left) == 1 and left[0].reason.startswith("larger than max_hole_size")
    # no fill over the channel: it stays a gap between the two patches
    new = res.mesh.vertices[scan.n_points:]
    assert not np.any((np.abs(new[:, 1] - 30) < 0.9) & (new[:, 0] > 33) & (new[:, 0] < 47))


def test_a_hole_across_a_cliff_is_filled_on_each_side() -> None:
    # a step of 8 between two flat terraces (x < 30: z = 0, else 8); no triangle across
    # it; a disk of radius 11 punched on the cliff (a bay of the gap along the cliff)
    z = np.where(np.mgrid[0:60, 0:60][1] < 30, 0.0, 8.0)
    scan = _grid_scan(z, lambda x, y: np.hypot(x - 29.5, y - 30) >= 11)
    res = fill_holes(scan, seed=0, progress=False)
    assert res.network.n_pieces >= 2
    new = res.mesh.vertices[scan.n_points:]
    left, right = new[new[:, 0] < 27], new[new[:, 0] > 32]
    assert len(left) > 20 and len(right) > 20
    assert np.abs(left[:, 2]).max() < 0.05  # each side continues its own terrace
    assert np.abs(right[:, 2] - 8).max() < 0.05


def test_parts_tell_a_gap_from_a_blob_whatever_the_winding() -> None:
    """A small boundary cycle is a gap when the triangles on its edges have more border
    elsewhere: a missing triangle seen nearly edge-on winds either way (desk2 kept one
    open), while a triangle pinched to the mesh at one vertex is a blob."""
    from asrbf_mesh._hole_close import _Parts

    faces = grid_faces(6, 6)
    gap = faces[20]  # an inner triangle, taken out: its three edges bound a gap
    pinched = np.array([[35, 36, 37]])  # a triangle on the grid's last corner vertex only
    mesh_faces = np.vstack([np.delete(faces, 20, axis=0), pinched])
    parts = _Parts(mesh_faces)
    assert parts.is_gap(gap)
    assert not parts.is_gap(pinched[0])
    # a larger cycle is left to its winding
    ring = np.array([0, 1, 2, 3, 4, 5, 11, 17, 23, 29])
    assert not parts.is_gap(ring)


def test_a_disk_fill_keeps_its_interior_small_whatever_the_rim() -> None:
    """A loop with one rim edge hundreds of times its median asked the disk fill for
    ~630,000 interior vertices (a 37-vertex rim 3,700 median edges long): libigl's
    fairing then ran for minutes on gigabytes. The interior is capped."""
    from asrbf_mesh._hole_loops import _DISK_SAMPLES, _fill_by_disk

    # 36 points 0.01 apart on a short arc, then one far away: the closing edges are long
    t = np.linspace(0.0, 0.35, 36)
    rim = np.column_stack([np.cos(t), np.sin(t), np.zeros_like(t)])
    rim = np.vstack([rim, [[-15.0, 8.0, 0.5]]])
    loop = np.arange(len(rim))
    new, tris, why = _fill_by_disk(loop, rim)
    assert why is None, why
    assert 0 < len(new) <= 1.2 * _DISK_SAMPLES
    assert np.all(np.isfinite(new))
    assert set(np.unique(tris[tris >= 0])) <= set(loop.tolist())


def _grid(nx: int, ny: int, x0: float = 0.0, y0: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    from asrbf_mesh._surface import grid_faces

    x, y = np.meshgrid(np.arange(nx, dtype=float) + x0, np.arange(ny, dtype=float) + y0)
    return np.c_[x.ravel(), y.ravel(), np.zeros(x.size)], grid_faces(ny, nx)


def test_the_protocol_counts_a_fragment_pinched_at_a_vertex_as_a_part() -> None:
    """Its border is an outer border (a bite out of it is a notch); a hole's is not."""
    from asrbf_mesh._hole_loops import boundary_cycles
    from asrbf_mesh.evaluate._punch_protocol import _part_borders

    v, f = _grid(8, 8)
    f = f[~np.isin(f, 27).any(axis=1)]  # a hole around the inner vertex 27
    hole = [c for c in boundary_cycles(f) if 0 not in c]
    assert len(hole) == 1
    v2, f2 = _grid(3, 3, 7.0, 7.0)  # a 3 x 3 fragment whose corner is the grid's corner 63
    f2 = f2 + len(v)
    f2[f2 == len(v)] = 63
    faces = np.vstack([f, f2])
    borders = _part_borders(faces, len(v) + len(v2))
    assert len(borders) == 2
    assert sorted(len(b) for b in borders) == [8, 28]  # the fragment's and the grid's
    assert not any(set(b.tolist()) == set(h.tolist()) for b in borders for h in hole)


def test_the_protocol_leaves_out_a_fragment_erased_whole() -> None:
    """Truth with no kept, meshed vertex beside it has nothing around it to fill from."""
    from asrbf_mesh.evaluate._punch_protocol import _rimmed

    v, f = _grid(6, 6)
    v2, f2 = _grid(2, 2, 10.0, 0.0)  # an island of two triangles, far from the grid
    faces = np.vstack([f, f2 + len(v)])
    removed = np.zeros(len(v) + len(v2), dtype=bool)
    removed[[14, 15, 20, 21]] = True  # inside the grid: a hole with a rim
    removed[len(v):] = True  # the whole island
    hole = np.r_[np.zeros(4, int), np.ones(4, int)]  # removed points in index order
    assert _rimmed(hole, removed, faces).tolist() == [True, False]


def test_a_hole_around_an_island_is_filled_without_covering_the_island() -> None:
    """A ring-shaped hole around an island of scan on a lattice: the patch's triangles
    over the island have centroids on its lattice points (on no triangle's inside), and
    some stayed over it (a second layer there, and a gap where those sharing its edges
    were dropped). The patch now covers the ring alone: the faces' view-plane areas sum
    to the square's, and only the outer border stays open."""
    from asrbf_mesh._hole_loops import boundary_cycles
    from asrbf_mesh.evaluate._synthetic_holes import synthetic_holes

    for seed in (28, 42):
        scan = synthetic_holes("nested", seed)
        n = int(scan.points[:, 0].max()) + 1
        assert len(boundary_cycles(scan.faces)) == 3  # border, ring's outside, island's
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = fill_holes(scan, seed=seed, progress=False)
        assert res.holes_found == res.holes_filled == 1
        assert len(boundary_cycles(res.mesh.faces)) == 1
        _, counts = edges_count(res.mesh.faces)
        assert counts.max() == 2
        v = res.mesh.vertices
        f = res.mesh.faces
        a = np.cross(v[f[:, 1], :2] - v[f[:, 0], :2], v[f[:, 2], :2] - v[f[:, 0], :2]) / 2
        assert np.all(a > 0)
        assert abs(a.sum() - (n - 1) ** 2) < 1e-6 * n ** 2


@pytest.mark.parametrize("seed", [25, 27])
def test_a_hole_the_loop_stage_finishes_is_reported_filled(seed: int) -> None:
    """The view-plane patch of a hole on a cylinder's steep side misses a few rim edges;
    the loop stage closes them in 3D. The hole was reported open ("4 rim edges could
    not be closed") with nothing open but the outer border: a partial patch is judged,
    like one whose triangles clashed, by what is still open at the end."""
    from asrbf_mesh._hole_loops import boundary_cycles
    from asrbf_mesh.evaluate._synthetic_holes import synthetic_holes

    scan = synthetic_holes("cylinder", seed)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = fill_holes(scan, seed=seed, progress=False)
    assert len(boundary_cycles(res.mesh.faces)) == 1
    assert res.holes_found == res.holes_filled == 1
    assert all(h.reason is None for h in res.holes)


def test_a_gap_the_border_walk_ran_through_is_closed_by_a_second_loop_pass(monkeypatch) -> None:
    """A Kinect crop meshed as its range grid (float32 coordinates, as a PLY holds them):
    part of a 156-vertex hole's rim is walked as the outer border until the other loops
    are filled, and becomes a loop of its own only then. One more pass of the loop stage
    closes it (23 rim edges were left open). That fill then crosses the scan (1,353 of
    its triangles: the crop's depth steps), so the fill leaves it out unless told not to
    look (here, for the second pass's sake); either way no edge gets a third face."""
    from pathlib import Path

    import asrbf_mesh._holes as holes_mod
    from asrbf_mesh._hole_cross import crossing_faces
    from asrbf_mesh._range import read_depth_image

    g = read_depth_image(Path(__file__).parent / "data" / "tum_desk2_crop.png",
                         depth_scale=5000, intrinsics=(520.9, 521.0, 305.1, 139.7))
    s = g.to_scan()
    scan = am.Scan((s.points * [1.0, -1.0, -1.0]).astype(np.float32).astype(np.float64),
                   s.faces[:, ::-1])
    with warnings.catch_warnings():  # in the view plane (by default: the camera's frame)
        warnings.simplefilter("ignore")
        res = fill_holes(scan, seed=0, progress=False, frame="view")
        with monkeypatch.context() as m:
            m.setattr(holes_mod, "_leave_out_crossings",
                      lambda v, f, outer, owner, *_: (v, f, outer, owner, []))
            crossing = fill_holes(scan, seed=0, progress=False, frame="view")
    big = [h for h in crossing.holes if h.rim_vertices > 100]
    assert len(big) == 1 and big[0].filled and big[0].reason is None
    (big,) = [h for h in res.holes if h.rim_vertices > 100]
    assert big.filled or "would cross the scan" in big.reason
    assert len(crossing_faces(res.mesh.vertices, res.mesh.faces, len(scan.faces))) == 0
    # the report adds up to the mesh: a loop's fill counted once, with the hole owning it
    assert len(res.mesh.faces) == len(scan.faces) + res.faces_added
    assert len(res.mesh.vertices) == scan.n_points + res.vertices_added
    for out in (res, crossing):
        _, counts = edges_count(out.mesh.faces)
        assert counts.max() == 2
        assert np.array_equal(out.mesh.vertices[:scan.n_points], scan.points)


def _kinect_crop_mesh() -> am.Scan:
    """The Kinect desk2 crop meshed as its range grid, as a float32 PLY holds it."""
    from pathlib import Path

    from asrbf_mesh._range import read_depth_image

    g = read_depth_image(Path(__file__).parent / "data" / "tum_desk2_crop.png",
                         depth_scale=5000, intrinsics=(520.9, 521.0, 305.1, 139.7))
    s = g.to_scan()
    return am.Scan((s.points * [1.0, -1.0, -1.0]).astype(np.float32).astype(np.float64),
                   s.faces[:, ::-1])


def test_a_loop_fill_that_crosses_leaves_the_hole_beside_it_filled() -> None:
    """A flat grid with two cells out: hole 0 closed by its patch, the other cell by a
    loop fill the loop stage credited to hole 0 (a shared rim vertex). A fin of the scan
    stands in that cell, so its fill crosses and goes (chords would cross it too); a wall
    of the loop stage through hole 0's patch goes whole, and the patch, which crosses only
    that wall, stays. Hole 0 is filled; the cell is reported as a gap of its own."""
    from asrbf_mesh._hole_close import _rim_keys_of
    from asrbf_mesh._hole_loops import outer_loops
    from asrbf_mesh._holes import HoleInfo, _leave_out_crossings

    x, y = np.meshgrid(np.arange(6.0), np.arange(6.0))
    grid = np.column_stack([x.ravel(), y.ravel(), np.zeros(36)])
    fin = [[3.1, 3.5, -1.0], [3.9, 3.5, -1.0], [3.5, 3.5, 1.0]]  # in cell 18 (row 3, col 3)
    wall = [[1.1, 1.5, -1.0], [1.9, 1.5, -1.0], [1.5, 1.5, 1.0]]  # in cell 6 (row 1, col 1)
    v = np.vstack([grid, fin, wall])
    f = grid_faces(6, 6)
    scan = np.vstack([np.delete(f, [12, 13, 36, 37], axis=0), [[36, 37, 38]]])
    faces = np.vstack([scan, f[[12, 13]], f[[36, 37]], [[39, 40, 41]]])
    first, loops = len(scan), len(scan) + 2
    owner = np.r_[np.full(first, -1), np.zeros(5, np.int64)]
    infos = [HoleInfo(0, 1.4, 10.0, (1.5, 1.5, 0.0), 4, True, None, 3, 5)]
    rim = _rim_keys_of(np.array([[7, 8], [8, 14], [14, 13], [13, 7]]))
    outer = outer_loops(faces[:-1], len(v))  # the grid's border and the fin's
    out_v, out_f, _, out_owner, opened = _leave_out_crossings(
        v, faces, outer, owner, infos, first, loops, 39, np.eye(3), [rim], 14.0)
    assert opened == {} and np.array_equal(out_owner, owner[:first + 2])
    assert len(out_v) == 39  # the wall's vertices dropped
    assert len(out_f) == first + 2
    assert np.array_equal(out_f[first:], f[[12, 13]])  # the patch stays
    assert infos[0].filled and infos[0].reason is None and infos[0].faces_added == 2
    assert len(infos) == 2 and not infos[1].filled
    assert infos[1].reason.startswith("a gap beside hole 0: ")


def test_close_gaps_mends_a_flat_gap_by_chords_and_leaves_a_wall() -> None:
    """Two triangles left out of a flat grid: closed by chords. The same gap stood on its
    edge (a wall between two layers, seen edge-on) stays open."""
    from asrbf_mesh._hole_close import _edge_keys, close_gaps

    def closed(v: np.ndarray) -> int:
        f = grid_faces(5, 5)
        gone = f[[12, 13]]
        kept = np.delete(f, [12, 13], axis=0)
        keys, count = np.unique(_edge_keys(kept), return_counts=True)
        gap = np.intersect1d(keys[count == 1], _edge_keys(gone))  # the open edges but the border
        tris, mends = close_gaps(v, kept, gap, np.unique(_edge_keys(gone)), 0.15)
        assert len(tris) == len(mends)
        normal = np.cross(v[tris[:, 1]] - v[tris[:, 0]], v[tris[:, 2]] - v[tris[:, 0]])
        assert np.all(normal @ np.cross(v[1] - v[0], v[5] - v[0]) > 0)  # the grid's way
        return len(tris)

    x, y = np.meshgrid(np.arange(5.0), np.arange(5.0))
    flat = np.column_stack([x.ravel(), y.ravel(), np.zeros(25)])
    assert closed(flat) == 2
    wall = flat[:, [0, 2, 1]]  # the grid in the xz plane: seen edge-on from +z
    assert closed(wall) == 0


def test_min_area_triangulation_takes_the_smaller_diagonal() -> None:
    """The compiled dynamic programme: a planar convex polygon costs its area whatever
    the triangulation; a bent quad takes the diagonal of the smaller two triangles."""
    from asrbf_mesh._hole_close import _min_area

    t = np.linspace(0, 2 * np.pi, 9)[:-1]
    octagon = np.column_stack([np.cos(t), np.sin(t), np.zeros(8)])
    cost, _ = _min_area(octagon, np.ones((8, 8), dtype=bool))
    assert cost[0, 7] == pytest.approx(2 * np.sqrt(2))  # the regular octagon's area
    quad = np.array([[0.0, 0, 0], [1, 0, 1], [1, 1, 0], [0, 1, 1]])
    cost, pick = _min_area(quad, np.ones((4, 4), dtype=bool))
    ac = 2 * 0.5 * np.linalg.norm(np.cross(quad[1] - quad[0], quad[2] - quad[0]))
    bd = 2 * 0.5 * np.linalg.norm(np.cross(quad[2] - quad[1], quad[3] - quad[1]))
    assert cost[0, 3] == pytest.approx(min(ac, bd))
    free = np.ones((4, 4), dtype=bool)
    free[0, 2] = free[2, 0] = False  # a diagonal the mesh has: the other one
    cost, pick = _min_area(quad, free)
    assert pick[0, 3] in (1, 2) and np.isfinite(cost[0, 3])


@pytest.mark.parametrize("seed", [4, 16])
def test_a_hole_on_a_cylinders_steep_side_is_filled_again_whole_when_its_fill_crosses(
        seed, monkeypatch) -> None:
    """The patch and the loop stage's fill of what it missed crossed each other there."""
    import asrbf_mesh._holes as holes_mod
    from asrbf_mesh._hole_cross import crossing_faces
    from asrbf_mesh.evaluate._synthetic_holes import synthetic_holes

    scan = synthetic_holes("cylinder", seed)  # a part-cylinder around the y axis
    radius = float(np.median(np.hypot(scan.points[:, 0], scan.points[:, 2])))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = fill_holes(scan, seed=seed, progress=False)
        with monkeypatch.context() as m:  # without the refill: left open
            m.setattr(holes_mod, "refill_crossed",
                      lambda v, f, owner, outer, *_: (v, f, owner, outer, {}))
            before = fill_holes(scan, seed=seed, progress=False)
    assert before.holes_filled < before.holes_found
    assert res.holes_filled == res.holes_found == 1
    (hole,) = res.holes
    mesh = res.mesh
    assert hole.faces_added == len(mesh.faces) - len(scan.faces)
    assert hole.vertices_added == len(mesh.vertices) - len(scan.points)
    assert len(crossing_faces(mesh.vertices, mesh.faces, len(scan.faces))) == 0
    new = mesh.vertices[len(scan.points):]
    assert np.abs(np.hypot(new[:, 0], new[:, 2]) - radius).max() < 0.01 * radius
    assert len(boundary_loops(mesh.faces)) == 1  # the outer border only
    half = np.vstack([mesh.faces[:, [0, 1]], mesh.faces[:, [1, 2]], mesh.faces[:, [2, 0]]])
    assert len(np.unique(half, axis=0)) == len(half)  # oriented as the scan, manifold


def test_the_near_faces_test_of_a_refill_agrees_with_every_pair() -> None:
    """A fill's crossings against the faces near it only, as against every face."""
    from asrbf_mesh._hole_cross import crossing_faces
    from asrbf_mesh._hole_refill import _Near

    x, y = np.meshgrid(np.arange(8.0), np.arange(8.0))
    v = np.column_stack([x.ravel(), y.ravel(), np.zeros(64)])
    faces = np.vstack([grid_faces(8, 8), [[0, 9, 63]]])  # and one long face across it
    v[63, 2] = 0.5
    near = _Near(v, faces)
    rng = np.random.default_rng(0)
    for _ in range(40):  # random fills of one or two new triangles over the grid
        p = np.c_[rng.uniform(0, 7, (4, 2)), rng.uniform(-0.5, 0.5, 4)]
        t = np.array([[-1, -2, -3], [-2, -4, -3]])[: rng.integers(1, 3)]
        every = crossing_faces(np.vstack([v, p]), np.vstack([faces, np.where(t < 0, 63 - t, t)]),
                               len(faces))
        assert near.crosses(p, t, np.zeros(0, np.int64)) == bool(len(every))
