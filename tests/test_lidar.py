"""LAS/LAZ point clouds: filtered reading, streaming blocks, writing the fill back."""

from __future__ import annotations

import hashlib
import struct
import sys
from pathlib import Path

import numpy as np
import pytest

laspy = pytest.importorskip("laspy")

from asrbf_mesh._lidar import (  # noqa: E402
    LasBlocks,
    las_blocks,
    read_las,
    write_las_with_fill,
)
from asrbf_mesh._stream import PointBlocks  # noqa: E402
from asrbf_mesh.errors import AsrbfError, ConfigError, ScanError  # noqa: E402

X0, Y0 = 500_000.0, 5_000_000.0
SCALES = [0.01, 0.01, 0.001]
OFFSETS = [X0, Y0, 0.0]
N_GRID, N_VEG, N_NOISE = 400, 100, 3  # ground pulses, of which under trees, noise points
N_ALL = N_GRID + N_VEG + N_NOISE


def _has_lazrs() -> bool:
    try:
        return bool(laspy.LazBackend.detect_available())
    except Exception:
        return False


needs_laz = pytest.mark.skipif(not _has_lazrs(), reason="lazrs not installed")


def terrain(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    u, v = (x - X0) / 100.0, (y - Y0) / 100.0
    return 200.0 + 5.0 * np.sin(3 * u) * np.cos(2 * v) + 2.0 * u


def _geokeys_vlr() -> object:
    """A GeoTIFF key directory for EPSG 32633 (WGS 84 / UTM 33N), as raw bytes."""
    keys = [(1024, 0, 1, 1), (1025, 0, 1, 1), (3072, 0, 1, 32633)]
    data = struct.pack("<4H", 1, 1, 0, len(keys))
    data += b"".join(struct.pack("<4H", *k) for k in keys)
    return laspy.VLR(user_id="LASF_Projection", record_id=34735,
                     description="GeoTIFF GeoKeyDirectoryTag", record_data=data)


def _add_crs(header: object) -> None:
    try:
        import pyproj
    except ImportError:
        header.vlrs.append(_geokeys_vlr())
    else:
        header.add_crs(pyproj.CRS.from_epsg(32633))


def make_las(path: Path, version: str = "1.4", point_format: int = 6, *,
             crs: bool = True, seed: int = 0) -> Path:
    """A 20 x 20 terrain tile: ground (class 2), trees over 100 pulses, 3 noise points.

    Under a tree the pulse has two returns: the canopy first (class 5, high vegetation),
    the ground last; elsewhere one return, ground. The records are shuffled.
    """
    rng = np.random.default_rng(seed)
    g = (np.arange(20) + 0.5) * 5.0
    gx, gy = np.meshgrid(g, g)
    x = X0 + gx.ravel() + rng.uniform(-1, 1, N_GRID)
    y = Y0 + gy.ravel() + rng.uniform(-1, 1, N_GRID)
    z = terrain(x, y)
    tree = np.zeros(N_GRID, bool)
    tree[rng.choice(N_GRID, N_VEG, replace=False)] = True
    cols = {
        "x": [x, x[tree], X0 + np.array([10.0, 50.0, 90.0])],
        "y": [y, y[tree], Y0 + np.array([20.0, 60.0, 80.0])],
        "z": [z, z[tree] + rng.uniform(8, 15, N_VEG), np.array([-50.0, 900.0, 0.0])],
        "classification": [np.full(N_GRID, 2), np.full(N_VEG, 5), np.full(N_NOISE, 7)],
        "return_number": [np.where(tree, 2, 1), np.ones(N_VEG), np.ones(N_NOISE)],
        "number_of_returns": [np.where(tree, 2, 1), np.full(N_VEG, 2), np.ones(N_NOISE)],
        "intensity": [rng.integers(0, 4000, N_GRID), rng.integers(0, 4000, N_VEG),
                      np.zeros(N_NOISE)],
    }
    order = rng.permutation(N_ALL)
    header = laspy.LasHeader(point_format=point_format, version=version)
    header.scales = SCALES
    header.offsets = OFFSETS
    if crs:
        _add_crs(header)
    las = laspy.LasData(header)
    for key in ("x", "y", "z"):
        setattr(las, key, np.concatenate(cols[key])[order])
    las.classification = np.concatenate(cols["classification"])[order].astype(np.uint8)
    las.return_number = np.concatenate(cols["return_number"])[order].astype(np.uint8)
    las.number_of_returns = np.concatenate(cols["number_of_returns"])[order].astype(np.uint8)
    las.intensity = np.concatenate(cols["intensity"])[order].astype(np.uint16)
    if "gps_time" in las.point_format.dimension_names:
        las.gps_time = np.arange(N_ALL, dtype=np.float64) * 1e-5
    las.write(path)
    return path


@pytest.fixture(params=[("1.4", 6), ("1.2", 1)], ids=["las14-fmt6", "las12-fmt1"])
def las_file(request: pytest.FixtureRequest, tmp_path: Path) -> Path:
    version, fmt = request.param
    return make_las(tmp_path / "tile.las", version, fmt)


def _sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _one_line(exc: pytest.ExceptionInfo) -> str:
    msg = str(exc.value)
    assert "\n" not in msg and msg
    return msg


# --------------------------------------------------------------------------- read


def test_read_all_points_in_real_coordinates(las_file: Path) -> None:
    scan, meta = read_las(las_file)
    ref = laspy.read(las_file)
    assert scan.n_points == N_ALL and scan.faces is None
    assert scan.source == str(las_file)
    np.testing.assert_array_equal(scan.points[:, 0], np.asarray(ref.x))
    np.testing.assert_array_equal(scan.points[:, 2], np.asarray(ref.z))
    assert scan.points[:, 0].min() > X0 - 2 and scan.points[:, 1].min() > Y0 - 2
    expect = (np.asarray(ref.X) * SCALES[0] + OFFSETS[0])
    np.testing.assert_allclose(scan.points[:, 0], expect, rtol=0, atol=1e-9)
    assert meta.n_read == meta.n_kept == N_ALL
    assert meta.scales == tuple(SCALES) and meta.offsets == tuple(OFFSETS)
    assert meta.version == str(ref.header.version)
    assert meta.point_format == ref.header.point_format.id
    assert dict(meta.class_counts) == {2: N_GRID, 5: N_VEG, 7: N_NOISE}
    assert meta.has_crs and meta.crs_vlrs[0].user_id == "LASF_Projection"
    assert not meta.compressed


@pytest.mark.parametrize(("classes", "returns", "n"), [
    ((2,), None, N_GRID),
    ([5], None, N_VEG),
    ((2, 5), None, N_GRID + N_VEG),
    (2, None, N_GRID),
    (None, "first", N_GRID - N_VEG + N_VEG + N_NOISE),
    (None, "last", N_GRID + N_NOISE),
    (None, "single", N_GRID - N_VEG + N_NOISE),
    (None, (2,), N_VEG),
    (None, [1, 2], N_ALL),
    ((2,), "last", N_GRID),
    ((2,), "first", N_GRID - N_VEG),
    ((2,), "single", N_GRID - N_VEG),
    ((5,), "first", N_VEG),
])
def test_filters(las_file: Path, classes: object, returns: object, n: int) -> None:
    scan, meta = read_las(las_file, classes=classes, returns=returns)
    assert scan.n_points == meta.n_kept == n
    assert meta.n_read == N_ALL
    ref = laspy.read(las_file)
    keep = np.ones(N_ALL, bool)
    if classes is not None:
        keep &= np.isin(np.asarray(ref.classification), np.atleast_1d(classes))
    pts = np.column_stack([np.asarray(ref.x), np.asarray(ref.y), np.asarray(ref.z)])
    if returns is None:
        np.testing.assert_array_equal(scan.points, pts[keep])


def test_ground_is_the_terrain(las_file: Path) -> None:
    scan, _ = read_las(las_file, classes=(2,))
    p = scan.points
    np.testing.assert_allclose(p[:, 2], terrain(p[:, 0], p[:, 1]), atol=1e-3)
    veg, _ = read_las(las_file, classes=(5,))
    q = veg.points
    assert (q[:, 2] > terrain(q[:, 0], q[:, 1]) + 7).all()


@pytest.mark.parametrize("bad", [(256,), (-1,), ("2",), (2.0,), (), "ground", (True,)])
def test_bad_classes(las_file: Path, bad: object) -> None:
    with pytest.raises(ConfigError) as exc:
        read_las(las_file, classes=bad)
    _one_line(exc)


@pytest.mark.parametrize("bad", ["second", (0,), (16,), (), 1.5])
def test_bad_returns(las_file: Path, bad: object) -> None:
    with pytest.raises(ConfigError) as exc:
        read_las(las_file, returns=bad)
    _one_line(exc)


# --------------------------------------------------------------------------- errors


def test_laspy_missing(las_file: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "laspy", None)
    with pytest.raises(ScanError) as exc:
        read_las(las_file)
    assert _one_line(exc) == ("reading LAS needs the lidar extra: "
                              "pip install 'asrbf-mesh[lidar]'")
    with pytest.raises(ScanError, match=r"lidar extra"):
        las_blocks(las_file, 64)
    with pytest.raises(ScanError, match=r"writing LAS needs the lidar extra"):
        write_las_with_fill(las_file, None, np.zeros((1, 3)), las_file.with_name("o.las"))


def _no_backend(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(laspy.LazBackend, "detect_available", classmethod(lambda cls: ()))


@needs_laz
def test_laz_without_lazrs(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    laz = make_las(tmp_path / "tile.laz")
    _no_backend(monkeypatch)
    with pytest.raises(ScanError) as exc:
        read_las(laz)
    msg = _one_line(exc)
    assert msg.startswith(str(laz)) and "pip install lazrs" in msg
    with pytest.raises(ScanError, match="pip install lazrs"):
        las_blocks(laz, 64)
    # a compressed file named .las is found by its header
    disguised = tmp_path / "disguised.las"
    disguised.write_bytes(laz.read_bytes())
    with pytest.raises(ScanError, match="pip install lazrs"):
        read_las(disguised)


def test_laz_output_without_lazrs(las_file: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    _, meta = read_las(las_file)
    _no_backend(monkeypatch)
    out = las_file.with_name("out.laz")
    with pytest.raises(ScanError, match="pip install lazrs") as exc:
        write_las_with_fill(las_file, meta, np.zeros((0, 3)), out)
    _one_line(exc)
    assert not out.exists()


def test_class_filter_keeping_nothing_names_the_classes(las_file: Path) -> None:
    with pytest.raises(ScanError) as exc:
        read_las(las_file, classes=(6, 9))
    msg = _one_line(exc)
    assert "class 6 (building), class 9 (water)" in msg
    assert "class 2 (ground): 400" in msg
    assert "class 5 (high vegetation): 100" in msg
    assert "class 7 (low noise): 3" in msg
    with pytest.raises(ScanError, match=r"class 2 \(ground\): 400"):
        las_blocks(las_file, 64, classes=(6,))


def test_filters_together_keeping_nothing(las_file: Path) -> None:
    with pytest.raises(ScanError) as exc:
        read_las(las_file, classes=(5,), returns="last")
    msg = _one_line(exc)
    assert "100 points of classes 5" in msg and "'last'" in msg


def test_too_few_points(las_file: Path) -> None:
    with pytest.raises(ScanError) as exc:
        read_las(las_file, classes=(7,))
    msg = _one_line(exc)
    assert "only 3 points of 503 kept by classes 7" in msg and "at least 10" in msg


def test_tiny_file(tmp_path: Path) -> None:
    header = laspy.LasHeader(point_format=1, version="1.2")
    las = laspy.LasData(header)
    las.x, las.y, las.z = np.arange(4.0), np.arange(4.0), np.zeros(4)
    las.write(tmp_path / "tiny.las")
    with pytest.raises(ScanError, match="only 4 points of 4 kept, a fit needs at least 10"):
        read_las(tmp_path / "tiny.las")
    las = laspy.LasData(laspy.LasHeader(point_format=1, version="1.2"))
    las.write(tmp_path / "empty.las")
    with pytest.raises(ScanError, match="holds no points"):
        read_las(tmp_path / "empty.las")


@pytest.mark.parametrize("cut", ["header", "mid-record", "record-boundary"])
def test_truncated(las_file: Path, cut: str) -> None:
    data = las_file.read_bytes()
    header = laspy.read(las_file).header
    start, size = header.offset_to_point_data, header.point_format.size
    keep = {"header": 50, "mid-record": start + 100 * size + size // 2,
            "record-boundary": start + 200 * size}[cut]
    las_file.write_bytes(data[:keep])
    with pytest.raises(ScanError) as exc:
        read_las(las_file)
    msg = _one_line(exc)
    assert msg.startswith(str(las_file))
    with pytest.raises(ScanError):
        las_blocks(las_file, 64)
    if cut == "record-boundary":
        assert "truncated" in msg and "503" in msg and "200" in msg


@pytest.mark.parametrize("content", [b"not a las file at all" * 20, b"LASF" + bytes(300)])
def test_corrupt(tmp_path: Path, content: bytes) -> None:
    bad = tmp_path / "bad.las"
    bad.write_bytes(content)
    with pytest.raises(ScanError) as exc:
        read_las(bad)
    assert _one_line(exc).startswith(f"{bad}: ")


@needs_laz
def test_truncated_laz(tmp_path: Path) -> None:
    laz = make_las(tmp_path / "tile.laz")
    data = laz.read_bytes()
    laz.write_bytes(data[: len(data) * 2 // 3])
    with pytest.raises(ScanError) as exc:
        read_las(laz)
    assert _one_line(exc).startswith(str(laz))


def test_path_errors(tmp_path: Path) -> None:
    with pytest.raises(ScanError, match="no such file"):
        read_las(tmp_path / "missing.las")
    (tmp_path / "empty.las").write_bytes(b"")
    with pytest.raises(ScanError, match="empty file"):
        read_las(tmp_path / "empty.las")
    (tmp_path / "pts.xyz").write_text("0 0 0\n")
    with pytest.raises(ScanError, match="not LAS/LAZ"):
        read_las(tmp_path / "pts.xyz")


# --------------------------------------------------------------------------- LAZ


@needs_laz
def test_laz_round_trip(tmp_path: Path) -> None:
    las = make_las(tmp_path / "tile.las")
    laz = make_las(tmp_path / "tile.laz")
    a, meta_a = read_las(las, classes=(2,), returns="last")
    b, meta_b = read_las(laz, classes=(2,), returns="last")
    np.testing.assert_array_equal(a.points, b.points)
    assert meta_b.compressed and not meta_a.compressed
    assert meta_b.crs_vlrs == meta_a.crs_vlrs
    blocks = las_blocks(laz, 64, classes=(2,), returns="last")
    np.testing.assert_array_equal(
        np.concatenate([blocks.block(i) for i in range(blocks.n_blocks)]), b.points)
    fill = np.array([[X0 + 33.0, Y0 + 44.0, 201.5], [X0 + 34.0, Y0 + 45.0, 202.5]])
    out = write_las_with_fill(laz, meta_b, fill, tmp_path / "filled.laz")
    src, got = laspy.read(laz), laspy.read(out)
    assert got.header.are_points_compressed
    assert got.points.array[: N_ALL].tobytes() == src.points.array.tobytes()
    assert np.asarray(got.synthetic)[N_ALL:].all()


# --------------------------------------------------------------------------- stream


@pytest.mark.parametrize("chunk", [1, 64, 100, 4096])
@pytest.mark.parametrize(("classes", "returns"), [(None, None), ((2,), None), ((5,), "first"),
                                                  ((2, 5), "last")])
def test_blocks_cover_read_las(las_file: Path, monkeypatch: pytest.MonkeyPatch, chunk: int,
                               classes: object, returns: object) -> None:
    scan, meta = read_las(las_file, classes=classes, returns=returns)

    def whole_file(*args: object, **kwargs: object) -> None:
        raise AssertionError("the whole file was read")

    monkeypatch.setattr(laspy, "read", whole_file)
    monkeypatch.setattr(laspy.LasReader, "read", whole_file)
    blocks = las_blocks(las_file, chunk, classes=classes, returns=returns)
    assert isinstance(blocks, PointBlocks) and isinstance(blocks, LasBlocks)
    assert blocks.n == scan.n_points and blocks.chunk == chunk
    assert blocks.path == str(las_file)
    assert blocks.meta.n_kept == meta.n_kept and blocks.meta.crs_vlrs == meta.crs_vlrs
    parts = []
    for b in range(blocks.n_blocks):
        lo, hi = blocks.bounds(b)
        pts = blocks.block(b)
        assert pts.shape == (hi - lo, 3) and pts.dtype == np.float64
        parts.append(pts)
    np.testing.assert_array_equal(np.concatenate(parts), scan.points)
    # random access, twice, and a second opening: the same blocks
    again = las_blocks(las_file, chunk, classes=classes, returns=returns)
    for b in reversed(range(blocks.n_blocks)):
        np.testing.assert_array_equal(blocks.block(b), parts[b])
        np.testing.assert_array_equal(again.block(b), parts[b])


def test_blocks_bad_arguments(las_file: Path) -> None:
    with pytest.raises(ConfigError):
        las_blocks(las_file, 0)
    blocks = las_blocks(las_file, 100)
    with pytest.raises(ConfigError):
        blocks.block(blocks.n_blocks)


def test_blocks_file_changed(las_file: Path, tmp_path: Path) -> None:
    blocks = las_blocks(las_file, 64, classes=(2,))
    make_las(las_file, "1.2", 1, seed=1)  # another tile, fewer ground points in the end
    data = las_file.read_bytes()
    las_file.write_bytes(data[: len(data) - 10 * 28])
    with pytest.raises(ScanError) as exc:
        for b in range(blocks.n_blocks):
            blocks.block(b)
    _one_line(exc)


# --------------------------------------------------------------------------- write


FILL = np.array([[X0 + 12.345, Y0 + 67.891, 205.4321],
                 [X0 + 50.0, Y0 + 50.0, 199.9999],
                 [X0 + 99.99, Y0 + 0.01, 210.0]])


def test_write_with_fill(las_file: Path, tmp_path: Path) -> None:
    scan, meta = read_las(las_file, classes=(2,))
    before = _sha(las_file)
    fill = FILL.copy()
    out = write_las_with_fill(las_file, meta, fill, tmp_path / "filled.las")
    assert out == tmp_path / "filled.las"
    assert _sha(las_file) == before
    np.testing.assert_array_equal(fill, FILL)
    assert not list(tmp_path.glob(".filled*"))  # no temporary file left

    src, got = laspy.read(las_file), laspy.read(out)
    n, m = N_ALL, len(FILL)
    assert len(got.points) == n + m
    # the original records, every field, bit for bit
    assert got.points.array[:n].tobytes() == src.points.array.tobytes()
    for dim in ("X", "Y", "Z"):
        np.testing.assert_array_equal(np.asarray(got[dim])[:n], np.asarray(src[dim]))
    # the fill: synthetic, class 2 (the class read), return 1 of 1, within half a unit
    assert not np.asarray(got.synthetic)[:n].any()
    assert np.asarray(got.synthetic)[n:].all()
    np.testing.assert_array_equal(np.asarray(got.classification)[n:], 2)
    np.testing.assert_array_equal(np.asarray(got.return_number)[n:], 1)
    np.testing.assert_array_equal(np.asarray(got.number_of_returns)[n:], 1)
    xyz = np.column_stack([np.asarray(got.x), np.asarray(got.y), np.asarray(got.z)])[n:]
    assert (np.abs(xyz - FILL) <= np.asarray(SCALES) / 2 + 1e-9).all()
    # header: version, point format, scales, offsets, CRS records
    assert got.header.version == src.header.version
    assert got.header.point_format.id == src.header.point_format.id
    np.testing.assert_array_equal(got.header.scales, src.header.scales)
    np.testing.assert_array_equal(got.header.offsets, src.header.offsets)
    assert got.header.z_max >= FILL[:, 2].max() - 1e-3
    filled, meta2 = read_las(out, classes=(2,))
    assert meta2.crs_vlrs == meta.crs_vlrs and meta2.crs_vlrs
    assert meta2.class_counts == ((2, N_GRID + m), (5, N_VEG), (7, N_NOISE))
    np.testing.assert_array_equal(filled.points[:N_GRID], scan.points)
    if src.header.point_format.id < 6:  # the flag is a bit of the classification byte
        raw = np.asarray(got.points.array["raw_classification"])
        assert (raw[n:] == 2 | 0b0010_0000).all()


def test_write_classification_and_empty_fill(las_file: Path, tmp_path: Path) -> None:
    _, meta = read_las(las_file)
    out = write_las_with_fill(las_file, meta, FILL, tmp_path / "a.las", classification=9)
    got = laspy.read(out)
    np.testing.assert_array_equal(np.asarray(got.classification)[N_ALL:], 9)
    _, meta_all = read_las(las_file)
    out = write_las_with_fill(las_file, meta_all, np.zeros((0, 3)), tmp_path / "b.las")
    got = laspy.read(out)
    assert got.points.array.tobytes() == laspy.read(las_file).points.array.tobytes()
    with pytest.raises(ConfigError):
        write_las_with_fill(las_file, meta, FILL, tmp_path / "c.las", classification=256)


def test_write_without_crs(tmp_path: Path) -> None:
    src = make_las(tmp_path / "nocrs.las", crs=False)
    _, meta = read_las(src)
    assert not meta.has_crs and meta.crs is None and meta.crs_vlrs == ()
    out = write_las_with_fill(src, meta, FILL, tmp_path / "out.las")
    assert not read_las(out)[1].has_crs


@pytest.mark.parametrize("where", ["x", "y", "z", "nan"])
def test_fill_out_of_range(las_file: Path, tmp_path: Path, where: str) -> None:
    _, meta = read_las(las_file)
    fill = FILL.copy()
    if where == "nan":
        fill[1, 2] = np.nan
    else:
        fill[1, "xyz".index(where)] = 1e12
    out = tmp_path / "out.las"
    with pytest.raises(ScanError) as exc:
        write_las_with_fill(las_file, meta, fill, out)
    msg = _one_line(exc)
    if where != "nan":
        assert "1 fill point cannot be stored" in msg and "fill point 2" in msg
    assert not out.exists() and not list(tmp_path.glob(".out*"))


def test_write_bad_outputs(las_file: Path, tmp_path: Path) -> None:
    _, meta = read_las(las_file)
    with pytest.raises(AsrbfError, match="overwrite the input"):
        write_las_with_fill(las_file, meta, FILL, las_file)
    with pytest.raises(ConfigError, match=r"\.las or \.laz"):
        write_las_with_fill(las_file, meta, FILL, tmp_path / "out.ply")
    with pytest.raises(AsrbfError, match="does not exist"):
        write_las_with_fill(las_file, meta, FILL, tmp_path / "no" / "out.las")
    with pytest.raises(ScanError, match=r"fill_points"):
        write_las_with_fill(las_file, meta, np.zeros((2, 2)), tmp_path / "out.las")


def test_write_refuses_another_file(tmp_path: Path) -> None:
    a = make_las(tmp_path / "a.las", "1.4", 6)
    b = make_las(tmp_path / "b.las", "1.2", 1)
    _, meta_a = read_las(a)
    with pytest.raises(ScanError, match="not the file the metadata describes"):
        write_las_with_fill(b, meta_a, FILL, tmp_path / "out.las")


@pytest.mark.parametrize("suffix", [".las", pytest.param(".laz", marks=needs_laz)])
def test_write_keeps_an_extended_crs_record(tmp_path: Path, suffix: str) -> None:
    from laspy.vlrs.vlrlist import VLRList

    las = laspy.read(make_las(tmp_path / "plain.las", crs=False))
    wkt = b'PROJCS["WGS 84 / UTM zone 33N",AUTHORITY["EPSG","32633"]]\x00'
    las.header.evlrs = VLRList([laspy.VLR("LASF_Projection", 2112, "OGC WKT", wkt)])
    src = tmp_path / "evlr.las"
    las.write(src)
    _, meta = read_las(src)
    assert [(v.record_id, v.data, v.extended) for v in meta.crs_vlrs] == [(2112, wkt, True)]
    out = write_las_with_fill(src, meta, FILL, tmp_path / f"out{suffix}")
    _, meta2 = read_las(out)
    assert meta2.crs_vlrs == meta.crs_vlrs and meta2.n_read == N_ALL + len(FILL)


def test_laspy_log_level_restored(las_file: Path) -> None:
    import logging

    log = logging.getLogger("laspy")
    before = log.level
    blocks = las_blocks(las_file, 64, classes=(2,))
    blocks.block(0)
    with pytest.raises(ScanError):
        read_las(las_file, classes=(6,))
    assert log.level == before


def test_a_corrupt_record_count_is_refused_not_looped_on(tmp_path: Path) -> None:
    """Found by fuzzing: 3 billion VLRs claimed by a 952-byte file made laspy loop forever."""
    import struct

    src = make_las(tmp_path / "tile.las")
    data = bytearray(src.read_bytes())
    struct.pack_into("<L", data, 100, 3_463_577_600)
    bad = tmp_path / "bad.las"
    bad.write_bytes(bytes(data))
    with pytest.raises(ScanError, match="variable-length records cannot fit") as exc:
        read_las(bad)
    assert "\n" not in str(exc.value)
