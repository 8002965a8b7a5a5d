"""Streaming fit: the same network as in memory for the same order, from every format."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import asrbf_mesh as am
import asrbf_mesh._stream as stream
from asrbf_mesh._stream import block_order, fit_stream, open_points
from asrbf_mesh.errors import ConfigError, ScanError

N = 30_000
CHUNK = 8_192


@pytest.fixture(scope="module")
def points() -> np.ndarray:
    rng = np.random.default_rng(5)
    xy = rng.random((N, 2)) * [120.0, 90.0]
    z = 6 * np.sin(xy[:, 0] / 15) * np.cos(xy[:, 1] / 11) + rng.normal(0, 0.02, N)
    return np.c_[xy, z]


@pytest.fixture(scope="module")
def files(points: np.ndarray, tmp_path_factory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("stream")
    out = {"npy": d / "s.npy", "ply": d / "s.ply", "xyz": d / "s.xyz"}
    np.save(out["npy"], points)
    import plyfile

    v = np.empty(len(points), dtype=[("x", "f8"), ("y", "f8"), ("z", "f8")])
    v["x"], v["y"], v["z"] = points.T
    plyfile.PlyData([plyfile.PlyElement.describe(v, "vertex")]).write(str(out["ply"]))
    with open(out["xyz"], "w") as fh:
        fh.write(f"# synthetic\n{len(points)}\n")
        for a, b, c in points:
            fh.write(f"{float(a)!r}, {float(b)!r} {float(c)!r}\n")  # repr: exact
    return out


@pytest.fixture(scope="module")
def streamed(files: dict[str, Path]) -> am.Network:
    return fit_stream(files["npy"], seed=2, chunk=CHUNK, mix=2, progress=False)


def _same_network(a: am.Network, b: am.Network) -> None:
    assert a.a0 == b.a0
    for name in ("centers", "widths", "weights"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert np.array_equal(a.frame.offset, b.frame.offset)
    assert np.array_equal(a.frame.scale, b.frame.scale)


def test_streaming_equals_the_in_memory_fit_in_the_same_order(
        streamed: am.Network, points: np.ndarray) -> None:
    mem = am.fit(points, seed=2, progress=False, pieces=1,  # a streamed fit is one network
                 order=lambda rng: block_order(N, CHUNK, 2, rng))
    _same_network(streamed, mem)
    assert streamed.log.counters() == mem.log.counters()
    for key in ("n_points", "spacing", "d_min", "steps", "source_sha256", "ebar_sequential"):
        assert streamed.info[key] == mem.info[key], key
    for key in ("ebar", "error_mean", "error_std"):  # sums over blocks: round-off only
        assert streamed.info[key] == pytest.approx(mem.info[key], rel=1e-12), key
    assert streamed.info["streamed"] and streamed.info["spacing_exact"]


@pytest.mark.parametrize("fmt", ["ply", "xyz"])
def test_every_format_streams_to_the_same_network(streamed: am.Network,
                                                  files: dict[str, Path], fmt: str) -> None:
    net = fit_stream(files[fmt], seed=2, chunk=CHUNK, mix=2, progress=False)
    _same_network(net, streamed)


def test_block_order_is_a_permutation_by_groups_of_blocks() -> None:
    assert sorted(block_order(50, 8, 2, np.random.default_rng(1)).tolist()) == list(range(50))
    o = block_order(48, 8, 2, np.random.default_rng(1))  # 6 whole blocks
    blocks = o // 8
    # each group of 2 blocks is replayed before the next group starts
    groups = [set(blocks[i:i + 16].tolist()) for i in range(0, 48, 16)]
    assert all(len(g) == 2 for g in groups)


def test_streaming_is_deterministic_and_seeded(files: dict[str, Path],
                                               streamed: am.Network) -> None:
    again = fit_stream(files["npy"], seed=2, chunk=CHUNK, mix=2, progress=False)
    _same_network(again, streamed)
    other = fit_stream(files["npy"], seed=3, chunk=CHUNK, mix=2, progress=False)
    assert not np.array_equal(other.weights[:50], streamed.weights[:50]) \
        or other.n_neurons != streamed.n_neurons


def test_tile_spacing_above_the_exact_limit(files: dict[str, Path], monkeypatch,
                                            streamed: am.Network) -> None:
    # large scans estimate the spacing from tiles of the footprint: close to the exact one
    monkeypatch.setattr(stream, "EXACT_SPACING_MAX", 1_000)
    monkeypatch.setattr(stream, "TILE_SAMPLE", 6_000)
    net = fit_stream(files["npy"], seed=2, chunk=CHUNK, mix=2, progress=False)
    assert not net.info["spacing_exact"]
    assert net.info["spacing"] == pytest.approx(streamed.info["spacing"], rel=0.1)
    assert net.info["ebar"] < 2 * streamed.info["ebar"]


def test_nan_is_reported_with_its_point(points: np.ndarray, tmp_path: Path) -> None:
    bad = points.copy()
    bad[20_000, 2] = np.nan
    np.save(tmp_path / "bad.npy", bad)
    with pytest.raises(ScanError, match=r"bad.npy: point 20,001 has NaN"):
        fit_stream(tmp_path / "bad.npy", chunk=CHUNK, progress=False)


def _put(path: Path, data) -> Path:
    """Write text, bytes or an array (.npy) to ``path`` and return it."""
    if isinstance(data, np.ndarray):
        np.save(path, data)
    elif isinstance(data, bytes):
        path.write_bytes(data)
    else:
        path.write_text(data)
    return path


@pytest.mark.parametrize(("make", "match"), [
    (lambda d: d / "missing.npy", "no such file"),
    (lambda d: d, "is a directory"),
    (lambda d: _put(d / "e.npy", b""), "empty file"),
    (lambda d: _put(d / "s.stl", "solid\n"), "cannot be streamed"),
    (lambda d: _put(d / "v.npy", np.zeros(5)), r"shape \(5,\), expected \(N, 3\)"),
    (lambda d: _put(d / "four.npy", np.zeros((50, 4))), r"shape \(50, 4\), expected \(N, 3\)"),
    (lambda d: _put(d / "f.npy", np.asfortranarray(np.zeros((50, 3)))), "Fortran order"),
    (lambda d: _put(d / "b.pts", np.random.default_rng(0).bytes(999)),
     r"cannot read PTS: not a text point file \(binary data\)$"),
    (lambda d: _put(d / "nov.ply", "ply\nformat binary_little_endian 1.0\nelement point 1\n"
                    "property float x\nend_header\n0000"), "cannot read PLY: no 'vertex' element"),
    (lambda d: _put(d / "few.npy", np.random.default_rng(0).random((5, 3))), "only 5 points"),
    (lambda d: _put(d / "flat.npy", np.c_[np.arange(50.0), np.zeros(50), np.arange(50.0)]),
     "zero y extent"),
    (lambda d: _put(d / "a.ply", "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n"
                    "property float y\nproperty float z\nend_header\n0 0 0\n"), "ASCII PLY"),
    (lambda d: _put(d / "t.xyz", "0 0 0\n1 x 2\n" * 10), "cannot read XYZ near point"),
])
def test_bad_files_get_one_line_errors(tmp_path: Path, make, match: str) -> None:
    path = make(tmp_path)
    with pytest.raises(ScanError, match=match) as info:
        fit_stream(path, chunk=CHUNK, progress=False)
    assert "\n" not in str(info.value) and str(info.value).startswith(str(path))


@pytest.mark.parametrize(("kw", "match"), [
    ({"chunk": 1000}, "multiple of 8,192"),
    ({"chunk": 0}, "chunk must be an integer >= 1"),
    ({"mix": 0}, "mix must be an integer >= 1"),
    ({"polish": "full"}, "polish='full' needs every point"),
    ({"view_axis": "pca"}, "view_axis 'z', 'x' or 'y'"),
])
def test_bad_options(files: dict[str, Path], kw: dict, match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        fit_stream(files["npy"], progress=False, **kw)


def test_open_points_blocks_cover_the_file(files: dict[str, Path], points: np.ndarray) -> None:
    for path in files.values():
        src = open_points(path, CHUNK)
        assert src.n == N and src.n_blocks == -(-N // CHUNK)
        got = np.concatenate([src.block(b) for b in range(src.n_blocks)])
        assert np.array_equal(got, points)


def test_cli_fit_stream(files: dict[str, Path], streamed: am.Network, tmp_path: Path) -> None:
    out = tmp_path / "s.asrbf"
    done = subprocess.run([sys.executable, "-m", "asrbf_mesh.cli", "fit", str(files["npy"]),
                           "-o", str(out), "--stream", "--chunk", str(CHUNK), "--mix", "2",
                           "--seed", "2", "--json"], capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout)["n_neurons"] == streamed.n_neurons
    _same_network(am.Network.load(out), streamed)
    bad = subprocess.run([sys.executable, "-m", "asrbf_mesh.cli", "fit", str(files["npy"]),
                          "-o", str(tmp_path / "b.asrbf"), "--stream", "--chunk", "100"],
                         capture_output=True, text=True, timeout=300)
    assert bad.returncode == 2 and "multiple of 8,192" in bad.stderr
    assert not (tmp_path / "b.asrbf").exists()


def test_truncated_npy_is_reported(points: np.ndarray, tmp_path: Path) -> None:
    path = tmp_path / "cut.npy"
    np.save(path, points)
    path.write_bytes(path.read_bytes()[:-1000])
    with pytest.raises(ScanError, match=r"cut.npy: truncated: block 3 holds"):
        fit_stream(path, chunk=CHUNK, progress=False)
