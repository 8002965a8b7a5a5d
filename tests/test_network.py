"""Network: evaluation in physical units, normals, statistics, the .asrbf file, pickling."""

from __future__ import annotations

import io
import json
import pickle
import zipfile
from pathlib import Path

import numpy as np
import pytest

import asrbf_mesh as am
from asrbf_mesh._config import FitConfig
from asrbf_mesh._frame import Frame
from asrbf_mesh._network import FORMAT_VERSION, VOLATILE_INFO, FitLog, Network
from asrbf_mesh.errors import AsrbfError, NetworkFileError


def grid_xy(net: Network, n: int = 25, inset: float = 0.02) -> np.ndarray:
    """Physical (x, y) points of an n x n grid inside the scan's xy box."""
    lo = net.frame.offset[:2] + inset * net.frame.scale[:2]
    hi = net.frame.offset[:2] + (1 - inset) * net.frame.scale[:2]
    gx, gy = np.meshgrid(np.linspace(lo[0], hi[0], n), np.linspace(lo[1], hi[1], n))
    return np.column_stack([gx.ravel(), gy.ravel()])


# ----------------------------------------------------------------------------- evaluation


def test_physical_and_unit_evaluation_agree(franke_net: Network) -> None:
    xy = grid_xy(franke_net)
    fr = franke_net.frame
    uv = (xy - fr.offset[:2]) / fr.scale[:2]
    z_phys = franke_net.evaluate(xy)
    z_unit = franke_net.evaluate(uv, unit=True)
    np.testing.assert_allclose(z_phys, z_unit * fr.scale[2] + fr.offset[2], rtol=1e-13)
    # surface_points: world points above the query, consistent with evaluate
    sp = franke_net.surface_points(xy)
    np.testing.assert_allclose(sp[:, :2], xy, rtol=1e-13)
    np.testing.assert_allclose(sp[:, 2], z_phys, rtol=1e-13)
    np.testing.assert_allclose(franke_net.surface_points(uv, unit=True), sp, rtol=1e-13)


def test_network_is_close_to_the_truth_in_physical_units(franke_net: Network, syn) -> None:
    xy = grid_xy(franke_net, 40)
    err = np.abs(franke_net.evaluate(xy) - syn.truth(syn.franke, xy))
    # z spans ~24 mm; measured mean 0.025 mm, max 0.33 mm
    assert err.mean() < 0.15
    assert err.max() < 1.5


def test_gradient_matches_finite_differences_in_physical_units(franke_net: Network) -> None:
    xy = grid_xy(franke_net, 15, inset=0.1)
    h = 1e-4  # mm
    fd = np.column_stack([
        (franke_net.evaluate(xy + [h, 0]) - franke_net.evaluate(xy - [h, 0])) / (2 * h),
        (franke_net.evaluate(xy + [0, h]) - franke_net.evaluate(xy - [0, h])) / (2 * h)])
    grad = franke_net.gradient(xy)
    assert np.abs(grad).max() > 0.1  # Franke's slopes in mm/mm
    # truncation steps (exp(-12.25) of a weight) may fall between the two samples
    close = np.abs(grad - fd) < 1e-4 * np.abs(grad).max() + 1e-6
    assert close.mean() > 0.98
    unit = franke_net.gradient((xy - franke_net.frame.offset[:2]) / franke_net.frame.scale[:2],
                               unit=True)
    np.testing.assert_allclose(grad, unit * franke_net.frame.scale[2] / franke_net.frame.scale[:2],
                               rtol=1e-12)


def test_normals_are_unit_face_plus_z_and_follow_gradient(franke_net: Network) -> None:
    xy = grid_xy(franke_net, 20)
    n = franke_net.normals(xy)
    assert n.shape == (len(xy), 3)
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, rtol=1e-12)
    assert np.all(n[:, 2] > 0)
    g = franke_net.gradient(xy)
    expected = np.column_stack([-g, np.ones(len(g))])
    expected /= np.linalg.norm(expected, axis=1, keepdims=True)
    np.testing.assert_allclose(n, expected, atol=1e-12)


def test_normals_in_world_frame_for_another_view_axis(syn) -> None:
    # a height field x = f(y, z): the depth axis is world x, normals must face +x
    p = syn.franke_points(40)
    pts = np.column_stack([p[:, 2], p[:, 0], p[:, 1]])  # (depth, a, b) -> world (x, y, z)
    net = am.fit(pts, seed=0, view_axis="x", progress=False, passes=1)
    assert net.frame.view_axis == "x"
    local = pts @ net.frame.rotation
    n = net.normals(local[:, :2])
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, rtol=1e-12)
    assert np.all(n[:, 0] > 0)
    # surface points lie close to the scan points (world units, x spans 20 mm)
    sp = net.surface_points(local[:, :2])
    assert np.abs(sp - pts).max() < 1.0
    np.testing.assert_allclose(sp[:, 1:], pts[:, 1:], atol=1e-9)


@pytest.mark.parametrize("bad", [np.zeros((3, 3)), np.zeros(4), np.array([[np.nan, 0.5]])])
def test_evaluate_rejects_bad_points(franke_net: Network, bad: np.ndarray) -> None:
    with pytest.raises(AsrbfError, match="xy"):
        franke_net.evaluate(bad)


# ----------------------------------------------------------------------------- sizes, stats


def test_stats_match_numpy(franke_net: Network) -> None:
    st = franke_net.stats()
    w = franke_net.widths
    a = np.abs(franke_net.weights)
    assert st.n_neurons == franke_net.n_neurons == len(w)
    assert (st.width_max, st.width_min) == (w.max(), w.min())
    assert st.width_mean == pytest.approx(w.mean(), rel=1e-14)
    assert st.width_std == pytest.approx(w.std(), rel=1e-12)
    assert (st.weight_max, st.weight_min) == (a.max(), a.min())
    assert st.weight_mean == pytest.approx(a.mean(), rel=1e-14)
    assert st.weight_std == pytest.approx(a.std(), rel=1e-12)
    assert st.weight_min >= 0


def test_compression_ratios(franke_net: Network) -> None:
    n, k = franke_net.info["n_points"], franke_net.n_neurons
    assert n == 3600
    assert franke_net.compression_ratio() == pytest.approx(n / k)
    assert franke_net.storage_ratio() == pytest.approx(3 * n / (4 * k))
    assert franke_net.compression_ratio(1000) == pytest.approx(1000 / k)
    bare = Network(franke_net.a0, franke_net.centers, franke_net.widths, franke_net.weights,
                   franke_net.frame, franke_net.config)
    with pytest.raises(AsrbfError, match="n_points is unknown"):
        bare.compression_ratio()
    assert bare.storage_ratio(400) == pytest.approx(300 / k)


def test_arrays_are_read_only(franke_net: Network) -> None:
    for arr in (franke_net.centers, franke_net.widths, franke_net.weights):
        assert arr.dtype == np.float64
        with pytest.raises(ValueError):
            arr[0] = 0.0


# ----------------------------------------------------------------------------- constructor

FRAME = Frame(np.eye(3), np.zeros(3), np.ones(3))


@pytest.mark.parametrize(("a0", "centers", "widths", "weights", "match"), [
    (0.0, [[0.5, np.nan]], [0.1], [1.0], "finite"),
    (0.0, [[0.5, 0.5]], [np.inf], [1.0], "finite"),
    (0.0, [[0.5, 0.5]], [0.1], [np.nan], "finite"),
    (np.nan, [[0.5, 0.5]], [0.1], [1.0], "finite"),
    (0.0, [[0.5, 0.5]], [0.0], [1.0], "positive"),
    (0.0, [[0.5, 0.5], [0.2, 0.2]], [0.1, -0.1], [1.0, 1.0], "positive"),
    (0.0, [[0.5, 0.5], [0.2, 0.2]], [0.1], [1.0, 1.0], "differ"),
    (0.0, [[0.5, 0.5]], [0.1], [1.0, 2.0], "differ"),
])
def test_constructor_rejects_bad_parameters(a0, centers, widths, weights, match) -> None:
    with pytest.raises(ValueError, match=match):
        Network(a0, np.array(centers), np.array(widths), np.array(weights), FRAME, FitConfig())


def test_constructor_rejects_centers_of_the_wrong_width() -> None:
    with pytest.raises(ValueError, match="centers"):
        Network(0.0, np.arange(12.0).reshape(4, 3) / 12, np.full(6, 0.1), np.zeros(6), FRAME,
                FitConfig())


def test_constructor_copies_inputs() -> None:
    c = np.array([[0.5, 0.5]])
    net = Network(0.0, c, np.array([0.1]), np.array([1.0]), FRAME, FitConfig())
    c[0, 0] = 0.0
    assert net.centers[0, 0] == 0.5


# ----------------------------------------------------------------------------- file, pickle


def assert_same_network(a: Network, b: Network, rtol: float = 0.0) -> None:
    assert a.n_neurons == b.n_neurons
    assert a.a0 == b.a0
    for name in ("centers", "widths", "weights"):
        np.testing.assert_allclose(getattr(a, name), getattr(b, name), rtol=rtol, atol=0)
    np.testing.assert_array_equal(a.frame.rotation, b.frame.rotation)
    np.testing.assert_array_equal(a.frame.offset, b.frame.offset)
    np.testing.assert_array_equal(a.frame.scale, b.frame.scale)
    assert a.frame.view_axis == b.frame.view_axis
    assert a.config == b.config


def test_save_load_exact_round_trip(franke_net: Network, tmp_path: Path) -> None:
    out = franke_net.save(tmp_path / "franke.asrbf")
    assert out == tmp_path / "franke.asrbf"
    back = Network.load(out)
    assert_same_network(franke_net, back)
    stored = {k: v for k, v in franke_net.info.items() if k not in VOLATILE_INFO}
    assert back.info == json.loads(json.dumps(stored))
    assert back.log is not None and franke_net.log is not None
    for name in FitLog._ARRAYS:
        np.testing.assert_array_equal(getattr(back.log, name), getattr(franke_net.log, name))
    assert back.log.counters() == franke_net.log.counters()
    xy = grid_xy(franke_net, 10)
    np.testing.assert_array_equal(back.evaluate(xy), franke_net.evaluate(xy))


def test_file_is_a_zip_of_npy_members(franke_net: Network, tmp_path: Path) -> None:
    path = franke_net.save(tmp_path / "n.asrbf")
    with np.load(path) as z:
        np.testing.assert_array_equal(z["centers"], franke_net.centers)
        meta = json.loads(bytes(z["meta"]).decode())
    assert meta["format"] == "asrbf-network"
    assert meta["format_version"] == FORMAT_VERSION
    assert meta["dtype"] == "float64"


def test_save_load_float32_round_trip(franke_net: Network, tmp_path: Path) -> None:
    p64 = franke_net.save(tmp_path / "n64.asrbf")
    p32 = franke_net.save(tmp_path / "n32.asrbf", float32=True)
    back = Network.load(p32)
    assert back.centers.dtype == np.float64
    assert_same_network(franke_net, back, rtol=1e-7)  # a0 stays float64
    assert not np.array_equal(back.weights, franke_net.weights)
    with np.load(p32) as z:
        assert z["widths"].dtype == np.float32
    assert p32.stat().st_size < p64.stat().st_size
    xy = grid_xy(franke_net, 10)
    np.testing.assert_allclose(back.evaluate(xy), franke_net.evaluate(xy), atol=1e-4)


def test_same_network_gives_identical_bytes(franke_net: Network, tmp_path: Path) -> None:
    a = franke_net.save(tmp_path / "a.asrbf").read_bytes()
    b = franke_net.save(tmp_path / "b.asrbf").read_bytes()
    assert a == b
    c = Network.load(tmp_path / "a.asrbf").save(tmp_path / "c.asrbf").read_bytes()
    assert c == a


def test_save_refuses_bad_outputs(franke_net: Network, tmp_path: Path) -> None:
    with pytest.raises(AsrbfError, match="does not exist"):
        franke_net.save(tmp_path / "missing" / "n.asrbf")
    with pytest.raises(AsrbfError, match="is a directory"):
        franke_net.save(tmp_path)
    src = tmp_path / "scan.asrbf"
    src.write_bytes(b"input")
    with pytest.raises(AsrbfError, match="refusing to overwrite"):
        franke_net.save(src, inputs=(src,))
    assert src.read_bytes() == b"input"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scan.asrbf"]


def test_pickle_round_trip(franke_net: Network) -> None:
    xy = grid_xy(franke_net, 10)
    z = franke_net.evaluate(xy)  # builds the cached evaluation grid first
    back = pickle.loads(pickle.dumps(franke_net))
    assert_same_network(franke_net, back)
    assert back.info == franke_net.info
    np.testing.assert_array_equal(back.evaluate(xy), z)


def rewrite(src: Path, dst: Path, change) -> None:
    """Copy a .asrbf file, passing its members through ``change(name, array)``."""
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst, "w") as zout:
        for name in zin.namelist():
            arr = np.lib.format.read_array(io.BytesIO(zin.read(name)))
            arr = change(name, arr)
            if arr is None:
                continue
            buf = io.BytesIO()
            np.lib.format.write_array(buf, arr)
            zout.writestr(name, buf.getvalue())


def with_meta(**changes):
    def change(name, arr):
        if name != "meta.npy":
            return arr
        meta = json.loads(bytes(arr).decode())
        meta.update(changes)
        return np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8)
    return change


def test_load_errors(franke_net: Network, tmp_path: Path) -> None:
    good = franke_net.save(tmp_path / "good.asrbf")
    with pytest.raises(NetworkFileError, match="no such file"):
        Network.load(tmp_path / "missing.asrbf")
    with pytest.raises(NetworkFileError, match="is a directory"):
        Network.load(tmp_path)

    junk = tmp_path / "junk.asrbf"
    junk.write_bytes(np.random.default_rng(0).bytes(3000))
    with pytest.raises(NetworkFileError, match="not a zip archive"):
        Network.load(junk)

    empty = tmp_path / "empty.asrbf"
    empty.write_bytes(b"")
    with pytest.raises(NetworkFileError, match="not an asrbf network file"):
        Network.load(empty)

    truncated = tmp_path / "truncated.asrbf"
    data = good.read_bytes()
    truncated.write_bytes(data[: len(data) // 2])
    with pytest.raises(NetworkFileError, match=r"truncated\.asrbf"):
        Network.load(truncated)

    no_meta = tmp_path / "no_meta.asrbf"
    rewrite(good, no_meta, lambda name, arr: None if name == "meta.npy" else arr)
    with pytest.raises(NetworkFileError, match="no metadata"):
        Network.load(no_meta)

    other = tmp_path / "other.zip"
    with zipfile.ZipFile(other, "w") as zf:
        zf.writestr("hello.txt", "not a network")
    with pytest.raises(NetworkFileError, match="no metadata"):
        Network.load(other)

    v2 = tmp_path / "v2.asrbf"
    rewrite(good, v2, with_meta(format_version=FORMAT_VERSION + 1))
    with pytest.raises(NetworkFileError, match=f"format version {FORMAT_VERSION + 1} is not "
                                               "supported"):
        Network.load(v2)

    foreign = tmp_path / "foreign.asrbf"
    rewrite(good, foreign, with_meta(format="something-else"))
    with pytest.raises(NetworkFileError, match="not an asrbf network file"):
        Network.load(foreign)

    bad_json = tmp_path / "bad_json.asrbf"
    rewrite(good, bad_json, lambda name, arr: np.frombuffer(b"{oops", np.uint8)
            if name == "meta.npy" else arr)
    with pytest.raises(NetworkFileError, match="unreadable metadata"):
        Network.load(bad_json)

    no_widths = tmp_path / "no_widths.asrbf"
    rewrite(good, no_widths, lambda name, arr: None if name == "widths.npy" else arr)
    with pytest.raises(NetworkFileError, match="corrupt network file"):
        Network.load(no_widths)

    nan_weights = tmp_path / "nan.asrbf"
    rewrite(good, nan_weights, lambda name, arr: np.full_like(arr, np.nan)
            if name == "weights.npy" else arr)
    with pytest.raises(NetworkFileError, match="corrupt network file.*finite"):
        Network.load(nan_weights)

    bad_config = tmp_path / "bad_config.asrbf"
    rewrite(good, bad_config, with_meta(config={"no_such_field": 1}))
    with pytest.raises(NetworkFileError, match="unknown FitConfig field"):
        Network.load(bad_config)

    # the good file still loads after all that
    assert Network.load(good).n_neurons == franke_net.n_neurons


# ----------------------------------------------------------------------------- fit info, K = 0


def test_fit_info_is_typed_and_round_trips(franke_net, tmp_path) -> None:
    info = franke_net.fit_info
    assert isinstance(info, am.FitInfo)
    assert info.n_points == franke_net.info["n_points"] and info.ebar == franke_net.info["ebar"]
    assert info.to_dict() == franke_net.info  # the same dict, key for key
    assert am.FitInfo.from_dict(info.to_dict()) == info
    loaded = am.Network.load(franke_net.save(tmp_path / "n.asrbf"))
    assert loaded.fit_info is not None and loaded.fit_info.fit_seconds is None
    assert loaded.fit_info.ebar == info.ebar
    bare = am.Network(0.0, np.zeros((0, 2)), [], [], franke_net.frame, franke_net.config)
    assert bare.fit_info is None


def test_stats_of_a_network_without_neurons_has_no_nan(franke_net) -> None:
    bare = am.Network(0.5, np.zeros((0, 2)), [], [], franke_net.frame, franke_net.config)
    st = bare.stats()
    assert st.n_neurons == 0
    values = list(st.to_dict().values())
    assert values[0] == 0 and all(x is None for x in values[1:])
    json.dumps(st.to_dict(), allow_nan=False)  # strict JSON
