"""The synthetic range scanner of scripts/synth_views.py (benchmark inputs from new views)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))

import synth_views as sv  # noqa: E402

import asrbf_mesh as am  # noqa: E402


def _sphere(n: int = 40) -> am.Mesh:
    """A unit sphere (latitude-longitude mesh)."""
    th = np.linspace(0, np.pi, n)
    ph = np.linspace(0, 2 * np.pi, 2 * n, endpoint=False)
    t, p = np.meshgrid(th[1:-1], ph, indexing="ij")
    v = np.c_[np.sin(t).ravel() * np.cos(p).ravel(), np.sin(t).ravel() * np.sin(p).ravel(),
              np.cos(t).ravel()]
    v = np.vstack([[0, 0, 1], v, [0, 0, -1]])
    rows, cols = t.shape
    idx = 1 + np.arange(rows * cols).reshape(rows, cols)
    f = []
    for i in range(rows - 1):
        for j in range(cols):
            a, b = idx[i, j], idx[i, (j + 1) % cols]
            c, d = idx[i + 1, j], idx[i + 1, (j + 1) % cols]
            f += [[a, c, b], [b, c, d]]
    for j in range(cols):
        f += [[0, idx[0, j], idx[0, (j + 1) % cols]],
              [len(v) - 1, idx[-1, (j + 1) % cols], idx[-1, j]]]
    return am.Mesh(v, np.array(f, dtype=np.int64))


def test_the_zbuffer_keeps_the_nearest_surface() -> None:
    # a far square at z = 0 and a near triangle at z = 1 over part of it
    v = np.array([[0, 0, 0], [4, 0, 0], [4, 4, 0], [0, 4, 0],
                  [1, 1, 1], [3, 1, 1], [1, 3, 1]], dtype=np.float64)
    f = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6]], dtype=np.int64)
    zb, fid = sv._zbuffer(v, f, 0.0, 0.0, 0.5, 9, 9)
    assert np.isfinite(zb).all()
    assert zb[2, 2] == 1.0 and fid[2, 2] == 2  # (1, 1): under the triangle
    assert zb[8, 8] == 0.0 and fid[8, 8] in (0, 1)  # (4, 4): only the square


def test_a_view_of_a_sphere_lies_on_it_and_drops_grazing_pixels() -> None:
    sphere = _sphere()
    scan = sv.scan_view(sphere, np.eye(3), 0.05, 0.0, 0.3, 4.0, seed=0)
    r = np.linalg.norm(scan.points, axis=1)
    assert np.all(np.abs(r - 1) < 0.01)  # on the (faceted) sphere
    assert scan.points[:, 2].min() > 0  # the near half only, seen along -z
    # |n . view| >= 0.3: nothing beyond ~72.5 degrees from the view axis
    assert np.hypot(scan.points[:, 0], scan.points[:, 1]).max() < np.sqrt(1 - 0.28 ** 2)
    assert len(scan.faces) > 1.5 * scan.n_points


def test_the_laser_shadow_cuts_next_to_a_cliff() -> None:
    # a box standing on a plane: the laser beside the camera cannot reach part of the
    # plane next to the box, which the camera sees
    plane = np.array([[-3, -3, 0], [3, -3, 0], [3, 3, 0], [-3, 3, 0]], dtype=np.float64)
    box = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0],
                    [-1, -1, 2], [1, -1, 2], [1, 1, 2], [-1, 1, 2]], dtype=np.float64)
    quads = [[4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]]
    f = [[0, 1, 2], [0, 2, 3]]
    for a, b, c, d in quads:
        f += [[4 + a, 4 + b, 4 + c], [4 + a, 4 + c, 4 + d]]
    mesh = am.Mesh(np.vstack([plane, box]), np.array(f, dtype=np.int64))
    lit = sv.scan_view(mesh, np.eye(3), 0.1, 0.0, 0.2, 4.0, seed=0, shadow=30.0)
    dark = sv.scan_view(mesh, np.eye(3), 0.1, 0.0, 0.2, 4.0, seed=0, shadow=0.0)
    assert lit.n_points < dark.n_points
    gone = dark.points[~np.isin(dark.points.round(6).view("f8,f8,f8"),
                                lit.points.round(6).view("f8,f8,f8")).ravel()]
    assert len(gone) and np.all(gone[:, 2] < 1e-9)  # the shadow falls on the plane
    assert np.all(np.abs(gone[:, 0]) > 1 - 1e-9)  # beside the box, not under it


@pytest.mark.parametrize("axis, deg", [("y", 90.0), ("yx", (180.0, 35.0))])
def test_view_rotations_are_rotations(axis: str, deg) -> None:
    R = sv.view_rotation(axis, deg)
    assert np.allclose(R @ R.T, np.eye(3)) and np.isclose(np.linalg.det(R), 1.0)


def test_another_model_becomes_a_smooth_surface_of_the_extent_asked() -> None:
    import pymeshlab

    cube = Path(pymeshlab.__file__).parent / "tests" / "sample_meshes" / "cube.obj"
    if not cube.exists():  # pragma: no cover - a pymeshlab without its sample meshes
        pytest.skip("pymeshlab's sample meshes are not installed")
    ms = pymeshlab.MeshSet()
    ms.load_new_mesh(str(cube))
    n_faces = ms.current_mesh().face_number()
    s = sv.model_surface(cube, 0.2, subdivide=2)
    assert len(s.faces) == 16 * n_faces  # each loop subdivision splits a face in four
    assert np.isclose(np.ptp(s.vertices, axis=0).max(), 0.2)
    assert np.abs(s.vertices.mean(axis=0)).max() < 1e-9
    # subdivided, the cube rounds off: its vertices no longer all sit on its faces
    half = np.abs(s.vertices).max(axis=1)
    assert half.min() < 0.9 * half.max()


def test_the_second_view_set_repeats_no_view_or_name_of_the_first() -> None:
    for first, second in ((sv.VIEWS, sv.VIEWS_SECOND), (sv.MESH_VIEWS, sv.MESH_VIEWS_SECOND)):
        assert not set(first.values()) & set(second.values())
        assert not set(first) & set(second)
        for axis, deg in second.values():
            R = sv.view_rotation(axis, deg)
            assert np.allclose(R @ R.T, np.eye(3)) and np.isclose(np.linalg.det(R), 1.0)
