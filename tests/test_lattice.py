"""A depth frame's mesh recognised by its pixel lattice and filled on it (``_lattice``)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from asrbf_mesh import tasks
from asrbf_mesh._grid_fill import fill_grid
from asrbf_mesh._io import load_scan, save_mesh
from asrbf_mesh._lattice import find_lattice, frame_faces, lattice_grid, merge_fill
from asrbf_mesh._mesh import Mesh, Scan
from asrbf_mesh._range import RangeGrid

K = (300.0, 310.0, 41.5, 27.0)  # fx, fy, cx, cy


def _frame() -> tuple[RangeGrid, np.ndarray, np.ndarray]:
    """A tilted, curved wall at about 2 m with two enclosed voids and one open to the side."""
    H, W = 56, 84
    r, c = np.mgrid[:H, :W].astype(np.float64)
    truth = 2.0 + 0.003 * (c - 40) + 0.002 * (r - 28) + 0.05 * np.sin(c / 9.0) * np.cos(r / 7.0)
    voids = ((r - 20) ** 2 + (c - 25) ** 2 <= 16) | ((r - 35) ** 2 + (c - 60) ** 2 <= 9)
    side = (r - 28) ** 2 + (c - 83) ** 2 <= 16
    return RangeGrid(np.where(voids | side, np.nan, truth), "depth", intrinsics=K), truth, voids


def _opencv(scan: Scan, dtype: type = np.float64) -> Scan:
    """The same frame in OpenCV camera coordinates (+y down, +z forward)."""
    p = (scan.points * [1.0, -1.0, -1.0]).astype(dtype).astype(np.float64)
    return Scan(p, scan.faces[:, ::-1].copy())


def _edges(faces: np.ndarray) -> tuple[int, int, int]:
    """Boundary edges, edges of more than two triangles, directed edges used twice."""
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    key = int(faces.max()) + 1
    _, count = np.unique(np.sort(e, axis=1) @ [key, 1], return_counts=True)
    _, directed = np.unique(e @ [key, 1], return_counts=True)
    return int((count == 1).sum()), int((count > 2).sum()), int((directed > 1).sum())


@pytest.mark.parametrize("convention", ["opengl", "opencv", "opencv-float32"])
def test_lattice_found_in_either_camera_convention(convention: str) -> None:
    grid, _, _ = _frame()
    scan = grid.to_scan()
    if convention != "opengl":
        scan = _opencv(scan, np.float32 if convention.endswith("float32") else np.float64)
    lat = find_lattice(scan)
    assert lat is not None
    # the grid's bounding box: the void at the right border crops nothing (row 28 only)
    assert lat.shape == grid.shape
    fx, fy, cx, cy = lat.intrinsics
    assert np.allclose((fx, fy, cx, cy), K, rtol=1e-5, atol=1e-4)
    # row 0 is the image's top in both conventions: the grid comes back as it was
    back = lattice_grid(scan, lat)
    assert np.array_equal(np.isnan(back.z), np.isnan(grid.z))
    assert np.allclose(back.z, grid.z, rtol=1e-6, equal_nan=True)


def test_not_a_lattice() -> None:
    grid, _, _ = _frame()
    scan = grid.to_scan()
    p = scan.points.copy()
    p[100, 0] += 0.2 * p[100, 2] / K[0]  # one vertex a fifth of a pixel off its ray
    assert find_lattice(Scan(p, scan.faces)) is None
    p = scan.points.copy()
    p[7, 2] = -p[7, 2]  # a point behind the camera
    assert find_lattice(Scan(p, scan.faces)) is None
    f = scan.faces.copy()
    f[0, 0] = f[-1, 0]  # a triangle across the frame
    assert find_lattice(Scan(scan.points, f)) is None
    # an orthographic grid (a Stanford-like range grid): x, y on a lattice, z not constant
    r, c = np.mgrid[:30, :40].astype(np.float64)
    z = -(5.0 + np.sin(c / 5.0) + 0.1 * r)
    ortho = RangeGrid(z, "depth").to_scan()
    assert find_lattice(ortho) is None


def test_merge_keeps_the_scan_and_closes_the_enclosed_voids() -> None:
    grid, truth, voids = _frame()
    scan = grid.to_scan()
    lat = find_lattice(scan)
    res = fill_grid(lattice_grid(scan, lat), seed=0)
    assert np.array_equal(res.filled_mask, voids)
    mesh = merge_fill(scan, lat, res.z_filled, res.filled_mask)
    n = scan.n_points
    assert np.array_equal(mesh.vertices[:n], scan.points)
    assert np.array_equal(mesh.faces[:len(scan.faces)], scan.faces)
    assert np.array_equal(mesh.vertex_quality, np.r_[np.zeros(n), np.ones(int(voids.sum()))])
    # the new vertices are the filled cells' rays at the filled depths, close to the truth
    rr, cc = np.nonzero(voids)
    d = -mesh.vertices[n:, 2]
    assert np.allclose(mesh.vertices[n:, 0], (cc - K[2]) * d / K[0])
    assert np.allclose(mesh.vertices[n:, 1], -(rr - K[3]) * d / K[1])
    assert np.max(np.abs(d - truth[voids])) < 0.01
    # closed: only the outer border (with the side void) is left; manifold, one orientation
    outer = _edges(grid.to_scan().faces)[0]
    full = RangeGrid(np.where(np.isnan(grid.z) & ~voids, np.nan, truth), "depth",
                     intrinsics=K).to_scan()
    before, over, twice = _edges(mesh.faces)
    assert before == _edges(full.faces)[0] < outer
    assert over == 0 and twice == 0
    used = np.zeros(mesh.n_vertices, bool)
    used[mesh.faces] = True
    assert used[n:].all()


@pytest.mark.parametrize("defect", ["copies", "turned", "repeated"])
def test_merge_adds_the_same_triangles_to_a_frame_with_faulty_faces(defect: str) -> None:
    # the decisions see the faces mended (usable_faces): a copied face made its edges
    # look taken, and the new triangles there were dropped
    grid, _, _ = _frame()
    scan = grid.to_scan()
    lat = find_lattice(scan)
    res = fill_grid(lattice_grid(scan, lat), seed=0)
    clean = merge_fill(scan, lat, res.z_filled, res.filled_mask).faces[len(scan.faces):]
    f = scan.faces
    pick = np.random.default_rng(3).random(len(f)) < 0.2
    spoiled = {"copies": np.vstack([f, f[pick][:, [1, 2, 0]]]),
               "turned": np.where(pick[:, None], f[:, [0, 2, 1]], f),
               "repeated": np.vstack([f, f[pick][:, [0, 1, 0]]])}[defect]
    mesh = merge_fill(Scan(scan.points, spoiled), lat, res.z_filled, res.filled_mask)
    assert np.array_equal(mesh.faces[:len(spoiled)], spoiled)  # the input as it was
    np.testing.assert_array_equal(mesh.faces[len(spoiled):], clean)


def test_merge_completes_a_block_the_scan_half_covers() -> None:
    # one missing pixel inside a plane: its four blocks each hold the scan's triangle on
    # the other three corners, so only the filled corner's triangles are added
    H, W = 12, 14
    z = np.full((H, W), 1.5)
    z[6, 7] = np.nan
    grid = RangeGrid(z, "depth", intrinsics=(200.0, 200.0, 7.0, 6.0))
    scan = grid.to_scan()
    lat = find_lattice(scan)
    res = fill_grid(lattice_grid(scan, lat), seed=0)
    mesh = merge_fill(scan, lat, res.z_filled, res.filled_mask)
    added = mesh.faces[len(scan.faces):]
    assert len(added) == 4 and (added == scan.n_points).any(axis=1).all()
    boundary, over, twice = _edges(mesh.faces)
    assert boundary == 2 * (H - 1) + 2 * (W - 1) and over == 0 and twice == 0
    assert abs(mesh.vertices[-1, 2] + 1.5) < 1e-6


def test_cli_task_fills_a_frame_mesh_on_its_lattice(tmp_path: Path) -> None:
    grid, _, voids = _frame()
    src = tmp_path / "frame.ply"
    save_mesh(Mesh(*(lambda s: (s.points, s.faces))(_opencv(grid.to_scan(), np.float32))),
              src)
    before = src.read_bytes()
    d = tasks.fill_holes(src, tmp_path / "out.ply", progress=False)
    assert d["lattice"]["rows"] == grid.shape[0] and d["cells_filled"] == int(voids.sum())
    assert d["vertices_added"] == int(voids.sum()) and d["faces_added"] > 0
    json.dumps(d)
    out = load_scan(tmp_path / "out.ply")
    assert out.n_points == load_scan(src).n_points + int(voids.sum())
    assert src.read_bytes() == before
    # --as-mesh, or a mesh-fill option, takes the mesh path
    for kw in ({"lattice": False}, {"blend": "harmonic"}):
        m = tasks.fill_holes(src, tmp_path / "mesh.ply", progress=False, **kw)
        assert "lattice" not in m and "holes_skipped" in m


def test_a_new_triangle_on_an_edge_with_two_triangles_is_dropped() -> None:
    from asrbf_mesh._lattice import _manifold

    faces = np.array([[0, 1, 2], [1, 0, 3]])  # edge 0-1 has two triangles
    tris = np.array([[0, 1, 4], [2, 1, 5], [5, 1, 4]])
    assert np.array_equal(_manifold(tris, faces), tris[1:])
    assert np.array_equal(_manifold(tris[1:], faces), tris[1:])


def test_cli_says_it_read_a_frame(capsys, tmp_path: Path) -> None:
    from asrbf_mesh.cli import main

    grid, _, voids = _frame()
    src = tmp_path / "frame.ply"
    s = grid.to_scan()
    save_mesh(Mesh(s.points, s.faces), src)
    assert main(["fill-holes", str(src), "-o", str(tmp_path / "out.ply")]) == 0
    out = capsys.readouterr().out
    assert "84 x 56 pixel lattice (fx 300, fy 310)" in out
    assert f"{int(voids.sum())} cells filled (+{int(voids.sum())} vertices" in out


def test_far_off_vertices_are_no_lattice() -> None:
    grid, _, _ = _frame()
    scan = grid.to_scan()
    p = scan.points.copy()
    p[5, 0] = 1e30 * p[5, 2]  # one ray at an absurd angle: no grid of 1e33 columns
    assert find_lattice(Scan(p, scan.faces)) is None


@pytest.mark.parametrize("convention", ["opengl", "opencv-float32"])
def test_a_bare_point_cloud_of_a_frame_is_found_and_meshed_as_its_depth_image(
        convention: str) -> None:
    grid, _, _ = _frame()
    scan = grid.to_scan()
    if convention != "opengl":
        scan = _opencv(scan, np.float32)
    cloud = Scan(scan.points)
    lat = find_lattice(cloud)
    assert lat is not None and lat.shape == grid.shape
    assert np.allclose(lat.intrinsics, K, rtol=1e-5, atol=1e-4)
    # the same triangles as the frame's own mesh (each as a set of corners)
    key = lambda f: np.unique(np.sort(f, axis=1), axis=0)  # noqa: E731
    assert np.array_equal(key(frame_faces(cloud, lat)), key(scan.faces))


def test_bare_clouds_that_are_no_frame() -> None:
    grid, _, _ = _frame()
    p = grid.to_scan().points
    q = p.copy()
    q[100, 0] += 0.2 * q[100, 2] / K[0]  # one point a fifth of a pixel off its ray
    assert find_lattice(Scan(q)) is None
    assert find_lattice(Scan(np.vstack([p, p[:1]]))) is None  # two points on one pixel
    r, c = np.mgrid[:30, :40].astype(np.float64)  # an orthographic grid
    ortho = np.column_stack([c.ravel(), r.ravel(), -(5.0 + np.sin(c / 5.0) + 0.1 * r).ravel()])
    assert find_lattice(Scan(ortho)) is None
    rng = np.random.default_rng(0)
    for n in (16, 17, 200, 5000):  # random clouds in front of a camera, some flat
        cloud = rng.normal(size=(n, 3)) + [0.0, 0.0, 6.0]
        assert find_lattice(Scan(cloud)) is None
        cloud[:, 0] = 1.0  # every point on one column ray... of varying depth
        assert find_lattice(Scan(cloud)) is None
    line = np.column_stack([np.arange(40.0), np.zeros(40), np.full(40, -3.0)])  # one row
    assert find_lattice(Scan(line)) is None


@pytest.mark.parametrize("suffix", [".xyz", ".ply"])
def test_cli_task_fills_a_frame_point_cloud_on_its_lattice(tmp_path: Path,
                                                          suffix: str) -> None:
    grid, _, voids = _frame()
    frame = _opencv(grid.to_scan(), np.float32)
    src = tmp_path / f"frame{suffix}"
    if suffix == ".xyz":
        np.savetxt(src, frame.points, fmt="%.9g")
    else:
        save_mesh(Mesh(frame.points, np.zeros((0, 3), np.int64)), src)
    before = src.read_bytes()
    d = tasks.fill_holes(src, tmp_path / "out.ply", progress=False)
    assert d["lattice"]["points_only"] and d["cells_filled"] == int(voids.sum())
    assert d["lattice"]["scan_faces"] == len(frame.faces)
    assert d["vertices_added"] == int(voids.sum()) and d["faces_added"] > 0
    out = load_scan(tmp_path / "out.ply")
    n = frame.n_points
    assert out.n_points == n + int(voids.sum())
    assert np.allclose(out.points[:n], frame.points, atol=1e-6)
    assert len(out.faces) == len(frame.faces) + d["faces_added"]
    boundary, over, twice = _edges(out.faces)
    assert over == 0 and twice == 0
    assert src.read_bytes() == before
    m = tasks.fill_holes(src, tmp_path / "mesh.ply", progress=False, lattice=False)
    assert "lattice" not in m and "holes_skipped" in m


def test_a_lattice_cloud_with_no_triangle_of_its_own_takes_the_mesh_path(tmp_path: Path) -> None:
    """Every other pixel of a frame (a checkerboard): on a lattice, but no 2 x 2 block has
    three points, so no triangle: the cloud is filled as any cloud (was a traceback)."""
    r, c = np.mgrid[:20, :30].astype(np.float64)
    keep = (r + c) % 2 == 0
    d = 2.0 + 0.01 * c
    p = np.column_stack([((c - 15) / 100.0 * d)[keep], ((r - 10) / 100.0 * d)[keep],
                         -d[keep]])
    assert find_lattice(Scan(p)) is None
    src = tmp_path / "checker.xyz"
    np.savetxt(src, p, fmt="%.9g")
    d = tasks.fill_holes(src, tmp_path / "out.ply", progress=False)
    assert "lattice" not in d and (tmp_path / "out.ply").exists()
