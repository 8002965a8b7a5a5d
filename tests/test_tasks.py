"""The task layer (asrbf_mesh.tasks) and the command-line defects fixed with it.

Every task returns the dict ``asrbf <command> --json`` prints; bad options raise
ConfigError naming the option; folder outputs appear whole or not at all, also when the
command is interrupted (SIGINT: one line ``asrbf: interrupted``, exit 130).
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import asrbf_mesh as am
from asrbf_mesh import tasks
from asrbf_mesh._atomic import atomic_dir
from asrbf_mesh._config import FitConfig
from asrbf_mesh._frame import Frame
from asrbf_mesh.cli import main
from asrbf_mesh.errors import AsrbfError, ConfigError


def grid_scan(n: int, *, hole: bool = False) -> am.Mesh:
    """A regular ``n x n`` range grid of a smooth surface, as a mesh (spacing 1)."""
    yy, xx = np.mgrid[0:n, 0:n].astype(float)
    z = 3 * np.sin(xx / 7) * np.cos(yy / 9)
    keep = np.ones((n, n), bool) if not hole else (xx - n / 2) ** 2 + (yy - n / 2) ** 2 > 9
    idx = -np.ones((n, n), int)
    idx[keep] = np.arange(keep.sum())
    a, b = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel()
    c, d = idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    faces = np.concatenate([np.c_[a, b, d], np.c_[a, d, c]])
    faces = faces[(faces >= 0).all(axis=1)]
    return am.Mesh(np.c_[xx[keep], yy[keep], z[keep]], faces)


@pytest.fixture(scope="module")
def scan(tmp_path_factory) -> Path:
    return am.save_mesh(grid_scan(33, hole=True), tmp_path_factory.mktemp("scan") / "g.ply")


@pytest.fixture(scope="module")
def net(tmp_path_factory, scan: Path) -> Path:
    out = tmp_path_factory.mktemp("net") / "g.asrbf"
    tasks.fit(scan, out, passes=1, progress=False)
    return out


def run(capsys, *argv) -> tuple[int, str, str]:
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def one_error(code: int, out: str, err: str) -> str:
    assert code == 2, err
    assert out == ""
    lines = err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("asrbf: error: "), err
    return lines[0]


def strict(text: str):
    def refuse(token: str):
        raise AssertionError(f"not strict JSON: {token}")

    return json.loads(text, parse_constant=refuse)


# ----------------------------------------------------------------------------- the layer


def test_tasks_return_what_json_prints(capsys, scan: Path, net: Path, tmp_path: Path) -> None:
    d = tasks.info(net)
    code, out, _ = run(capsys, "info", net, "--json")
    assert code == 0 and strict(out) == d
    r = tasks.reconstruct(net, tmp_path / "m.ply", resolution=21)
    assert r == {"output": str(tmp_path / "m.ply"), "vertices": 21 * 21,
                 "faces": 2 * 20 * 20}


def test_import_and_help_load_no_evaluation_libraries() -> None:
    code = ("import sys, contextlib, io\n"
            "import asrbf_mesh.tasks\n"
            "from asrbf_mesh.cli import main\n"
            "with contextlib.redirect_stdout(io.StringIO()), contextlib.suppress(SystemExit):\n"
            "    main(['--help'])\n"
            "print(sorted(m for m in sys.modules if m.split('.')[0] in "
            "('pymeshlab', 'matplotlib')))\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[]"


def test_check_options() -> None:
    assert tasks.check_options("lod", levels=3) == {"levels": 3}
    with pytest.raises(ConfigError, match="levels must be an integer in"):
        tasks.check_options("lod", levels=13)
    with pytest.raises(ConfigError, match="colour is not an option of lod"):
        tasks.check_options("lod", colour="red")
    with pytest.raises(ConfigError, match="gamma"):
        tasks.check_options("fit", gamma=1.5)
    with pytest.raises(ConfigError, match="blend"):
        tasks.check_options("fill-holes", blend="cubic")


# ----------------------------------------------------------------------------- seed < 0


@pytest.mark.parametrize("command", ["fit", "fill-holes", "lod", "metro", "compare"])
def test_negative_seed_is_one_line(capsys, scan: Path, tmp_path: Path, command: str) -> None:
    """Was a traceback (numpy's default_rng(-1))."""
    argv = {"fit": ["fit", scan, "-o", tmp_path / "n.asrbf"],
            "fill-holes": ["fill-holes", scan, "-o", tmp_path / "f.ply"],
            "lod": ["lod", scan, "-o", tmp_path / "lod"],
            "metro": ["metro", scan, scan],
            "compare": ["compare", scan, "-o", tmp_path / "cmp"]}[command]
    line = one_error(*run(capsys, *argv, "--seed", "-1"))
    assert "seed must be an integer >= 0" in line
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(ConfigError, match="seed must be an integer >= 0"):
        tasks.fit(scan, tmp_path / "n.asrbf", seed=-1)


# ----------------------------------------------------------------------------- lod levels


def test_lod_refuses_absurd_levels_at_once(capsys, scan: Path, tmp_path: Path) -> None:
    """--levels 1000000000 ran 90 s into an OverflowError."""
    t0 = time.perf_counter()
    line = one_error(*run(capsys, "lod", scan, "-o", tmp_path / "lod", "--levels",
                          "1000000000"))
    assert "levels must be an integer in [1, 12]" in line
    assert time.perf_counter() - t0 < 5
    assert list(tmp_path.iterdir()) == []


def test_lod_refuses_levels_coarser_than_the_scan(capsys, tmp_path: Path) -> None:
    """A 65 x 65 grid: level i samples the short side at 64 / 2**i + 1 points; 4 needed."""
    src = am.save_mesh(grid_scan(65), tmp_path / "g.ply")
    t0 = time.perf_counter()
    line = one_error(*run(capsys, "lod", src, "-o", tmp_path / "lod", "--levels", "6",
                          "--no-metro"))
    assert "levels must be at most 5 for this scan" in line and "levels=6" in line
    assert time.perf_counter() - t0 < 5  # refused before the fit
    assert not (tmp_path / "lod").exists()
    d = tasks.lod(src, tmp_path / "lod", levels=5, metro=False)
    assert [lv["index"] for lv in d["levels"]] == [0, 1, 2, 3, 4]
    with pytest.raises(ConfigError, match="at most"):
        tasks.lod(src, tmp_path / "lod", levels=6, method="refit")


# ----------------------------------------------------------------------------- folders


def test_a_rerun_replaces_the_previous_folder(scan: Path, tmp_path: Path) -> None:
    out = tmp_path / "lod"
    tasks.lod(scan, out, levels=3, metro=False)
    assert (out / "level_2.ply").exists()
    tasks.lod(scan, out, levels=2, metro=False)
    assert not (out / "level_2.ply").exists()  # stale file of the earlier run gone
    assert json.loads((out / "manifest.json").read_text())["levels"][-1]["index"] == 1
    assert [p.name for p in tmp_path.iterdir()] == ["lod"]  # no temporary folder left


def test_a_folder_with_other_files_keeps_them(scan: Path, tmp_path: Path) -> None:
    out = tmp_path / "mine"
    out.mkdir()
    (out / "notes.txt").write_text("keep me")
    (out / "level_0.ply").write_text("old")
    tasks.lod(scan, out, levels=2, metro=False)
    assert (out / "notes.txt").read_text() == "keep me"
    assert am.load_scan(out / "level_0.ply").n_faces > 0
    assert [p.name for p in tmp_path.iterdir()] == ["mine"]


def test_atomic_dir_removes_everything_on_failure(tmp_path: Path) -> None:
    out = tmp_path / "a" / "b" / "out"
    with pytest.raises(RuntimeError), atomic_dir(out) as tmp:
        (tmp / "half.ply").write_text("half")
        raise RuntimeError
    assert list(tmp_path.iterdir()) == []  # the parents it made are gone too
    with atomic_dir(out) as tmp:
        assert tmp.parent == out.parent and tmp.name.startswith(".out.tmp-")
        (tmp / "x").write_text("x")
    assert (out / "x").read_text() == "x"
    (tmp_path / "file").write_text("")
    with pytest.raises(AsrbfError, match="not a folder"), atomic_dir(tmp_path / "file"):
        pass


CHILD = r"""
import os, sys, time
real = os.replace
def slow(src, dst, *args, **kwargs):
    real(src, dst, *args, **kwargs)
    if ".tmp-" in os.path.basename(os.path.dirname(os.fspath(dst))):  # a file in the folder
        print("writing", flush=True)
        time.sleep(120)
os.replace = slow
from asrbf_mesh.cli import main
sys.exit(main(sys.argv[1:]))
"""


def default_sigint() -> None:
    """A shell's SIGINT in the child (a native library may have left the parent's ignored)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def interrupt(argv: list[str], out: Path, *, child: str | None = CHILD) -> tuple[int, str]:
    """Run ``asrbf argv``; SIGINT once its temporary folder exists (and, with the slowed
    child, once it has written a file there)."""
    cmd = [sys.executable, "-c", child, *argv] if child else [
        sys.executable, "-m", "asrbf_mesh.cli", *argv]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=default_sigint)
    try:
        if child:
            assert proc.stdout.readline() == "writing\n", proc.stderr.read()
        deadline = time.monotonic() + 120
        while not list(out.parent.glob(f".{out.name}.tmp-*")):
            assert proc.poll() is None, proc.communicate()
            assert time.monotonic() < deadline
            time.sleep(0.005)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=120)
    finally:
        proc.kill()
    return proc.returncode, err


@pytest.mark.parametrize("command", ["lod", "compare", "report"])
def test_ctrl_c_leaves_no_partial_folder(scan: Path, net: Path, tmp_path: Path,
                                         command: str) -> None:
    out = tmp_path / "out"
    if command == "report":
        tasks.compare(scan, tmp_path / "cmp", network=net, meshes=False, som_iterations=200,
                      progress=False)
    argv = {"lod": ["lod", str(scan), "-o", str(out), "--levels", "2"],
            "compare": ["compare", str(scan), "--network", str(net), "-o", str(out),
                        "--som-iterations", "200"],
            "report": ["report", str(tmp_path / "cmp"), "-o", str(out)]}[command]
    before = sorted(p.name for p in tmp_path.iterdir())
    code, err = interrupt(argv, out)
    assert code == 130, err
    assert err.splitlines() == ["asrbf: interrupted"]
    assert sorted(p.name for p in tmp_path.iterdir()) == before  # no out, no .out.tmp-*


def test_ctrl_c_in_numba_code(tmp_path: Path) -> None:
    """An interrupt inside a numba kernel surfaces as SystemError; still one line, 130."""
    src = am.save_mesh(grid_scan(300), tmp_path / "big.ply")
    out = tmp_path / "lod"
    code, err = interrupt(["lod", str(src), "-o", str(out), "--levels", "2", "--method",
                           "refit"], out, child=None)
    assert code == 130, err
    assert err.splitlines() == ["asrbf: interrupted"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["big.ply"]


def test_interrupt_wrapped_by_numba_maps_to_130(capsys, monkeypatch, net: Path) -> None:
    def kernel(*args, **kwargs):
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as exc:
            raise SystemError("CPUDispatcher(<function learn>) returned a result with an "
                              "exception set") from exc

    monkeypatch.setitem(tasks.COMMANDS, "info", kernel)
    code, out, err = run(capsys, "info", net)
    assert (code, out, err) == (130, "", "asrbf: interrupted\n")


# ----------------------------------------------------------------------------- info NaN


def test_info_of_an_empty_network_is_strict_json(capsys, tmp_path: Path) -> None:
    empty = am.Network(0.0, np.zeros((0, 2)), np.zeros(0), np.zeros(0),
                       Frame(np.eye(3), np.zeros(3), np.ones(3)), FitConfig(),
                       info={"n_points": 10, "ebar": float("nan")})
    path = empty.save(tmp_path / "empty.asrbf")
    code, out, err = run(capsys, "info", path, "--json")
    assert code == 0, err
    d = strict(out)  # was a bare NaN
    assert d["n_neurons"] == 0 and d["stats"]["width_max"] is None
    code, out, _ = run(capsys, "info", path)
    assert code == 0
    assert "nan" not in out.lower() and "n/a" in out


# ----------------------------------------------------------------------------- report


def test_report_counts_a_scan_once(capsys, scan: Path, net: Path, tmp_path: Path) -> None:
    cmp = tmp_path / "cmp"
    tasks.compare(scan, cmp, network=net, meshes=False, som_iterations=200, progress=False)
    code, out, err = run(capsys, "report", cmp, cmp / "compare.json", f"{cmp}/", "-o",
                         tmp_path / "rep", "--json")
    assert code == 0
    assert len(strict(out)["scans"]) == 1  # was 3
    lines = err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("asrbf: warning: report: counted once")


# ----------------------------------------------------------------------------- ignored options


@pytest.mark.parametrize(("argv", "match"), [
    (["fit", "{scan}", "-o", "{tmp}/n.asrbf", "--chunk", "8192"], "chunk applies to a streamed"),
    (["fit", "{scan}", "-o", "{tmp}/n.asrbf", "--mix", "4"], "mix applies to a streamed"),
    (["reconstruct", "{net}", "-o", "{tmp}/m.ply", "--mode", "hull", "--footprint", "{scan}",
      "--margin", "0.1"], "margin applies to mode full only: mode hull"),
    (["reconstruct", "{net}", "-o", "{tmp}/m.ply", "--footprint", "{scan}", "--margin", "0.1"],
     "margin applies to mode full only: mode surface"),
])
def test_options_that_would_be_ignored_are_refused(capsys, scan: Path, net: Path,
                                                   tmp_path: Path, argv, match) -> None:
    argv = [a.format(scan=scan, net=net, tmp=tmp_path) for a in argv]
    line = one_error(*run(capsys, *argv))
    assert match in line
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(("options", "match"), [
    (["--spacing", "0"], "spacing must be a finite number > 0.0, got 0.0"),
    (["--spacing", "1e-6"], "raise spacing or lower resolution"),
    (["--margin", "20"], "margin must be a finite number >= 0.0 and < 10.0, got 20.0"),
    (["--margin", "-1"], "margin must be"),
])
def test_reconstruct_errors_name_the_options(capsys, net: Path, tmp_path: Path, options,
                                             match) -> None:
    line = one_error(*run(capsys, "reconstruct", net, "-o", tmp_path / "m.ply", *options))
    assert match in line
    assert "spacing_abs" not in line and "margin_rel" not in line


def test_stream_still_takes_chunk_and_mix(capsys, tmp_path: Path) -> None:
    pts = grid_scan(40).vertices
    src = tmp_path / "p.npy"
    np.save(src, pts)
    code, out, err = run(capsys, "fit", src, "-o", tmp_path / "n.asrbf", "--stream",
                         "--chunk", "8192", "--mix", "2", "--passes", "1", "--json")
    assert code == 0, err
    assert strict(out)["n_points"] == len(pts)
    assert os.path.exists(tmp_path / "n.asrbf")
