"""The ``asrbf`` command: fit, info, reconstruct, demo; exit codes and error lines."""

from __future__ import annotations

import io
import json
import os
import subprocess
import sys
import warnings
import zipfile
from pathlib import Path

import numpy as np
import pytest

import asrbf_mesh as am
from asrbf_mesh._network import FORMAT_VERSION
from asrbf_mesh.cli import main

FIT_KEYS = {"n_points", "n_neurons", "ebar", "n_to_k", "storage_ratio", "error_mean",
            "error_std", "steps", "fit_seconds", "us_per_step"}
TIMING_KEYS = {"fit_seconds", "learn_seconds", "polish_seconds", "us_per_step"}


@pytest.fixture(scope="module")
def scan_file(tmp_path_factory, syn) -> Path:
    """1,600 points of Franke's function as a point-cloud PLY."""
    path = tmp_path_factory.mktemp("scan") / "franke.ply"
    am.save_mesh(am.Scan(syn.franke_points(40)), path)
    return path


@pytest.fixture(scope="module")
def net_file(tmp_path_factory, scan_file: Path) -> Path:
    out = tmp_path_factory.mktemp("net") / "franke.asrbf"
    assert main(["fit", str(scan_file), "-o", str(out), "--passes", "1", "--json"]) == 0
    return out


def run(capsys, *argv) -> tuple[int, str, str]:
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def assert_user_error(code: int, out: str, err: str, match: str) -> None:
    assert code == 2
    lines = err.splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("asrbf: error: ")
    assert match in lines[0]
    assert out == ""


# ----------------------------------------------------------------------------- fit


def test_fit_json(capsys, scan_file: Path, tmp_path: Path) -> None:
    out = tmp_path / "n.asrbf"
    code, stdout, err = run(capsys, "fit", scan_file, "-o", out, "--json", "--passes", "1",
                            "--seed", "3", "--polish", "none")
    assert code == 0 and err == ""
    s = json.loads(stdout)
    assert FIT_KEYS <= set(s)
    assert s["n_points"] == 1600
    assert s["steps"] == 1600
    assert s["n_to_k"] == pytest.approx(1600 / s["n_neurons"])
    assert s["storage_ratio"] == pytest.approx(3 * 1600 / (4 * s["n_neurons"]))
    assert s["ebar"] < 0.02  # measured 0.004
    assert s["seed"] == 3 and s["polish"] == "none"
    assert s["output"] == str(out)
    net = am.Network.load(out)
    assert net.n_neurons == s["n_neurons"]
    assert net.config.passes == 1 and net.config.polish == "none"
    assert net.info["seed"] == 3
    assert net.info["source"] == str(scan_file)


def test_fit_options_reach_the_config(capsys, scan_file: Path, tmp_path: Path) -> None:
    out = tmp_path / "n.asrbf"
    code, _, err = run(capsys, "fit", scan_file, "-o", out, "--json", "--passes", "1",
                       "--error-threshold", "0.02", "--d-min", "0.05", "--window", "300",
                       "--update", "gd", "--pruning", "literal", "--decay", "observation",
                       "--max-neurons", "25", "--float32")
    assert code == 0
    assert err.startswith("asrbf: warning: the neuron cap stopped growth at K = 25: ")
    assert len(err.splitlines()) == 1
    net = am.Network.load(out)
    c = net.config
    assert (c.error_threshold, c.d_min, c.window, c.update, c.pruning, c.max_neurons) == (
        0.02, 0.05, 300, "gd", "literal", 25)
    assert net.n_neurons <= 25
    with np.load(out) as z:
        assert z["weights"].dtype == np.float32


def test_fit_text_summary(capsys, scan_file: Path, tmp_path: Path) -> None:
    out = tmp_path / "n.asrbf"
    code, stdout, err = run(capsys, "fit", scan_file, "-o", out, "--passes", "1")
    assert code == 0
    assert stdout.startswith(f"fitted {scan_file} -> {out}")
    assert err == ""


def test_fit_text_summary_follows_sys_stdout(capsys, scan_file: Path, tmp_path: Path) -> None:
    code, stdout, _ = run(capsys, "fit", scan_file, "-o", tmp_path / "n.asrbf", "--passes", "1")
    assert code == 0
    for label in ("points N", "neurons K", "E-bar (unit cube)", "N:K", "3N:4K", "fit time"):
        assert label in stdout
    assert "1,600" in stdout


def test_fit_summary_tells_compiling_apart(capsys, monkeypatch, scan_file: Path,
                                           tmp_path: Path) -> None:
    """A warm fit shows no compile time; one that compiled says how much of it was that."""
    code, stdout, _ = run(capsys, "fit", scan_file, "-o", tmp_path / "a.asrbf", "--passes", "1")
    assert code == 0 and "compiling" not in stdout
    from asrbf_mesh import _fit

    clock = iter([10.0, 12.5])  # the fit's start, its end: 2.5 s compiling in between
    monkeypatch.setattr(_fit, "compile_seconds", lambda: next(clock))
    code, stdout, _ = run(capsys, "fit", scan_file, "-o", tmp_path / "b.asrbf", "--passes", "1")
    assert code == 0
    assert "of which compiling  2.50 s" in stdout
    net = am.Network.load(tmp_path / "b.asrbf")
    assert "compile_seconds" not in net.info  # a timing: not stored (same seed, same file)


def test_fit_reports_height_field_warning(capsys, syn, tmp_path: Path) -> None:
    src = tmp_path / "sphere.npy"
    np.save(src, syn.sphere_points(1500))
    code, _, err = run(capsys, "fit", src, "-o", tmp_path / "s.asrbf", "--json",
                       "--passes", "1", "--polish", "none")
    assert code == 0
    assert err.startswith("asrbf: warning: ")
    assert "not a height field" in err and "'z' axis" in err


def test_main_restores_warning_display(capsys, net_file: Path) -> None:
    def mine(*args, **kwargs) -> None:
        pass

    with warnings.catch_warnings():
        warnings.showwarning = mine
        assert main(["info", str(net_file), "--json"]) == 0
        capsys.readouterr()
        assert warnings.showwarning is mine


# ----------------------------------------------------------------------------- info


def test_info_json(capsys, net_file: Path) -> None:
    code, stdout, err = run(capsys, "info", net_file, "--json")
    assert code == 0 and err == ""
    d = json.loads(stdout)
    assert {"n_neurons", "format_version", "config", "frame", "stats", "info", "log"} <= set(d)
    net = am.Network.load(net_file)
    assert d["n_neurons"] == net.n_neurons
    assert d["format_version"] == FORMAT_VERSION
    assert d["config"] == net.config.to_dict()
    assert d["stats"]["width_max"] == pytest.approx(net.widths.max())
    assert d["info"]["n_points"] == 1600


def test_info_text(capsys, net_file: Path) -> None:
    code, stdout, _ = run(capsys, "info", net_file)
    assert code == 0
    assert f"format version {FORMAT_VERSION}" in stdout
    assert "fitted on N        1,600 points" in stdout
    assert "E-bar" in stdout and "learned with" in stdout


# ----------------------------------------------------------------------------- reconstruct


def test_reconstruct_writes_a_readable_mesh(capsys, net_file: Path, scan_file: Path,
                                            tmp_path: Path) -> None:
    out = tmp_path / "mesh.ply"
    code, stdout, err = run(capsys, "reconstruct", net_file, "-o", out, "--resolution", "41",
                            "--json")
    assert code == 0 and err == ""
    d = json.loads(stdout)
    mesh = am.load_scan(out)
    assert d == {"output": str(out), "vertices": mesh.n_points, "faces": mesh.n_faces}
    assert mesh.n_faces == 2 * (mesh.n_points // 41 - 1) * 40
    net = am.Network.load(net_file)
    np.testing.assert_allclose(mesh.points[:, 2], net.evaluate(mesh.points[:, :2]), atol=1e-9)

    fp = tmp_path / "fp.obj"
    code, stdout, _ = run(capsys, "reconstruct", net_file, "-o", fp, "--spacing", "2.0",
                          "--footprint", scan_file)
    assert code == 0
    assert stdout.startswith(f"wrote {fp}: ")
    assert am.load_scan(fp).n_faces > 0


# ----------------------------------------------------------------------------- user errors


@pytest.mark.parametrize("case", ["missing", "extension", "no_dir", "not_asrbf", "same",
                                  "bad_option"])
def test_fit_user_errors(capsys, scan_file: Path, tmp_path: Path, case: str) -> None:
    out = tmp_path / "out.asrbf"
    if case == "missing":
        argv, match = ["fit", tmp_path / "missing.xyz", "-o", out], "no such file"
    elif case == "extension":
        bad = tmp_path / "scan.foo"
        bad.write_text("1 2 3\n")
        argv, match = ["fit", bad, "-o", out], "unknown scan format '.foo'"
    elif case == "no_dir":
        out = tmp_path / "nowhere" / "out.asrbf"
        argv, match = ["fit", scan_file, "-o", out, "--passes", "1"], "does not exist"
    elif case == "not_asrbf":
        out = tmp_path / "out.ply"
        argv, match = ["fit", scan_file, "-o", out], "must end in .asrbf"
    elif case == "same":
        out = tmp_path / "scan.asrbf"
        out.write_bytes(b"precious")
        argv, match = ["fit", out, "-o", out], "unknown scan format"
    else:
        argv, match = ["fit", scan_file, "-o", out, "--gamma", "1.5"], "gamma must be a number in"
    before = sorted(p.name for p in tmp_path.iterdir())
    code, stdout, err = run(capsys, *argv)
    assert_user_error(code, stdout, err, match)
    assert sorted(p.name for p in tmp_path.iterdir()) == before  # nothing written
    if case == "same":
        assert out.read_bytes() == b"precious"


@pytest.mark.parametrize("case", ["missing", "junk", "mesh_ext", "no_dir", "same_as_footprint",
                                  "same_as_network", "resolution"])
def test_reconstruct_and_info_user_errors(capsys, net_file: Path, scan_file: Path,
                                          tmp_path: Path, case: str) -> None:
    out = tmp_path / "mesh.ply"
    if case == "missing":
        argv, match = ["reconstruct", tmp_path / "none.asrbf", "-o", out], "no such file"
    elif case == "junk":
        junk = tmp_path / "junk.asrbf"
        junk.write_bytes(b"\x00" * 100)
        argv, match = ["info", junk], "not an asrbf network file"
    elif case == "mesh_ext":
        argv, match = ["reconstruct", net_file, "-o", tmp_path / "m.xyz"], "unknown mesh format"
    elif case == "no_dir":
        argv, match = ["reconstruct", net_file, "-o", tmp_path / "no" / "m.ply"], "does not exist"
    elif case == "same_as_footprint":
        out = tmp_path / "scan.ply"
        out.write_bytes(scan_file.read_bytes())
        argv, match = (["reconstruct", net_file, "-o", out, "--footprint", out],
                       "refusing to overwrite the input file")
    elif case == "same_as_network":
        out = tmp_path / "net.asrbf"
        out.write_bytes(net_file.read_bytes())
        argv, match = ["reconstruct", out, "-o", out], "unknown mesh format '.asrbf'"
    else:
        argv, match = ["reconstruct", net_file, "-o", out, "--resolution", "1"], "resolution"
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    code, stdout, err = run(capsys, *argv)
    assert_user_error(code, stdout, err, match)
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before


def test_argparse_errors_exit_2(capsys) -> None:
    with pytest.raises(SystemExit) as info:
        main(["fit"])
    assert info.value.code == 2
    with pytest.raises(SystemExit) as info:
        main(["reconstruct", "a.asrbf", "-o", "m.ply", "--resolution", "5", "--spacing", "1"])
    assert info.value.code == 2
    with pytest.raises(SystemExit) as info:
        main(["--version"])
    assert info.value.code == 0
    assert am.__version__ in capsys.readouterr().out


# ----------------------------------------------------------------------------- determinism


def asrbf_members(path: Path) -> dict[str, bytes]:
    with zipfile.ZipFile(path) as zf:
        return {name: zf.read(name) for name in zf.namelist()}


def without_timings(members: dict[str, bytes]) -> dict:
    out: dict = dict(members)
    meta = json.loads(bytes(np.lib.format.read_array(io.BytesIO(members["meta.npy"]))).decode())
    for key in TIMING_KEYS:
        meta["info"].pop(key, None)
    out["meta.npy"] = meta
    return out


@pytest.fixture(scope="module")
def two_runs(tmp_path_factory, scan_file: Path) -> tuple[Path, Path]:
    """The same fit twice: once in-process, once as a single-threaded subprocess (``-m``)."""
    d = tmp_path_factory.mktemp("runs")
    a, b = d / "a.asrbf", d / "b.asrbf"
    args = ["fit", str(scan_file), "--seed", "11", "--passes", "1", "--json"]
    assert main([*args, "-o", str(a)]) == 0
    env = {**os.environ, "NUMBA_NUM_THREADS": "1"}
    proc = subprocess.run([sys.executable, "-m", "asrbf_mesh.cli", *args, "-o", str(b)],
                          capture_output=True, text=True, timeout=120, env=env)
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout)["n_points"] == 1600
    return a, b


def test_same_seed_gives_identical_networks(two_runs) -> None:
    a, b = two_runs
    ma, mb = asrbf_members(a), asrbf_members(b)
    assert set(ma) == set(mb)
    for name in ma:
        if name != "meta.npy":
            assert ma[name] == mb[name], name
    assert without_timings(ma) == without_timings(mb)


def test_same_seed_gives_byte_identical_file(two_runs) -> None:
    """Determinism: the same seed gives a byte-identical .asrbf file."""
    a, b = two_runs
    assert a.read_bytes() == b.read_bytes()


def test_console_script_runs(net_file: Path) -> None:
    script = Path(sys.executable).parent / "asrbf"
    if not script.exists():
        pytest.skip("the asrbf console script is not installed next to the interpreter")
    proc = subprocess.run([str(script), "info", str(net_file), "--json"], capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout)["format_version"] == FORMAT_VERSION
    bad = subprocess.run([str(script), "info", str(net_file) + ".missing"],
                         capture_output=True, text=True, timeout=120)
    assert bad.returncode == 2
    assert bad.stderr.startswith("asrbf: error: ") and len(bad.stderr.splitlines()) == 1


# ----------------------------------------------------------------------------- demo (slow)


@pytest.mark.slow
def test_demo_on_the_face_map(capsys, tmp_path: Path) -> None:
    out = tmp_path / "demo"
    code, stdout, _ = run(capsys, "demo", "-o", out)
    assert code == 0
    assert {"face.asrbf", "face_footprint.ply", "face_full.ply"} <= {
        p.name for p in out.iterdir()}
    net = am.Network.load(out / "face.asrbf")
    # measured: N = 85,849, K = 727, E-bar 0.0023 (sequential 0.0027)
    assert net.info["n_points"] == 85_849
    assert net.info["ebar"] < 0.004
    assert net.compression_ratio() > 40
    fp = am.load_scan(out / "face_footprint.ply")
    full = am.load_scan(out / "face_full.ply")
    assert 0 < fp.n_faces < full.n_faces
    assert "face range map" in stdout


def test_errors_name_parameters_by_their_flags(tmp_path, capsys) -> None:
    """A bad option is named the way it was typed (--max-hole-size), not by its Python name."""
    from asrbf_mesh.cli import main

    scan = tmp_path / "s.xyz"
    scan.write_text("".join(f"{x} {y} {x * y}\n" for x in range(5) for y in range(5)))
    assert main(["fill-holes", str(scan), "-o", str(tmp_path / "o.ply"),
                 "--max-hole-size", "inf"]) == 2
    assert capsys.readouterr().err.startswith("asrbf: error: --max-hole-size must be")
    assert main(["fit", str(scan), "-o", str(tmp_path / "n.asrbf"), "--seed", "-1"]) == 2
    assert capsys.readouterr().err == "asrbf: error: --seed must be an integer >= 0, got -1\n"
