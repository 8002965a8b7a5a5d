"""Tests of asrbf_mesh._io: Scan, load_scan, save_mesh, face_map_path.

``tests/data/bun000_crop.ply`` is a 60 x 50 crop (grid rows 30-89, cols 100-149) of
the Stanford bunny range scan ``bun000.ply`` (Stanford 3D Scanning Repository,
Stanford University Computer Graphics Laboratory), written as ASCII PLY with the
original header style; its vertices are the ones the crop references, renumbered in
their original order. The full scans ($ASRBF_BUNNY_DIR) are optional.
"""

from __future__ import annotations

import os
from pathlib import Path

import _grids
import numpy as np
import plyfile
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from asrbf_mesh import _io as scan_io
from asrbf_mesh import _readers, _writers
from asrbf_mesh._io import (
    SUPPORTED_MESH_FORMATS,
    SUPPORTED_SCAN_FORMATS,
    Scan,
    face_map_path,
    load_scan,
    save_mesh,
)
from asrbf_mesh._mesh import Mesh
from asrbf_mesh.errors import AsrbfError, ConfigError, ScanError

DATA = Path(__file__).parent / "data"
CROP = DATA / "bun000_crop.ply"
BUNNY_DIR = Path(os.environ.get("ASRBF_BUNNY_DIR") or "/nonexistent")


# ----------------------------------------------------------------------------- fixtures


def grid_points(nx: int = 4, ny: int = 3, z: float | None = None) -> np.ndarray:
    """Points of a small wavy height field, row by row."""
    x, y = np.meshgrid(np.arange(nx, dtype=float), np.arange(ny, dtype=float))
    zz = 0.1 * np.sin(x) * np.cos(y) if z is None else np.full_like(x, z)
    return np.column_stack([x.ravel(), y.ravel(), zz.ravel()])


def grid_faces(nx: int = 4, ny: int = 3) -> np.ndarray:
    """Counter-clockwise (seen from +z) triangles of :func:`grid_points`."""
    return _grids.grid_faces(nx, ny)


@pytest.fixture
def mesh() -> Mesh:
    v = grid_points()
    n = np.tile([0.0, 0.0, 1.0], (len(v), 1))
    return Mesh(v, grid_faces(), vertex_normals=n, vertex_quality=np.linspace(0, 1, len(v)))


def write_ply(path: Path, vertex: np.ndarray, faces=None, *, text: bool, extra=()) -> Path:
    """Write a PLY file with plyfile; ``faces`` is a list of index lists or None."""
    elements = [plyfile.PlyElement.describe(vertex, "vertex")]
    if faces is not None:
        fa = np.empty(len(faces), dtype=[("vertex_indices", "O")])
        fa["vertex_indices"] = [np.asarray(f, dtype=np.int32) for f in faces]
        elements.append(plyfile.PlyElement.describe(fa, "face"))
    elements.extend(extra)
    plyfile.PlyData(elements, text=text).write(str(path))
    return path


def xyz_struct(points: np.ndarray, dtype: str = "f4") -> np.ndarray:
    arr = np.empty(len(points), dtype=[("x", dtype), ("y", dtype), ("z", dtype)])
    for i, c in enumerate("xyz"):
        arr[c] = points[:, i]
    return arr


def face_normal_sum(points: np.ndarray, faces: np.ndarray) -> np.ndarray:
    p = points[faces]
    return np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]).sum(axis=0)


def triangles(points: np.ndarray, faces: np.ndarray) -> np.ndarray:
    return points[faces]


def assert_single_line(exc: pytest.ExceptionInfo, path: Path) -> None:
    msg = str(exc.value)
    assert "\n" not in msg
    assert msg.startswith(str(path))


# ----------------------------------------------------------------------------- Scan


def test_scan_converts_and_freezes() -> None:
    pts = np.asfortranarray(grid_points().astype(np.float32))
    faces = grid_faces().astype(np.int32)
    scan = Scan(pts, faces, source=Path("a/b.ply"), grid_shape=[3, 4])
    assert scan.points.dtype == np.float64 and scan.points.flags.c_contiguous
    assert scan.faces.dtype == np.int64 and scan.faces.shape == (12, 3)
    assert not scan.points.flags.writeable and not scan.faces.flags.writeable
    assert scan.source == str(Path("a/b.ply"))
    assert scan.grid_shape == (3, 4)
    assert scan.n_points == 12 and scan.n_faces == 12
    assert scan.bbox_diagonal == pytest.approx(np.linalg.norm(np.ptp(pts, axis=0)))
    assert "n_points=12" in repr(scan)
    with pytest.raises(AttributeError):
        scan.points = pts  # frozen dataclass


def test_scan_does_not_freeze_callers_arrays() -> None:
    pts = grid_points()
    faces = grid_faces()
    scan = Scan(pts, faces)
    assert pts.flags.writeable and faces.flags.writeable
    pts[0, 0] = 99.0
    assert scan.points[0, 0] == 0.0
    # A read-only float64 array is shared, not copied.
    again = Scan(scan.points, scan.faces)
    assert again.points is scan.points


def test_scan_empty_faces_become_none() -> None:
    assert Scan(grid_points(), np.empty((0, 3), dtype=int)).faces is None
    assert Scan(grid_points(), []).faces is None


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"points": np.zeros((4, 2))}, r"^points must be an \(N, 3\) array, got shape \(4, 2\)"),
        ({"points": [[0, 0, np.nan]]}, "^points contain NaN or infinite"),
        ({"points": [["a", "b", "c"]]}, "real numbers"),
        (
            {"points": np.zeros((4, 3)), "faces": [[0, 1, 4]]},
            r"1 face indexes points outside \[0, 4\)",
        ),
        ({"points": np.zeros((4, 3)), "faces": [[0, -1, 2]]}, "outside"),
        ({"points": np.zeros((4, 3)), "faces": [[0.0, 1.0, 2.0]]}, "integers"),
        ({"points": np.zeros((4, 3)), "faces": [[0, 1, 2, 3]]}, r"shape \(F, 3\)"),
        ({"points": np.zeros((4, 3)), "grid_shape": (0, 3)}, "positive"),
        ({"points": np.zeros((4, 3)), "grid_shape": (1, 2, 3)}, "rows, cols"),
    ],
)
def test_scan_validation(kwargs, match) -> None:
    with pytest.raises(ScanError, match=match):
        Scan(**kwargs)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"vertices": np.zeros((4, 2))},
         r"^vertices must be an \(N, 3\) array, got shape \(4, 2\)$"),
        ({"vertices": [[0, 0, np.inf]] * 3}, "^vertices contain NaN or infinite"),
        ({"faces": [[0, 1, 9]]}, r"^faces index vertices outside \[0, 4\)$"),
        ({"faces": [[0, 1, 2, 3]] * 3}, r"^faces must be an \(F, 3\) array, got shape \(3, 4\)$"),
        ({"faces": [["a", "b", "c"]]}, r"^faces must be an \(F, 3\) array of integers"),
        ({"vertex_normals": np.zeros((3, 3))}, r"^vertex_normals must have shape \(4, 3\)"),
        ({"vertex_quality": np.zeros(5)}, r"^vertex_quality must have shape \(4,\)"),
    ],
)
def test_mesh_validation_raises_scan_errors_naming_the_field(kwargs, match) -> None:
    # these were ValueErrors; a bad mesh is bad data: ScanError, one line
    args = {"vertices": np.zeros((4, 3)), "faces": [[0, 1, 2]]} | kwargs
    with pytest.raises(ScanError, match=match) as info:
        Mesh(**args)
    assert "\n" not in str(info.value)
    assert Mesh(np.zeros((4, 3)), []).n_faces == 0


def test_scan_error_names_source() -> None:
    with pytest.raises(ScanError, match=r"^x\.ply: 1 face indexes"):
        Scan(np.zeros((3, 3)), [[0, 1, 3]], source="x.ply")


def test_scan_to_mesh() -> None:
    scan = Scan(grid_points(), grid_faces())
    m = scan.to_mesh()
    assert isinstance(m, Mesh)
    np.testing.assert_array_equal(m.vertices, scan.points)
    np.testing.assert_array_equal(m.faces, scan.faces)
    with pytest.raises(ScanError, match="cloud.ply: the scan has no faces"):
        Scan(grid_points(), source="cloud.ply").to_mesh()


# ----------------------------------------------------------------------------- PLY loading


@pytest.mark.parametrize("text", [True, False])
@pytest.mark.parametrize("dtype", ["f4", "f8", "i4", "u1"])
def test_load_ply_vertex_types_and_faces(tmp_path, text, dtype) -> None:
    pts = grid_points(z=0.0) if dtype[0] in "iu" else grid_points()
    path = write_ply(tmp_path / "m.ply", xyz_struct(pts, dtype), grid_faces(), text=text)
    scan = load_scan(path)
    np.testing.assert_allclose(scan.points, pts, atol=1e-6)
    np.testing.assert_array_equal(scan.faces, grid_faces())
    assert scan.source == str(path) and scan.grid_shape is None


@pytest.mark.parametrize("text", [True, False])
def test_load_ply_polygons_are_fanned_in_order(tmp_path, text) -> None:
    pts = grid_points()
    polys = [[0, 1, 5, 4], [1, 2, 6], [2, 3, 7, 11, 10, 6]]
    scan = load_scan(write_ply(tmp_path / "p.ply", xyz_struct(pts), polys, text=text))
    expected = [[0, 1, 5], [0, 5, 4], [1, 2, 6], [2, 3, 7], [2, 7, 11], [2, 11, 10], [2, 10, 6]]
    np.testing.assert_array_equal(scan.faces, expected)


def test_load_ply_vertex_index_name_extra_properties_unused_vertices(tmp_path) -> None:
    pts = grid_points()
    vert = np.empty(len(pts), dtype=[("x", "f4"), ("y", "f4"), ("z", "f4"), ("flags", "i4")])
    for i, c in enumerate("xyz"):
        vert[c] = pts[:, i]
    fa = np.zeros(2, dtype=[("vertex_index", "i4", (3,)), ("quality", "f4")])
    fa["vertex_index"] = [[0, 1, 5], [0, 5, 4]]
    cam = np.zeros(1, dtype=[("view_px", "f4"), ("viewportx", "i4")])
    elements = [
        plyfile.PlyElement.describe(cam, "camera"),
        plyfile.PlyElement.describe(vert, "vertex"),
        plyfile.PlyElement.describe(fa, "face"),
    ]
    path = tmp_path / "v.ply"
    plyfile.PlyData(elements).write(str(path))
    scan = load_scan(path)
    assert scan.n_points == 12  # unused vertices are kept
    np.testing.assert_array_equal(scan.faces, [[0, 1, 5], [0, 5, 4]])


def test_load_ply_point_cloud(tmp_path) -> None:
    scan = load_scan(write_ply(tmp_path / "c.ply", xyz_struct(grid_points()), text=False))
    assert scan.faces is None and scan.n_points == 12


def test_face_map_loads_with_faces() -> None:
    try:
        path = face_map_path()
    except ScanError as exc:  # pragma: no cover - depends on the pymeshlab wheel
        pytest.skip(str(exc))
    assert path.name == "face000.ply" and path.is_file()
    scan = load_scan(path)
    assert scan.n_points == 85_849
    assert scan.n_faces == 166_259
    assert scan.grid_shape is None
    assert face_normal_sum(scan.points, scan.faces)[2] > 0


def test_face_map_path_without_pymeshlab(monkeypatch) -> None:
    monkeypatch.setattr(scan_io.importlib.util, "find_spec", lambda name: None)
    with pytest.raises(ScanError, match="pymeshlab is not installed"):
        face_map_path()


# ----------------------------------------------------------------------------- range grids


def write_range_grid(path: Path, pts: np.ndarray, cells: np.ndarray, *, binary=False) -> Path:
    """Write a Stanford-style range-grid PLY; ``cells`` is (rows, cols), -1 = empty."""
    rows, cols = cells.shape
    if binary:
        grid = np.empty(rows * cols, dtype=[("vertex_indices", "O")])
        grid["vertex_indices"] = [
            np.array([c] if c >= 0 else [], dtype=np.int32) for c in cells.ravel()
        ]
        el = [
            plyfile.PlyElement.describe(xyz_struct(pts), "vertex"),
            plyfile.PlyElement.describe(grid, "range_grid"),
        ]
        info = [f"num_cols {cols}", f"num_rows {rows}"]
        plyfile.PlyData(el, text=False, obj_info=info).write(str(path))
        return path
    lines = [
        "ply",
        "format ascii 1.0",
        "obj_info is_cyberware_data 1",
        f"obj_info num_cols {cols}",
        f"obj_info num_rows {rows}",
        f"element vertex {len(pts)}",
        "property float x",
        "property float y",
        "property float z",
        f"element range_grid {rows * cols}",
        "property list uchar int vertex_indices",
        "end_header",
    ]
    lines += [f"{x:.9g} {y:.9g} {z:.9g} " for x, y, z in pts]
    lines += ["0" if c < 0 else f"1 {c}" for c in cells.ravel()]
    path.write_text("\n".join(lines) + "\n")
    return path


def scanner_grid(rows: int, cols: int, missing=()) -> tuple[np.ndarray, np.ndarray]:
    """A range grid laid out like the bunny scans: column -> +x, row -> +y."""
    cells = np.full((rows, cols), -1)
    pts = []
    for r in range(rows):
        for c in range(cols):
            if (r, c) in missing:
                continue
            cells[r, c] = len(pts)
            pts.append((c * 1.0, r * 1.0, 0.05 * ((r * 7 + c * 3) % 5)))
    return np.array(pts), cells


@pytest.mark.parametrize("binary", [False, True])
def test_range_grid_small_exact(tmp_path, binary) -> None:
    # 3 x 3 samples, (0, 0) missing: block (0,0) has 3 samples -> 1 triangle,
    # the other three blocks have 4 -> 2 each.
    pts, cells = scanner_grid(3, 3, missing={(0, 0)})
    scan = load_scan(write_range_grid(tmp_path / "g.ply", pts, cells, binary=binary), min_points=3)
    assert scan.grid_shape == (3, 3)
    assert scan.n_faces == 1 + 3 * 2
    # the lone triangle of block (0,0), with MeshLab's winding: (0,1) -> (1,1) -> (1,0)
    first = scan.faces[0].tolist()
    expected = [int(cells[0, 1]), int(cells[1, 1]), int(cells[1, 0])]
    assert first in (expected, expected[1:] + expected[:1], expected[2:] + expected[:2])
    # every triangle faces +z (the scanner)
    p = scan.points[scan.faces]
    nz = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])[:, 2]
    assert (nz > 0).all()


def test_face_element_wins_over_range_grid(tmp_path) -> None:
    pts, cells = scanner_grid(3, 4)
    grid = np.empty(cells.size, dtype=[("vertex_indices", "O")])
    grid["vertex_indices"] = [np.array([c], dtype=np.int32) for c in cells.ravel()]
    fa = np.empty(1, dtype=[("vertex_indices", "O")])
    fa["vertex_indices"] = [np.array([0, 1, 5], dtype=np.int32)]
    elements = [
        plyfile.PlyElement.describe(xyz_struct(pts), "vertex"),
        plyfile.PlyElement.describe(fa, "face"),
        plyfile.PlyElement.describe(grid, "range_grid"),
    ]
    path = tmp_path / "both.ply"
    plyfile.PlyData(elements, obj_info=["num_cols 4", "num_rows 3"]).write(str(path))
    scan = load_scan(path)
    np.testing.assert_array_equal(scan.faces, [[0, 1, 5]])
    assert scan.grid_shape == (3, 4)


def test_range_grid_mirrored_grid_is_flipped_to_face_plus_z(tmp_path) -> None:
    pts, cells = scanner_grid(4, 5)
    pts[:, 1] *= -1  # rows now go to -y: MeshLab's winding would face -z
    scan = load_scan(write_range_grid(tmp_path / "m.ply", pts, cells))
    p = scan.points[scan.faces]
    assert (np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])[:, 2] > 0).all()


def test_range_grid_splits_along_shorter_diagonal(tmp_path) -> None:
    # one 2x2 block; lifting (0,0) makes the (0,0)-(1,1) diagonal the long one.
    pts = np.array([[0, 0, 5.0], [1, 0, 0], [0, 1, 0], [1, 1, 0]])
    cells = np.arange(4).reshape(2, 2)
    scan = load_scan(write_range_grid(tmp_path / "d.ply", pts, cells), min_points=4)
    edges = {
        tuple(sorted(e)) for f in scan.faces for e in ((f[0], f[1]), (f[1], f[2]), (f[0], f[2]))
    }
    assert (1, 2) in edges and (0, 3) not in edges
    pts[:, 2] = [0.0, 5.0, 0.0, 0.0]  # now lift (0,1): the other diagonal is long
    scan = load_scan(write_range_grid(tmp_path / "e.ply", pts, cells), min_points=4)
    edges = {
        tuple(sorted(e)) for f in scan.faces for e in ((f[0], f[1]), (f[1], f[2]), (f[0], f[2]))
    }
    assert (0, 3) in edges and (1, 2) not in edges


def brute_force_grid(path: Path) -> tuple[np.ndarray, int, int]:
    """Cells of an ASCII range-grid PLY and its expected face count, by plain loops."""
    lines = path.read_text().splitlines()
    rows = int(next(ln.split()[2] for ln in lines if ln.startswith("obj_info num_rows")))
    cols = int(next(ln.split()[2] for ln in lines if ln.startswith("obj_info num_cols")))
    nv = int(next(ln.split()[2] for ln in lines if ln.startswith("element vertex")))
    start = lines.index("end_header") + 1 + nv
    cells = np.full((rows, cols), -1)
    for k, ln in enumerate(lines[start : start + rows * cols]):
        parts = ln.split()
        if parts[0] == "1":
            cells[k // cols, k % cols] = int(parts[1])
    count = 0
    for r in range(rows - 1):
        for c in range(cols - 1):
            n = sum(cells[r + i, c + j] >= 0 for i in (0, 1) for j in (0, 1))
            count += {4: 2, 3: 1}.get(n, 0)
    return cells, count, nv


def test_range_grid_crop_of_bunny() -> None:
    cells, expected, nv = brute_force_grid(CROP)
    scan = load_scan(CROP)
    assert CROP.stat().st_size < 200_000
    assert scan.grid_shape == (60, 50)
    assert scan.n_points == nv == 1986
    assert scan.n_faces == expected == 3721
    # each triangle uses cells of one 2x2 block and is counter-clockwise seen from
    # the scanner (+z); the bunny's grid has col -> +x and row -> +y, so in grid
    # coordinates (col, row) every triangle turns counter-clockwise
    where = {int(v): (r, c) for (r, c), v in np.ndenumerate(cells) if v >= 0}
    rc = np.array([[where[int(v)] for v in f] for f in scan.faces], dtype=float)
    assert (np.ptp(rc, axis=1) <= 1).all()
    u, w = rc[:, 1] - rc[:, 0], rc[:, 2] - rc[:, 0]
    turn = u[:, 1] * w[:, 0] - u[:, 0] * w[:, 1]
    assert (turn > 0).all()
    n = face_normal_sum(scan.points, scan.faces)
    assert n[2] / np.linalg.norm(n) > 0.5
    # quads are split along their shorter diagonal (both triangles share it)
    p = scan.points
    edge_use: dict[tuple[int, int], int] = {}
    for f in scan.faces.tolist():
        for e in ((f[0], f[1]), (f[1], f[2]), (f[2], f[0])):
            key = (min(e), max(e))
            edge_use[key] = edge_use.get(key, 0) + 1
    n_quads = 0
    for r in range(59):
        for c in range(49):
            q = cells[r : r + 2, c : c + 2]
            if (q >= 0).all():
                n_quads += 1
                d03 = np.linalg.norm(p[q[0, 0]] - p[q[1, 1]])
                d12 = np.linalg.norm(p[q[0, 1]] - p[q[1, 0]])
                assert d03 != d12
                short, long = ((q[0, 0], q[1, 1]), (q[0, 1], q[1, 0]))[:: 1 if d03 < d12 else -1]
                assert edge_use.get((min(short), max(short))) == 2
                assert (min(long), max(long)) not in edge_use
    assert n_quads == 1837


def test_range_grid_crop_matches_pymeshlab_face_count() -> None:
    pymeshlab = pytest.importorskip("pymeshlab")
    ms = pymeshlab.MeshSet()
    ms.load_new_mesh(str(CROP))
    m = ms.current_mesh()
    scan = load_scan(CROP)
    assert scan.n_faces == m.face_number()
    np.testing.assert_allclose(scan.points, m.vertex_matrix(), rtol=0, atol=1e-7)


@pytest.mark.skipif(not (BUNNY_DIR / "bun000.ply").is_file(), reason="Stanford bunny data absent")
def test_full_bunny_scan_if_available() -> None:  # pragma: no cover - optional data
    scan = load_scan(BUNNY_DIR / "bun000.ply")
    assert scan.grid_shape == (400, 512)
    assert scan.n_points == 40_256
    assert scan.n_faces == 79_312  # pymeshlab's count
    assert face_normal_sum(scan.points, scan.faces)[2] > 0


# ----------------------------------------------------------------------------- other formats


def test_load_obj(tmp_path) -> None:
    text = """# a comment
mtllib x.mtl
v 0 0 0
v 1 0 0 1.0
v 1 1 0.5 0.2 0.3 0.4
vt 0 0
vn 0 0 1
  v 0 1 0
o thing
f 1/1/1 2/1/1 3/1/1
f -4//1 -2//1 -1//1
v 2 0 0
v 2 1 0
f 2 5 6 3
v 9 9 9
l 1 2
"""
    path = tmp_path / "m.obj"
    path.write_text(text)
    scan = load_scan(path, min_points=3)
    assert scan.n_points == 7  # the unused last vertex is kept
    np.testing.assert_allclose(scan.points[2], [1, 1, 0.5])
    np.testing.assert_array_equal(scan.faces, [[0, 1, 2], [0, 2, 3], [1, 4, 5], [1, 5, 2]])


def test_load_obj_without_faces(tmp_path) -> None:
    path = tmp_path / "p.obj"
    path.write_text("".join(f"v {x} {y} {z}\n" for x, y, z in grid_points()))
    scan = load_scan(path)
    assert scan.faces is None and scan.n_points == 12


@pytest.mark.parametrize(
    ("body", "match"),
    [
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n", "index 0"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n", r"1 face references vertices outside \[0, 3\)"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 -4\n", "outside"),
        ("v 0 0\n", "line 1: a vertex needs 3 coordinates"),
        ("v 0 0 zero\n", "bad vertex coordinate"),
        ("v 0 0 0\nv 1 0 0\nf 1 x 2\n", "bad face index 'x'"),
        ("v 0 0 0\nv 1 0 0\nf 1 2\n", "at least 3"),
    ],
)
def test_load_obj_errors(tmp_path, body, match) -> None:
    path = tmp_path / "bad.obj"
    path.write_text(body)
    with pytest.raises(ScanError, match=match) as exc:
        load_scan(path, min_points=2)
    assert_single_line(exc, path)


def test_load_off_variants(tmp_path) -> None:
    plain = (
        "OFF\n# comment\n5 3 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0.5\n2 2 2\n3 0 1 2\n4 0 2 3 1\n3 1 2 3\n"
    )
    p = tmp_path / "a.off"
    p.write_text(plain)
    scan = load_scan(p, min_points=3)
    assert scan.n_points == 5
    np.testing.assert_array_equal(scan.faces, [[0, 1, 2], [0, 2, 3], [0, 3, 1], [1, 2, 3]])

    coff = (
        "COFF 4 2 0  # counts on the keyword line\n"
        "0 0 0 255 0 0 255\n1 0 0 0 255 0 255\n1 1 0 0 0 255 255\n0 1 1 9 9 9 255\n"
        "3 0 1 2 0.5 0.5 0.5\n3 0 2 3 1 1 1\n"
    )
    p = tmp_path / "c.off"
    p.write_text(coff)
    scan = load_scan(p, min_points=3)
    np.testing.assert_allclose(scan.points[3], [0, 1, 1])
    np.testing.assert_array_equal(scan.faces, [[0, 1, 2], [0, 2, 3]])

    noff = (
        "NOFF\n4 2 5\n0 0 0 0 0 1\n1 0 0 0 0 1\n1 1 0 0 0 1\n0 1 0 0 0 1\n3 0 1 2\n3 0 2 3 7 7 7\n"
    )
    p = tmp_path / "n.off"
    p.write_text(noff)
    scan = load_scan(p, min_points=3)
    np.testing.assert_array_equal(scan.faces, [[0, 1, 2], [0, 2, 3]])


@pytest.mark.parametrize(
    ("body", "match"),
    [
        ("OFF\n4 1 0\n0 0 0\n1 0 0\n1 1 0\n", "announces 4 vertices but the file has 3"),
        ("OFF\n3 2 0\n0 0 0\n1 0 0\n1 1 0\n3 0 1 2\n", "announces 2 faces but the file has 1"),
        ("OFF\n3 1 0\n0 0 0\n1 0 0\n1 1 0\n3 0 1 3\n", "outside"),
        ("PLY\n3 1 0\n", "expected an OFF keyword"),
        ("4OFF\n3 1 0\n", "expected an OFF keyword"),
        ("OFF\nthree 1 0\n", "bad counts"),
        ("OFF BINARY\n", "binary OFF"),
    ],
)
def test_load_off_errors(tmp_path, body, match) -> None:
    path = tmp_path / "bad.off"
    path.write_text(body)
    with pytest.raises(ScanError, match=match) as exc:
        load_scan(path, min_points=2)
    assert_single_line(exc, path)


def stl_ascii(tris: np.ndarray) -> str:
    out = ["solid test"]
    for t in tris:
        out += ["  facet normal 0 0 1", "    outer loop"]
        out += [f"      vertex {x:.9g} {y:.9g} {z:.9g}" for x, y, z in t]
        out += ["    endloop", "  endfacet"]
    return "\n".join(out + ["endsolid test", ""])


def test_load_stl_ascii_and_binary_merge_vertices(tmp_path) -> None:
    pts, faces = grid_points(), grid_faces()
    tris = pts[faces]
    a = tmp_path / "a.stl"
    a.write_text(stl_ascii(tris))
    rec = np.zeros(len(faces), dtype=[("n", "<f4", (3,)), ("v", "<f4", (3, 3)), ("a", "<u2")])
    rec["v"] = tris
    b = tmp_path / "b.stl"
    # a binary STL whose header starts with "solid" (common) must still be read as binary
    b.write_bytes(
        b"solid but binary".ljust(80, b"\0") + np.uint32(len(faces)).tobytes() + rec.tobytes()
    )
    for path in (a, b):
        scan = load_scan(path)
        assert scan.n_points == 12  # shared corners merged
        assert scan.n_faces == len(faces)
        np.testing.assert_allclose(scan.points[scan.faces], tris.astype(np.float32), atol=1e-6)
        # vertices appear in order of first use
        assert scan.faces[0].tolist() == [0, 1, 2]


def test_load_stl_errors(tmp_path) -> None:
    path = tmp_path / "t.stl"
    path.write_bytes(b"\x01" * 80 + np.uint32(5).tobytes() + b"\0" * 100)  # 5 triangles, 2 stored
    with pytest.raises(ScanError, match=r"t\.stl: cannot read STL: .*5 triangles = 334 bytes"):
        load_scan(path)
    path.write_text("solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\n")
    with pytest.raises(ScanError, match="not a multiple of 3"):
        load_scan(path)


@pytest.mark.parametrize("ext", [".xyz", ".pts", ".txt"])
def test_load_point_lists(tmp_path, ext) -> None:
    pts = grid_points()
    variants = {
        "space": "\n".join(f"{x} {y}\t{z}" for x, y, z in pts),
        "comma": "\n".join(f"{x},{y}, {z}" for x, y, z in pts),
        "extra columns and comments": "# header\n"
        + "\n".join(f"{x} {y} {z} 0.5 255 0 0" for x, y, z in pts)
        + "\n# done\n",
        "count line": f"{len(pts)}\n" + "\n".join(f"{x} {y} {z} 7" for x, y, z in pts),
        "comment then count": f"# pts\n\n{len(pts)}\n"
        + "\n".join(f"{x} {y} {z}" for x, y, z in pts),
    }
    for name, text in variants.items():
        path = tmp_path / f"p{ext}"
        path.write_text(text)
        scan = load_scan(path)
        np.testing.assert_allclose(scan.points, pts, err_msg=name)
        assert scan.faces is None


def test_load_point_list_errors(tmp_path) -> None:
    path = tmp_path / "p.xyz"
    path.write_text("x y z\n1 2 3\n")
    with pytest.raises(ScanError, match=r"p\.xyz: cannot read XYZ: ") as exc:
        load_scan(path)
    assert_single_line(exc, path)
    path.write_text("1 2\n3 4\n")
    with pytest.raises(ScanError, match="cannot read XYZ"):
        load_scan(path)
    path.write_text("# only comments\n\n")
    with pytest.raises(ScanError, match=r"only 0 points, at least 10 needed"):
        load_scan(path)


def test_load_npy(tmp_path) -> None:
    pts = grid_points()
    path = tmp_path / "p.npy"
    np.save(path, pts)
    np.testing.assert_array_equal(load_scan(path).points, pts)
    np.save(path, pts.astype(np.float32))
    np.testing.assert_allclose(load_scan(path).points, pts)
    np.save(path, np.asfortranarray(pts))
    np.testing.assert_array_equal(load_scan(path).points, pts)
    np.save(path, np.rint(pts * 10).astype(np.int16))
    np.testing.assert_array_equal(load_scan(path).points, np.rint(pts * 10))


@pytest.mark.parametrize(
    ("array", "match"),
    [
        (np.zeros(30), r"shape \(30,\)"),
        (np.zeros((10, 2)), r"shape \(10, 2\)"),
        (np.zeros((10, 3), dtype=complex), "not a real numeric type"),
        (np.array([[1, 2, 3]] * 10, dtype=object), "dtype object is not a real numeric"),
    ],
)
def test_load_npy_errors(tmp_path, array, match) -> None:
    path = tmp_path / "bad.npy"
    np.save(path, array, allow_pickle=True)
    with pytest.raises(ScanError, match=match) as exc:
        load_scan(path)
    assert_single_line(exc, path)


@pytest.mark.parametrize("columns", [4, 6, 2])
def test_load_npy_refuses_other_column_counts(tmp_path, columns) -> None:
    # an (N, 4) array (x, y, z, intensity?) used to lose its 4th column without a word
    path = tmp_path / "four.npy"
    np.save(path, np.ones((12, columns), dtype=np.float32))
    with pytest.raises(ScanError, match=rf"^{path}: cannot read NPY: array has shape "
                                        rf"\(12, {columns}\), expected \(N, 3\)") as exc:
        load_scan(path)
    assert_single_line(exc, path)


@pytest.mark.parametrize("ext", [".pts", ".xyz", ".txt"])
@pytest.mark.parametrize("data", [
    np.random.default_rng(0).bytes(4000),              # random bytes
    np.arange(300, dtype="<f8").tobytes(),             # a binary array named .pts
    b"12\n" + np.random.default_rng(1).bytes(40),     # text header, binary body
])
def test_binary_point_list_is_named_as_such(tmp_path, ext, data) -> None:
    # used to say "line 1: expected x y z, got 1 value"
    path = tmp_path / f"bin{ext}"
    path.write_bytes(data)
    fmt = ext[1:].upper()
    with pytest.raises(ScanError, match=rf"^{path}: cannot read {fmt}: not a text point file "
                                        r"\(binary data\)$") as exc:
        load_scan(path)
    assert_single_line(exc, path)


def test_text_point_list_with_a_few_odd_bytes_still_loads(tmp_path) -> None:
    pts = grid_points()
    path = tmp_path / "latin.pts"
    body = "\n".join(f"{x} {y} {z}" for x, y, z in pts)
    path.write_bytes("# scanné à Zürich\n".encode("latin-1") + body.encode())
    np.testing.assert_allclose(load_scan(path).points, pts)


def test_extension_is_case_insensitive(tmp_path) -> None:
    path = tmp_path / "UPPER.XYZ"
    path.write_text("\n".join(f"{x} {y} {z}" for x, y, z in grid_points()))
    assert load_scan(path).n_points == 12


# ----------------------------------------------------------------------------- load errors


def test_missing_file(tmp_path) -> None:
    path = tmp_path / "nope.ply"
    with pytest.raises(ScanError, match=r"nope\.ply: no such file$"):
        load_scan(path)


def test_directory(tmp_path) -> None:
    with pytest.raises(ScanError, match="is a directory"):
        load_scan(tmp_path)


@pytest.mark.parametrize("ext", SUPPORTED_SCAN_FORMATS)
def test_empty_file(tmp_path, ext) -> None:
    path = tmp_path / f"empty{ext}"
    path.touch()
    with pytest.raises(ScanError, match=r"empty file \(0 bytes\)") as exc:
        load_scan(path)
    assert_single_line(exc, path)


def test_unknown_extension(tmp_path) -> None:
    path = tmp_path / "scan.abc"
    path.write_text("1 2 3\n")
    with pytest.raises(
        ScanError, match=r"scan\.abc: unknown scan format '\.abc' \(expected one of \.ply, \.obj"
    ):
        load_scan(path)
    path = tmp_path / "noext"
    path.write_text("1 2 3\n")
    with pytest.raises(ScanError, match=r"unknown scan format \(no extension\)"):
        load_scan(path)


@pytest.mark.parametrize(
    "content",
    [
        b"this is not a ply file\n",
        b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nend_head",
        b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n"
        b"property float z\nend_header\n1 2 3\n4 five 6\n",
        bytes(range(256)) * 4,
    ],
)
def test_corrupt_ply(tmp_path, content) -> None:
    path = tmp_path / "bad.ply"
    path.write_bytes(content)
    with pytest.raises(ScanError, match=r"bad\.ply: cannot read PLY: ") as exc:
        load_scan(path)
    assert_single_line(exc, path)
    assert exc.value.__cause__ is None and exc.value.__suppress_context__


@pytest.mark.parametrize("text", [True, False])
@pytest.mark.parametrize("cut", ["vertices", "faces"])
def test_truncated_ply_header_counts_lie(tmp_path, text, cut) -> None:
    path = write_ply(tmp_path / "t.ply", xyz_struct(grid_points()), grid_faces(), text=text)
    data = path.read_bytes()
    header_end = data.index(b"end_header") + len(b"end_header\n")
    keep = header_end + (40 if cut == "vertices" else (len(data) - header_end) - 20)
    path.write_bytes(data[:keep])
    with pytest.raises(
        ScanError, match=r"t\.ply: cannot read PLY: .*(end-of-file|end-of-line)"
    ) as exc:
        load_scan(path)
    assert_single_line(exc, path)


def test_ply_structural_errors(tmp_path) -> None:
    path = tmp_path / "s.ply"
    pts = grid_points()
    xy = np.zeros(len(pts), dtype=[("x", "f4"), ("y", "f4")])
    plyfile.PlyData([plyfile.PlyElement.describe(xy, "vertex")]).write(str(path))
    with pytest.raises(ScanError, match="no 'z' property"):
        load_scan(path)
    plyfile.PlyData([plyfile.PlyElement.describe(xy, "point")]).write(str(path))
    with pytest.raises(ScanError, match="no 'vertex' element"):
        load_scan(path)
    write_ply(path, xyz_struct(pts), [[0, 1, 12]], text=True)
    with pytest.raises(
        ScanError, match=r"1 face references vertices outside \[0, 12\) \(e\.g\. index 12\)"
    ):
        load_scan(path)
    write_ply(path, xyz_struct(pts), [[0, 1, 2], [0, -1, 2], [0, 1, 99]], text=False)
    with pytest.raises(ScanError, match=r"2 faces reference vertices outside"):
        load_scan(path)


def test_range_grid_header_errors(tmp_path) -> None:
    pts, cells = scanner_grid(3, 4)
    path = write_range_grid(tmp_path / "g.ply", pts, cells)
    text = path.read_text()
    path.write_text(text.replace("obj_info num_cols 4\n", ""))
    with pytest.raises(ScanError, match="no num_rows/num_cols"):
        load_scan(path)
    path.write_text(text.replace("num_cols 4", "num_cols 5"))
    with pytest.raises(ScanError, match=r"range_grid has 12 cells but num_rows x num_cols = 3 x 5"):
        load_scan(path)
    path.write_text(text.replace("\n1 11\n", "\n1 40\n"))
    with pytest.raises(ScanError, match=r"1 range_grid cell references vertices outside \[0, 12\)"):
        load_scan(path)


def test_nan_and_inf_coordinates(tmp_path) -> None:
    pts = grid_points()
    pts[[1, 4], 2] = np.nan
    pts[7, 0] = np.inf
    path = tmp_path / "n.npy"
    np.save(path, pts)
    with pytest.raises(ScanError, match=r"n\.npy: 3 points have NaN or infinite coordinates$"):
        load_scan(path)
    pts = grid_points()
    pts[0, 1] = -np.inf
    np.save(path, pts)
    with pytest.raises(ScanError, match=r"1 point has NaN"):
        load_scan(path)


def test_too_few_points(tmp_path) -> None:
    path = tmp_path / "few.xyz"
    path.write_text("0 0 0\n1 0 0\n0 1 0\n")
    with pytest.raises(ScanError, match=r"few\.xyz: only 3 points, at least 10 needed"):
        load_scan(path)
    assert load_scan(path, min_points=3).n_points == 3
    with pytest.raises(ConfigError):
        load_scan(path, min_points=0)
    with pytest.raises(ConfigError):
        load_scan(path, min_points=2.5)


@pytest.mark.parametrize("axis", [0, 1])
def test_zero_xy_extent(tmp_path, axis) -> None:
    pts = grid_points()
    pts[:, axis] = 3.25
    path = tmp_path / "flat.npy"
    np.save(path, pts)
    name = "xy"[axis]
    with pytest.raises(
        ScanError,
        match=(
            rf"flat\.npy: all points share the same {name} \(zero {name} extent\); "
            "a height field needs an x and a y extent"
        ),
    ):
        load_scan(path)


def test_zero_z_extent_is_valid(tmp_path) -> None:
    path = tmp_path / "flat.npy"
    np.save(path, grid_points(z=1.5))
    assert np.ptp(load_scan(path).points[:, 2]) == 0


@pytest.mark.skipif(os.name != "posix" or os.geteuid() == 0, reason="root reads anything")
def test_unreadable_file(tmp_path) -> None:
    path = tmp_path / "locked.xyz"
    path.write_text("1 2 3\n")
    path.chmod(0)
    with pytest.raises(ScanError, match=r"locked\.xyz: cannot read XYZ: Permission denied"):
        load_scan(path)


def test_messages_and_source_echo_the_path_as_given(tmp_path, monkeypatch) -> None:
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ScanError, match=r"^nope\.ply: no such file$"):
        load_scan("nope.ply")
    Path("rel.xyz").write_text("\n".join(f"{x} {y} {z}" for x, y, z in grid_points()))
    assert load_scan("rel.xyz").source == "rel.xyz"
    assert load_scan(Path("rel.xyz")).source == "rel.xyz"


def test_parser_exceptions_are_wrapped(tmp_path, monkeypatch) -> None:
    def broken(path):
        raise RuntimeError("some\n  internal detail")

    monkeypatch.setitem(_readers.READERS, ".ply", broken)
    path = tmp_path / "x.ply"
    path.write_text("ply\n")
    with pytest.raises(ScanError, match=r"x\.ply: cannot read PLY: some internal detail$") as exc:
        load_scan(path)
    assert_single_line(exc, path)


def test_inputs_are_never_modified(tmp_path) -> None:
    pts = grid_points()
    files = [
        write_ply(tmp_path / "a.ply", xyz_struct(pts), grid_faces(), text=False),
        write_ply(tmp_path / "b.ply", xyz_struct(pts), grid_faces(), text=True),
        CROP,
    ]
    np.save(tmp_path / "c.npy", pts)
    (tmp_path / "d.xyz").write_text("\n".join(f"{x},{y},{z}" for x, y, z in pts))
    (tmp_path / "e.obj").write_text("".join(f"v {x} {y} {z}\n" for x, y, z in pts) + "f 1 2 3\n")
    (tmp_path / "f.off").write_text("OFF\n12 0 0\n" + "".join(f"{x} {y} {z}\n" for x, y, z in pts))
    (tmp_path / "g.stl").write_text(stl_ascii(pts[grid_faces()]))
    files += [tmp_path / n for n in ("c.npy", "d.xyz", "e.obj", "f.off", "g.stl")]
    before = {f: (f.read_bytes(), f.stat().st_mtime_ns) for f in files}
    for f in files:
        scan = load_scan(f)
        assert not scan.points.flags.writeable
    after = {f: (f.read_bytes(), f.stat().st_mtime_ns) for f in files}
    assert before == after


# ----------------------------------------------------------------------------- save_mesh


@pytest.mark.parametrize("ext", SUPPORTED_MESH_FORMATS)
def test_round_trip_every_format(tmp_path, mesh, ext) -> None:
    out = save_mesh(mesh, tmp_path / f"out{ext}")
    assert out == tmp_path / f"out{ext}" and out.is_file()
    scan = load_scan(out)
    assert scan.n_faces == mesh.n_faces
    atol = 1e-6 if ext == ".stl" else 0
    np.testing.assert_allclose(
        triangles(scan.points, scan.faces), triangles(mesh.vertices, mesh.faces), atol=atol
    )
    if ext != ".stl":  # STL has no shared vertex list; the others keep it verbatim
        np.testing.assert_array_equal(scan.points, mesh.vertices)
        np.testing.assert_array_equal(scan.faces, mesh.faces)
    assert [p.name for p in tmp_path.iterdir()] == [out.name]  # no temp files left


def test_saved_ply_has_normals_quality_and_matches_plyfile(tmp_path, mesh) -> None:
    out = save_mesh(mesh, tmp_path / "q.ply")
    ply = plyfile.PlyData.read(str(out))
    assert not ply.text and ply.byte_order == "<"
    v = ply["vertex"].data
    assert v.dtype.names == ("x", "y", "z", "nx", "ny", "nz", "quality")
    np.testing.assert_allclose(v["quality"], mesh.vertex_quality, atol=1e-7)
    np.testing.assert_allclose(v["nz"], 1.0)
    # the fast writer produces exactly what plyfile's own writer would
    face = np.empty(mesh.n_faces, dtype=[("vertex_indices", "O")])
    face["vertex_indices"] = [np.asarray(f, dtype=np.int32) for f in mesh.faces]
    ref = tmp_path / "ref.ply"
    plyfile.PlyData(
        [plyfile.PlyElement.describe(v, "vertex"), plyfile.PlyElement.describe(face, "face")],
        byte_order="<",
        comments=["asrbf-mesh"],
    ).write(str(ref))
    assert out.read_bytes() == ref.read_bytes()


def test_saved_ply_is_read_by_pymeshlab(tmp_path, mesh) -> None:
    pymeshlab = pytest.importorskip("pymeshlab")
    out = save_mesh(mesh, tmp_path / "m.ply")
    ms = pymeshlab.MeshSet()
    ms.load_new_mesh(str(out))
    m = ms.current_mesh()
    assert (m.vertex_number(), m.face_number()) == (mesh.n_vertices, mesh.n_faces)
    np.testing.assert_allclose(m.vertex_matrix(), mesh.vertices)
    np.testing.assert_allclose(m.vertex_scalar_array(), mesh.vertex_quality, atol=1e-7)


def test_obj_with_normals_round_trips(tmp_path, mesh) -> None:
    out = save_mesh(mesh, tmp_path / "n.obj")
    assert "vn 0 0 1" in out.read_text() and "f 1//1 2//2 6//6" in out.read_text()
    np.testing.assert_array_equal(load_scan(out).faces, mesh.faces)


def test_save_scan_with_and_without_faces(tmp_path) -> None:
    scan = Scan(grid_points(), grid_faces())
    assert load_scan(save_mesh(scan, tmp_path / "s.off")).n_faces == 12
    cloud = Scan(grid_points())
    for ext in (".ply", ".obj", ".off"):
        back = load_scan(save_mesh(cloud, tmp_path / f"cloud{ext}"))
        assert back.faces is None
        np.testing.assert_array_equal(back.points, cloud.points)
    ply = plyfile.PlyData.read(str(tmp_path / "cloud.ply"))
    assert [e.name for e in ply.elements] == ["vertex"]
    with pytest.raises(ScanError, match="STL cannot store a point cloud"):
        save_mesh(cloud, tmp_path / "cloud.stl")
    assert not (tmp_path / "cloud.stl").exists()


def test_save_unknown_extension_writes_nothing(tmp_path, mesh) -> None:
    with pytest.raises(
        ScanError, match=r"out\.xyz: unknown mesh format '\.xyz' \(expected one of \.ply"
    ):
        save_mesh(mesh, tmp_path / "out.xyz")
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(TypeError):
        save_mesh(grid_points(), tmp_path / "out.ply")


def test_save_uppercase_extension(tmp_path, mesh) -> None:
    assert load_scan(save_mesh(mesh, tmp_path / "UP.PLY")).n_faces == mesh.n_faces


def test_save_refuses_to_overwrite_inputs(tmp_path, mesh) -> None:
    src = save_mesh(mesh, tmp_path / "in.ply")
    before = (src.read_bytes(), src.stat().st_mtime_ns)
    with pytest.raises(AsrbfError, match="refusing to overwrite the input file"):
        save_mesh(mesh, src, overwrite_inputs=[src])
    scan = load_scan(src)
    with pytest.raises(AsrbfError, match="refusing to overwrite"):
        save_mesh(scan, tmp_path / "in.ply")  # the scan's own source is protected
    assert (src.read_bytes(), src.stat().st_mtime_ns) == before
    # overwriting a file that is not an input is fine (atomically replaced)
    other = save_mesh(mesh, tmp_path / "other.ply")
    save_mesh(scan, other, overwrite_inputs=[None])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.ply", "other.ply"]


def test_save_failure_leaves_no_temp_and_keeps_target(tmp_path, mesh, monkeypatch) -> None:
    target = tmp_path / "keep.off"
    target.write_text("old")

    def boom(tmp, *args):
        Path(tmp).write_text("partial")
        raise OSError(28, "No space left on device")

    monkeypatch.setitem(_writers.WRITERS, ".off", boom)
    with pytest.raises(ScanError, match=r"keep\.off: cannot write \(No space left on device\)"):
        save_mesh(mesh, target)
    assert target.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["keep.off"]


def test_save_bad_output_location(tmp_path, mesh) -> None:
    with pytest.raises(AsrbfError, match="does not exist"):
        save_mesh(mesh, tmp_path / "missing" / "m.ply")
    (tmp_path / "d.ply").mkdir()
    with pytest.raises(AsrbfError, match="is a directory"):
        save_mesh(mesh, tmp_path / "d.ply")


def test_save_does_not_touch_mesh(tmp_path, mesh) -> None:
    v, f = mesh.vertices.copy(), mesh.faces.copy()
    for ext in SUPPORTED_MESH_FORMATS:
        save_mesh(mesh, tmp_path / f"m{ext}")
    np.testing.assert_array_equal(mesh.vertices, v)
    np.testing.assert_array_equal(mesh.faces, f)


@settings(
    max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    n=st.integers(min_value=10, max_value=40),
    n_faces=st.integers(min_value=1, max_value=60),
    seed=st.integers(min_value=0, max_value=2**32 - 1),
    ext=st.sampled_from(SUPPORTED_MESH_FORMATS),
)
def test_round_trip_random_meshes(tmp_path, n, n_faces, seed, ext) -> None:
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(n, 3)) * 10.0 ** rng.integers(-3, 4)
    f = np.vstack([[0, 1, 2], rng.integers(0, n, size=(n_faces, 3))])
    m = Mesh(v, f)
    scan = load_scan(save_mesh(m, tmp_path / f"r{ext}"), min_points=3)
    if ext == ".stl":
        np.testing.assert_allclose(scan.points[scan.faces], v[f].astype(np.float32))
    else:
        np.testing.assert_array_equal(scan.points, v)
        np.testing.assert_array_equal(scan.faces, f)
