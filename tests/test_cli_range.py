"""The ``asrbf`` commands on range data: depth images, elevation grids and LiDAR files."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from test_range_io import _dem, _write_geotiff

from asrbf_mesh.cli import main

DATA = Path(__file__).parent / "data"


def _run(capsys, *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def _smooth_depth(h: int = 48, w: int = 64) -> np.ndarray:
    """A 16-bit depth image (scale 5000) of a smooth surface 1-1.4 m away with two holes."""
    y, x = np.mgrid[0:h, 0:w]
    z = 1.0 + 0.2 * np.sin(x / 15.0) + 0.1 * (y / h) ** 2
    img = np.round(z * 5000).astype(np.uint16)
    img[(x - 20) ** 2 + (y - 20) ** 2 < 25] = 0
    img[(x - 45) ** 2 + (y - 30) ** 2 < 16] = 0
    img[:, :2] = 0  # a no-data strip open to the border
    return img


def test_fill_holes_on_a_depth_image_writes_an_image_in_kind(tmp_path, capsys) -> None:
    src = tmp_path / "depth.png"
    raw = _smooth_depth()
    Image.fromarray(raw).save(src)
    before = src.read_bytes()
    out, mask = tmp_path / "filled.png", tmp_path / "mask.png"
    code, text, _ = _run(capsys, "fill-holes", str(src), "-o", str(out), "--depth-scale", "5000",
                         "--mask", str(mask), "--json")
    assert code == 0 and src.read_bytes() == before
    d = json.loads(text)
    assert d["holes_found"] == 2 and d["holes_filled"] == 2
    filled = np.asarray(Image.open(out))
    assert filled.dtype == np.uint16 and filled.shape == raw.shape
    valid = raw > 0
    assert np.array_equal(filled[valid], raw[valid])  # measured pixels untouched
    assert np.all(filled[:, :2] == 0)  # open to the border: still no measurement
    hole = (raw == 0) & (np.arange(raw.shape[1]) >= 2)[None, :]
    assert np.all(filled[hole] > 0)
    y, x = np.nonzero(hole)
    truth = np.round((1.0 + 0.2 * np.sin(x / 15.0) + 0.1 * (y / raw.shape[0]) ** 2) * 5000)
    assert np.abs(filled[hole].astype(float) - truth).max() < 0.01 * 5000  # within 1 cm
    m = np.asarray(Image.open(mask))
    assert np.array_equal(m == 255, hole)


def test_fill_holes_on_a_depth_image_can_write_a_mesh(tmp_path, capsys) -> None:
    src = tmp_path / "depth.png"
    Image.fromarray(_smooth_depth()).save(src)
    out = tmp_path / "filled.ply"
    code, text, _ = _run(capsys, "fill-holes", str(src), "-o", str(out), "--depth-scale", "5000",
                         "--intrinsics", "520.9,521.0,32,24")
    assert code == 0 and "2 filled" in text and out.exists()


def test_fit_reconstruct_and_metro_take_a_real_depth_crop(tmp_path, capsys) -> None:
    crop = DATA / "tum_desk_crop.png"
    net = tmp_path / "crop.asrbf"
    code, _, _ = _run(capsys, "fit", str(crop), "-o", str(net), "--depth-scale", "5000",
                      "--intrinsics", "520.9,521.0,149.1,121.7")
    assert code == 0
    mesh = tmp_path / "crop.ply"
    code, _, _ = _run(capsys, "reconstruct", str(net), "-o", str(mesh), "--footprint",
                      str(crop), "--depth-scale", "5000", "--intrinsics",
                      "520.9,521.0,149.1,121.7")
    assert code == 0
    code, text, _ = _run(capsys, "metro", str(mesh), str(crop), "--depth-scale", "5000",
                         "--intrinsics", "520.9,521.0,149.1,121.7", "--json")
    assert code == 0
    d = json.loads(text)
    # metres: the crop is a desk about a metre away, a few centimetres across
    assert 0 < d["b_to_a"]["mean"] < 0.01


def test_fill_holes_on_an_elevation_grid_keeps_its_georeferencing(tmp_path, capsys) -> None:
    import tifffile

    z = _dem(40, 50)
    y, x = np.mgrid[0:40, 0:50]
    hole = (x - 25) ** 2 + (y - 20) ** 2 < 20
    z[hole] = -9999
    src = tmp_path / "dem.tif"
    _write_geotiff(src, z)
    out = tmp_path / "dem_filled.tif"
    code, text, _ = _run(capsys, "fill-holes", str(src), "-o", str(out), "--json")
    assert code == 0 and json.loads(text)["holes_filled"] == 1
    with tifffile.TiffFile(src) as a, tifffile.TiffFile(out) as b:
        for code_ in (33550, 33922, 34735, 42113):
            assert a.pages.first.tags[code_].value == b.pages.first.tags[code_].value
        assert b.pages.first.asarray().dtype == a.pages.first.asarray().dtype
        after = b.pages.first.asarray()
        assert np.all(after[hole] > -9999) and np.array_equal(after[~hole], z[~hole])


@pytest.mark.parametrize(("make", "extra", "match"), [
    ("u8", [], "depth_scale|depth scale"),
    ("rgb", ["--depth-scale", "1000"], "channel|RGB"),
    ("rotated", [], "rotated GeoTIFF grids are not supported"),
])
def test_bad_range_inputs_exit_2_with_one_line(tmp_path, capsys, make, extra, match) -> None:
    if make == "u8":
        src = tmp_path / "d8.png"
        Image.fromarray(np.full((20, 20), 100, np.uint8)).save(src)
    elif make == "rgb":
        src = tmp_path / "rgb.png"
        Image.fromarray(np.full((20, 20, 3), 100, np.uint8)).save(src)
    else:
        src = tmp_path / "rot.tif"
        m = (10.0, 1.0, 0.0, 1000.0, 1.0, -10.0, 0.0, 2000.0, 0, 0, 0, 0, 0, 0, 0, 1.0)
        _write_geotiff(src, _dem(), transform=m)
    code, out, err = _run(capsys, "fill-holes", str(src), "-o", str(tmp_path / "o.ply"), *extra)
    assert code == 2 and out == ""
    line = err.strip()
    assert "\n" not in line and line.startswith("asrbf: error:")
    import re

    assert re.search(match, line), line
    assert not (tmp_path / "o.ply").exists()


def test_a_2d_npy_needs_a_cell_size(tmp_path, capsys) -> None:
    src = tmp_path / "dem.npy"
    np.save(src, _dem(30, 30))
    code, _, err = _run(capsys, "fit", str(src), "-o", str(tmp_path / "n.asrbf"))
    assert code == 2 and "\n" not in err.strip()
    code, _, _ = _run(capsys, "fit", str(src), "-o", str(tmp_path / "n.asrbf"), "--cell", "30")
    assert code == 0


laspy = pytest.importorskip("laspy")


def test_lidar_fit_stream_and_fill_back_to_las(tmp_path, capsys) -> None:
    from test_lidar import make_las

    src = make_las(tmp_path / "tile.las")
    code, _, _ = _run(capsys, "fit", str(src), "-o", str(tmp_path / "g.asrbf"), "--classes", "2",
                      "--stream", "--chunk", "8192")
    assert code == 0
    hole = tmp_path / "holed.las"
    las = laspy.read(src)
    x, y = np.asarray(las.x), np.asarray(las.y)
    keep = np.hypot(x - x.mean(), y - y.mean()) >= 12.0  # the ground samples are 5 apart
    las.points = las.points[keep]
    las.write(hole)
    out = tmp_path / "filled.las"
    code, text, _ = _run(capsys, "fill-holes", str(hole), "-o", str(out), "--classes", "2",
                         "--json")
    assert code == 0
    back = laspy.read(out)
    n = len(laspy.read(hole).points)
    assert len(back.points) > n
    assert not np.any(back.synthetic[:n]) and np.all(back.synthetic[n:])


def test_lidar_without_the_requested_class_exits_2(tmp_path, capsys) -> None:
    from test_lidar import make_las

    src = make_las(tmp_path / "tile.las")
    code, _, err = _run(capsys, "fit", str(src), "-o", str(tmp_path / "g.asrbf"),
                        "--classes", "6")
    assert code == 2 and "class" in err and "\n" not in err.strip()


def test_copy_of_a_depth_crop_is_never_modified(tmp_path, capsys) -> None:
    src = tmp_path / "crop.png"
    shutil.copy(DATA / "tum_desk_crop.png", src)
    before = src.read_bytes()
    code, _, _ = _run(capsys, "fill-holes", str(src), "-o", str(tmp_path / "f.png"),
                      "--depth-scale", "5000")
    assert code == 0 and src.read_bytes() == before
