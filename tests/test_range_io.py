"""Gridded range data: depth images, GeoTIFF tiles and elevation arrays (asrbf_mesh._range)."""

from __future__ import annotations

import hashlib
import math
from pathlib import Path

import numpy as np
import pytest
import tifffile
from PIL import Image

from asrbf_mesh._range import (
    DEFAULT_JUMP,
    RangeGrid,
    degree_lengths,
    read_depth_image,
    read_geotiff,
    read_grid_array,
    read_range,
    sniff_range_kind,
)
from asrbf_mesh._range_write import write_like
from asrbf_mesh.errors import AsrbfError, ConfigError, ScanError

DATA = Path(__file__).parent / "data"
TUM_K = (520.9, 521.0, 325.1 - 176, 249.7 - 128)  # the crop's intrinsics


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _depth_u16(h: int = 12, w: int = 16) -> np.ndarray:
    rng = np.random.default_rng(0)
    a = rng.integers(800, 4000, size=(h, w)).astype(np.uint16)
    a[2:4, 3:6] = 0
    return a


def _one_line_error(exc: pytest.ExceptionInfo, path: Path) -> str:
    msg = str(exc.value)
    assert "\n" not in msg and path.name in msg, msg
    return msg


# --------------------------------------------------------------------------- depth images


def test_png16_round_trip_and_mask(tmp_path: Path) -> None:
    a = _depth_u16()
    src = tmp_path / "d.png"
    Image.fromarray(a).save(src)
    before = _digest(src)
    g = read_depth_image(src, depth_scale=1000)
    assert g.kind == "depth" and g.fmt == "png" and g.dtype == "uint16" and g.nodata == 0
    assert np.isnan(g.z[2:4, 3:6]).all()
    np.testing.assert_allclose(g.z[0, 0], a[0, 0] / 1000)

    out, mask = tmp_path / "o.png", tmp_path / "m.png"
    write_like(g, g.z, out)
    back = np.asarray(Image.open(out))
    assert back.dtype == a.dtype and back.shape == a.shape and np.array_equal(back, a)

    z_new = np.array(g.z)
    z_new[2, 3] = 1.5
    keep = z_new.copy()
    write_like(g, z_new, out, mask=mask)
    back = np.asarray(Image.open(out))
    assert back[2, 3] == 1500 and back[2, 4] == 0 and back[0, 0] == a[0, 0]
    m = np.asarray(Image.open(mask))
    assert m.dtype == np.uint8 and m.shape == a.shape
    assert m[2, 3] == 255 and int(m.sum()) == 255
    assert np.array_equal(z_new, keep, equal_nan=True)  # inputs never modified
    assert _digest(src) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["d.png", "m.png", "o.png"]


@pytest.mark.parametrize("dtype", [np.uint16, np.float32])
def test_tiff_round_trip(tmp_path: Path, dtype: type) -> None:
    a = _depth_u16().astype(dtype)
    if dtype is np.float32:
        a = a / np.float32(1000)
        a[5, 5] = np.nan
    src = tmp_path / "d.tif"
    tifffile.imwrite(src, a, photometric="minisblack")
    scale = 1000 if dtype is np.uint16 else None
    g = read_depth_image(src, depth_scale=scale)
    assert g.fmt == "tiff" and g.dtype == np.dtype(dtype).name
    assert np.isnan(g.z[2, 3]) and np.isnan(g.z[5, 5]) == (dtype is np.float32)
    np.testing.assert_allclose(g.z[0, 1], float(a[0, 1]) / (scale or 1), rtol=1e-6)
    out = tmp_path / "o.tiff"
    write_like(g, g.z, out)
    back = tifffile.imread(out)
    assert back.dtype == a.dtype and back.shape == a.shape
    if dtype is np.uint16:
        assert np.array_equal(back, a)
    else:  # no-data cells come back as the first invalid value (0)
        expect = np.where(np.isnan(a), 0, a)
        assert np.array_equal(back, expect)
    assert sniff_range_kind(src) == "depth"


@pytest.mark.parametrize("dtype", [np.uint16, np.float32])
def test_lzw_tiff_decoded_without_imagecodecs(tmp_path: Path, dtype: type) -> None:
    a = _depth_u16().astype(dtype)
    src = tmp_path / "lzw.tif"
    Image.fromarray(a).save(src, compression="tiff_lzw")
    with tifffile.TiffFile(src) as tif:
        assert tif.pages.first.compression == 5
    g = read_depth_image(src, depth_scale=1000)
    assert g.dtype == np.dtype(dtype).name and g.compressed
    np.testing.assert_allclose(g.z[0, 0], float(a[0, 0]) / 1000)
    out = tmp_path / "o.tif"
    write_like(g, g.z, out)
    with tifffile.TiffFile(out) as tif:
        assert tif.pages.first.compression == 8  # Deflate: tifffile writes it unaided
        assert np.array_equal(tif.asarray(), a)


def test_read_range_dispatches(tmp_path: Path) -> None:
    src = tmp_path / "d.png"
    Image.fromarray(_depth_u16()).save(src)
    g = read_range(src, depth_scale=5000)
    assert g.kind == "depth" and sniff_range_kind(src) == "depth"


def _plane_depth(h: int, w: int, k: tuple[float, float, float, float]) -> np.ndarray:
    """Depth of the plane 0.2 X + 0.1 Y + Z = 1.5 (OpenCV camera coordinates)."""
    fx, fy, cx, cy = k
    v, u = np.mgrid[0:h, 0:w].astype(np.float64)
    return 1.5 / (0.2 * (u - cx) / fx + 0.1 * (v - cy) / fy + 1.0)


def test_intrinsics_keep_a_plane_planar() -> None:
    k = (500.0, 520.0, 30.0, 20.0)
    z = _plane_depth(40, 60, k)
    z[5, 5] = np.inf
    keep = z.copy()
    g = RangeGrid(z, "depth", intrinsics=k)
    assert np.array_equal(z, keep) and not g.z.flags.writeable and np.isnan(g.z[5, 5])
    pts, idx = g.points()
    assert len(pts) == z.size - 1 and idx[5 * 60 + 5 - 1] == 5 * 60 + 4
    centred = pts - pts.mean(axis=0)
    sv = np.linalg.svd(centred, compute_uv=False)
    assert sv[2] < 1e-9 * sv[0]
    # world = (X, -Y, -Z): the plane's normal (0.2, 0.1, 1) becomes (0.2, -0.1, -1)
    assert np.allclose(pts @ np.array([0.2, -0.1, -1.0]), 1.5)
    # the camera centre's pixel lies on the -z axis
    on_axis = pts[np.flatnonzero(idx == 20 * 60 + 30)[0]]
    assert abs(on_axis[0]) < 1e-12 and abs(on_axis[1]) < 1e-12 and on_axis[2] < 0
    # without intrinsics: x = column, y = -row, z = -depth
    pix, _ = RangeGrid(z, "depth").points()
    assert pix[1].tolist() == [1.0, -0.0, -z[0, 1]]


# --------------------------------------------------------------------------- triangles


def _faces_ok(scan, n_expected: int) -> None:
    assert scan.n_faces == n_expected
    p = scan.points[scan.faces]
    nz = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])[:, 2]
    assert (nz > 0).all()  # counter-clockwise seen from +z


def test_full_grid_and_three_cell_blocks() -> None:
    z = np.ones((4, 5))
    g = RangeGrid(z, "elevation", cell=1.0)
    s = g.to_scan()
    assert s.grid_shape == (4, 5) and s.n_points == 20
    _faces_ok(s, 2 * 3 * 4)
    z[1, 1] = np.nan  # four blocks lose a corner: one triangle each
    _faces_ok(RangeGrid(z, "elevation", cell=1.0).to_scan(), 2 * 3 * 4 - 4)


def test_shorter_diagonal_is_used() -> None:
    z = np.array([[0.0, 0.0], [0.0, 0.9]])  # the (0,0)-(1,1) diagonal is longer
    s = RangeGrid(z, "elevation", cell=1.0).to_scan(jump=None)
    assert sorted(map(sorted, s.faces.tolist())) == [[0, 1, 2], [1, 2, 3]]


def _ramp_depth(angle_deg: float, k: tuple[float, float, float, float]) -> np.ndarray:
    """A plane inclined ``angle_deg`` to the image plane: Z = 1 + tan(angle) X."""
    fx, _, cx, _ = k
    _, u = np.mgrid[0:30, 0:40].astype(np.float64)
    return 1.0 / (1.0 - math.tan(math.radians(angle_deg)) * (u - cx) / fx)


def test_jump_keeps_a_60_degree_ramp_and_cuts_a_kinect_step() -> None:
    k = (525.0, 525.0, 20.0, 15.0)
    ramp = RangeGrid(_ramp_depth(60, k), "depth", intrinsics=k).to_scan()
    _faces_ok(ramp, 2 * 29 * 39)
    steep = RangeGrid(_ramp_depth(80, k), "depth", intrinsics=k).to_scan()
    assert steep.n_faces == 2 * 29 * 39  # 80 degrees (ratio 5.7) is still a surface

    z = np.full((30, 40), 1.0)
    z[:, 20:] = 1.05  # a 5 cm step at 1 m: 26 footprints
    g = RangeGrid(z, "depth", intrinsics=k)
    s = g.to_scan()
    near = s.points[:, 2] > -1.025
    across = near[s.faces].any(axis=1) & ~near[s.faces].all(axis=1)
    assert not across.any()
    _faces_ok(s, 2 * 29 * 38)  # only the column of blocks on the step goes
    assert g.to_scan(jump=None).n_faces == 2 * 29 * 39
    # without intrinsics the nominal focal length gives the same cut
    assert RangeGrid(z, "depth").to_scan().n_faces == 2 * 29 * 38


def test_jump_on_elevation_grids() -> None:
    _, cols = np.mgrid[0:10, 0:12].astype(np.float64)
    ramp = cols * 30.0 * math.tan(math.radians(60))  # 30 m cells, 60 degree slope
    assert RangeGrid(ramp, "elevation", cell=30.0).to_scan().n_faces == 2 * 9 * 11
    cliff = np.where(cols < 6, 100.0, 100.0 + 30.0 * (DEFAULT_JUMP + 1))
    assert RangeGrid(cliff, "elevation", cell=30.0).to_scan().n_faces == 2 * 9 * 10
    with pytest.raises(ConfigError, match="jump"):
        RangeGrid(ramp, "elevation", cell=30.0).to_scan(jump=0)


def test_step_corner_keeps_the_triangle_on_one_side() -> None:
    z = np.array([[1.0, 1.0], [1.0, 2.0]])  # one corner far behind
    s = RangeGrid(z, "depth", intrinsics=(500.0, 500.0, 0.5, 0.5)).to_scan()
    assert s.faces.tolist() == [[0, 2, 1]]


# --------------------------------------------------------------------------- GeoTIFF


def _geokeys(model: int, raster: int = 1, unit: int | None = 9001) -> tuple[int, ...]:
    keys = [(1024, 0, 1, model), (1025, 0, 1, raster)]
    if model == 1:
        keys += [(3072, 0, 1, 32617)] + ([(3076, 0, 1, unit)] if unit else [])
    else:
        keys += [(2048, 0, 1, 4326)]
    return (1, 1, 0, len(keys), *[v for key in keys for v in key])


def _write_geotiff(path: Path, z: np.ndarray, *, model: int = 1, scale=(30.0, 30.0),
                   tie=(500000.0, 4000000.0), nodata: str | None = "-9999",
                   transform: tuple[float, ...] | None = None) -> None:
    geo = _geokeys(model)
    tags = [(34735, 3, len(geo), geo, True)]
    if transform is None:
        tags += [(33550, 12, 3, (*scale, 0.0), True),
                 (33922, 12, 6, (0.0, 0.0, 0.0, *tie, 0.0), True)]
    else:
        tags.append((34264, 12, 16, transform, True))
    if nodata is not None:
        tags.append((42113, 2, 0, nodata, True))
    tifffile.imwrite(path, z, photometric="minisblack", metadata=None, extratags=tags)


def _dem(h: int = 10, w: int = 14) -> np.ndarray:
    r, c = np.mgrid[0:h, 0:w]
    z = (200 + 3 * r + 2 * c).astype(np.int16)
    z[0, 0] = -9999
    return z


def test_geotiff_projected_round_trip(tmp_path: Path) -> None:
    src = tmp_path / "dem.tif"
    raw = _dem()
    _write_geotiff(src, raw)
    before = _digest(src)
    assert sniff_range_kind(src) == "geotiff"
    g = read_geotiff(src)
    assert g.kind == "elevation" and g.crs == "projected" and g.dtype == "int16"
    assert g.cell == (30.0, 30.0) and g.origin == (500015.0, 3999985.0)
    assert np.isnan(g.z[0, 0]) and g.nodata == -9999
    pts, idx = g.points()
    assert pts[0].tolist() == [500045.0, 3999985.0, 202.0] and idx[0] == 1

    z_new = np.array(g.z)
    z_new[0, 0] = 201.6
    z_new[3, 3] = np.nan
    out = tmp_path / "filled.tif"
    write_like(g, z_new, out, mask=tmp_path / "mask.tif")
    back = tifffile.imread(out)
    assert back.dtype == raw.dtype and back.shape == raw.shape
    assert back[0, 0] == 202 and back[3, 3] == -9999 and back[5, 6] == raw[5, 6]
    with tifffile.TiffFile(src) as a, tifffile.TiffFile(out) as b:
        ta, tb = a.pages.first.tags, b.pages.first.tags
        for code in (33550, 33922, 34735, 42113):
            assert np.array_equal(np.asarray(ta[code].value), np.asarray(tb[code].value))
    g2 = read_geotiff(out)
    assert g2.cell == g.cell and g2.origin == g.origin and g2.crs == "projected"
    assert tifffile.imread(tmp_path / "mask.tif")[0, 0] == 255
    assert _digest(src) == before


def test_geotiff_without_nodata_gets_one_when_cells_are_empty(tmp_path: Path) -> None:
    src = tmp_path / "dem.tif"
    _write_geotiff(src, _dem().astype(np.uint16) + 10000, nodata=None)
    g = read_geotiff(src)
    assert g.nodata is None and np.isfinite(g.z).all()
    z_new = np.array(g.z)
    z_new[1, 1] = np.nan
    write_like(g, z_new, tmp_path / "o.tif")
    again = read_geotiff(tmp_path / "o.tif")
    assert again.nodata == 0 and np.isnan(again.z[1, 1]) and np.isfinite(again.z).sum() == 139


def test_geotiff_geographic_cells_in_metres(tmp_path: Path) -> None:
    src = tmp_path / "geo.tif"
    d = 1 / 1200
    _write_geotiff(src, _dem().astype(np.float32), model=2, scale=(d, d), tie=(-84.0, 36.5),
                   nodata="nan")
    g = read_geotiff(src)
    assert g.crs == "geographic"
    lat_c = 36.5 - 5 * d  # centre of the 10 rows of cells
    m_lon, m_lat = degree_lengths(lat_c)
    assert g.cell == pytest.approx((d * m_lon, d * m_lat))
    assert g.cell[1] == pytest.approx(92.4, abs=0.2) and g.cell[0] == pytest.approx(74.6, abs=0.2)
    assert m_lon == pytest.approx(111320 * math.cos(math.radians(lat_c)), rel=2e-3)


def test_geotiff_pixel_is_point_and_transformation(tmp_path: Path) -> None:
    src = tmp_path / "t.tif"
    m = (10.0, 0.0, 0.0, 1000.0, 0.0, -10.0, 0.0, 2000.0, 0, 0, 0, 0, 0, 0, 0, 1.0)
    _write_geotiff(src, _dem(), transform=m)
    g = read_geotiff(src)
    assert g.cell == (10.0, 10.0) and g.origin == (1005.0, 1995.0)


def test_rotated_geotiff_is_refused(tmp_path: Path) -> None:
    src = tmp_path / "rot.tif"
    m = (10.0, 1.0, 0.0, 1000.0, 1.0, -10.0, 0.0, 2000.0, 0, 0, 0, 0, 0, 0, 0, 1.0)
    _write_geotiff(src, _dem(), transform=m)
    with pytest.raises(ScanError) as exc:
        read_geotiff(src)
    assert "rotated GeoTIFF grids are not supported" in _one_line_error(exc, src)


# --------------------------------------------------------------------------- arrays


def test_npy_round_trip(tmp_path: Path) -> None:
    z = np.linspace(0, 1, 30).reshape(5, 6).astype(np.float32)
    z[1, 2] = np.nan
    src = tmp_path / "z.npy"
    np.save(src, z)
    g = read_grid_array(src, cell=(2.0, 3.0))
    assert g.cell == (2.0, 3.0) and np.isnan(g.z[1, 2]) and g.dtype == "float32"
    assert g.to_scan().n_points == 29
    out = tmp_path / "o.npy"
    write_like(g, g.z, out)
    back = np.load(out)
    assert back.dtype == z.dtype and np.array_equal(back, z, equal_nan=True)


def test_npz_with_cell_and_origin(tmp_path: Path) -> None:
    src = tmp_path / "z.npz"
    np.savez(src, elevation=np.arange(12.0).reshape(3, 4), cell=np.array(5.0),
             origin=np.array([100.0, 200.0]))
    g = read_grid_array(src)
    assert g.cell == (5.0, 5.0) and g.origin == (100.0, 200.0)
    write_like(g, g.z + 1, tmp_path / "o.npz")
    with np.load(tmp_path / "o.npz") as back:
        assert sorted(back.files) == ["cell", "elevation", "origin"]
        assert np.array_equal(back["elevation"], np.arange(12.0).reshape(3, 4) + 1)


def test_jacksboro_crop_loads_in_metres(tmp_path: Path) -> None:
    src = DATA / "jacksboro_crop.npz"
    before = _digest(src)
    g = read_grid_array(src)
    assert g.shape == (64, 64) and g.crs == "geographic" and g.dtype == "int16"
    assert g.cell[0] == pytest.approx(74.5, abs=0.3) and g.cell[1] == pytest.approx(92.5, abs=0.3)
    assert np.isfinite(g.z).all() and 200 < np.nanmin(g.z) < np.nanmax(g.z) < 1200
    s = g.to_scan()
    assert s.n_faces == 2 * 63 * 63
    ext = np.ptp(s.points, axis=0)
    assert ext[0] == pytest.approx(63 * g.cell[0]) and ext[1] == pytest.approx(63 * g.cell[1])
    out = tmp_path / "j.npz"
    write_like(g, g.z, out)
    with np.load(src) as a, np.load(out) as b:
        assert sorted(a.files) == sorted(b.files)
        assert b["elevation"].dtype == np.int16
        assert np.array_equal(a["elevation"], b["elevation"])
    assert _digest(src) == before


def test_tum_crop_loads() -> None:
    src = DATA / "tum_desk_crop.png"
    g = read_depth_image(src, depth_scale=5000, intrinsics=TUM_K)
    assert g.shape == (64, 64) and g.dtype == "uint16"
    valid = np.isfinite(g.z)
    assert 0.5 < valid.mean() < 1 and 0.5 < np.nanmin(g.z) < np.nanmax(g.z) < 10
    s = g.to_scan()
    assert s.grid_shape == (64, 64) and s.n_points == valid.sum()
    assert 0 < s.n_faces < g.to_scan(jump=None).n_faces  # some depth edges are cut
    p = s.points[s.faces]
    assert (np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])[:, 2] > 0).mean() > 0.95


# --------------------------------------------------------------------------- bad inputs


def test_eight_bit_without_scale(tmp_path: Path) -> None:
    src = tmp_path / "d8.png"
    Image.fromarray(np.full((4, 4), 9, np.uint8)).save(src)
    with pytest.raises(ScanError) as exc:
        read_depth_image(src)
    assert "depth_scale" in _one_line_error(exc, src)
    assert np.nanmax(read_depth_image(src, depth_scale=10).z) == pytest.approx(0.9)


def test_rgb_is_refused(tmp_path: Path) -> None:
    src = tmp_path / "rgb.png"
    Image.fromarray(np.zeros((4, 4, 3), np.uint8)).save(src)
    with pytest.raises(ScanError) as exc:
        read_depth_image(src, depth_scale=1000)
    assert "one channel" in _one_line_error(exc, src)
    tif = tmp_path / "rgb.tif"
    tifffile.imwrite(tif, np.zeros((4, 4, 3), np.uint16))
    with pytest.raises(ScanError) as exc:
        read_depth_image(tif, depth_scale=1000)
    assert "one channel" in _one_line_error(exc, tif)


def test_all_invalid_image(tmp_path: Path) -> None:
    src = tmp_path / "zero.png"
    Image.fromarray(np.zeros((5, 5), np.uint16)).save(src)
    with pytest.raises(ScanError) as exc:
        read_depth_image(src, depth_scale=1000)
    assert "no cell holds a measurement" in _one_line_error(exc, src)


def test_non_2d_npy_and_missing_cell(tmp_path: Path) -> None:
    src = tmp_path / "pts.npy"
    np.save(src, np.zeros((4, 4, 2)))
    with pytest.raises(ScanError) as exc:
        read_grid_array(src, cell=1.0)
    assert "2-D" in _one_line_error(exc, src)
    flat = tmp_path / "flat.npy"
    np.save(flat, np.zeros((4, 4)))
    with pytest.raises(ScanError) as exc:
        read_grid_array(flat)
    assert "cell size" in _one_line_error(exc, flat)
    bare = tmp_path / "bare.npz"
    np.savez(bare, elevation=np.zeros((3, 3)))
    with pytest.raises(ScanError) as exc:
        read_grid_array(bare)
    assert "cell size" in _one_line_error(exc, bare)


def test_other_bad_files(tmp_path: Path) -> None:
    junk = tmp_path / "junk.png"
    junk.write_bytes(b"not a png")
    with pytest.raises(ScanError) as exc:
        read_depth_image(junk, depth_scale=1)
    _one_line_error(exc, junk)
    with pytest.raises(ScanError) as exc:
        read_depth_image(tmp_path / "missing.png", depth_scale=1)
    _one_line_error(exc, tmp_path / "missing.png")
    plain = tmp_path / "plain.tif"
    tifffile.imwrite(plain, np.ones((3, 3), np.float32))
    with pytest.raises(ScanError) as exc:
        read_geotiff(plain)
    assert "no georeferencing" in _one_line_error(exc, plain)
    neg = tmp_path / "neg.tif"
    tifffile.imwrite(neg, -np.ones((3, 3), np.float32))
    with pytest.raises(ScanError) as exc:
        read_depth_image(neg)
    assert "negative" in _one_line_error(exc, neg)
    with pytest.raises(ScanError, match="no cell holds a measurement"):
        read_depth_image(neg, invalid=-1.0)


def test_writer_refuses_bad_targets(tmp_path: Path) -> None:
    src = tmp_path / "d.png"
    Image.fromarray(_depth_u16()).save(src)
    before = _digest(src)
    g = read_depth_image(src, depth_scale=1000)
    with pytest.raises(ConfigError, match="shape"):
        write_like(g, g.z[:-1], tmp_path / "o.png")
    with pytest.raises(ConfigError, match="depth_scale"):
        read_depth_image(src, depth_scale=-5)
    with pytest.raises(ConfigError, match="intrinsics"):
        read_depth_image(src, depth_scale=5, intrinsics=(0, 1, 2, 3))
    assert RangeGrid(np.full((3, 3), np.nan), "depth").to_scan().n_points == 0
    with pytest.raises(ConfigError, match=".png"):
        write_like(g, g.z, tmp_path / "o.tif")
    with pytest.raises(AsrbfError, match="input"):
        write_like(g, g.z, src)
    assert _digest(src) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["d.png"]


def test_a_header_claiming_billions_of_cells_is_refused(tmp_path: Path) -> None:
    """Found by fuzzing: a 300-byte TIFF claiming 13 billion cells asked for 49 GB."""
    from asrbf_mesh._range import MAX_CELLS, _check_size

    f = tmp_path / "x.tif"
    f.write_bytes(b"0" * 300)
    with pytest.raises(ScanError, match="a corrupt header"):
        _check_size(f, (MAX_CELLS // 1000 + 1, 1001), 4, True)
    with pytest.raises(ScanError, match="truncated"):
        _check_size(f, (10, 10), 4, False)
    _check_size(f, (5, 10), 4, True)  # compressed: may hold more than its size
