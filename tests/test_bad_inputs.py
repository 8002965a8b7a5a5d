"""Bad inputs: every command that reads files, and the library, on broken and odd files.

The matrix is ``(command slot, input case)``; a *slot* is one file argument of one
command (``metro/reference`` is the second file of ``asrbf metro``). For every bad input
the command must print exactly one line, ``asrbf: error: <file>: <problem>``, exit with
code 2, and leave the folder as it was: no output, no temporary file, inputs untouched.
The library raises an :class:`~asrbf_mesh.errors.AsrbfError` subclass with the same
line. Valid-but-odd inputs (duplicates, a sphere, a flat or rescaled scan) must work,
with an ``asrbf: warning:`` line where the data deserves one.

Scale and shift invariance (the fit learns in the unit cube): scaling by 1e12 or 1e-12
rounds each coordinate relatively by 1e-16, so the same seed must give the same K and
surfaces equal to ~1e-12 in unit-cube units. A shift by 1e12 is tested on a scan whose
coordinates are multiples of 2**-10 mm (1/1024 mm, finer than a range scanner's
precision): there ``x + 1e12`` needs 50 of float64's 53 bits, so the shifted file holds
exactly the same scan and the normalization (which subtracts the offset before anything
else) must give the same network bit for bit. A shift of unquantized data would round
every coordinate by up to 6e-5 mm (float64 spacing at 1e12 is 2**-13): a perturbation
of ~3e-6 of the depth range that can legitimately flip one of the learner's threshold
decisions, so it would not test invariance, only luck.

``scripts/bad_inputs_table.py`` runs :data:`CLI_MATRIX` through :func:`run_case` to
print the README's troubleshooting table.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import shutil
import stat
import warnings
import zipfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import plyfile
import pytest

import asrbf_mesh as am
from asrbf_mesh.cli import main
from asrbf_mesh.errors import AsrbfError, NetworkFileError, ScanError
from asrbf_mesh.evaluate._report import load_compare

GRID = 16  # 256 points: every fit here takes milliseconds
QUANTUM = 2.0**-10  # coordinates are multiples of this (see the module docstring)


# ============================================================================ valid inputs


def scan_points(n: int = GRID) -> np.ndarray:
    """(n*n, 3) points of Franke's function in mm on a jittered grid, row by row.

    x in [100, 180], y in [20, 80], z in about [5, 30]; multiples of :data:`QUANTUM`.
    """
    g = (np.arange(n) + 0.5) / n
    u, v = (a.ravel() for a in np.meshgrid(g, g))
    jitter = np.random.default_rng(0).uniform(-0.3, 0.3, (2, n * n)) / n
    u, v = np.clip(u + jitter[0], 0, 1), np.clip(v + jitter[1], 0, 1)
    x, y = 9 * u, 9 * v
    franke = (0.75 * np.exp(-((x - 2) ** 2 + (y - 2) ** 2) / 4)
              + 0.75 * np.exp(-((x + 1) ** 2) / 49 - (y + 1) / 10)
              + 0.5 * np.exp(-((x - 7) ** 2 + (y - 3) ** 2) / 4)
              - 0.2 * np.exp(-((x - 4) ** 2) - (y - 7) ** 2))
    pts = np.c_[100 + 80 * u, 20 + 60 * v, 5 + 20 * franke]
    return np.round(pts / QUANTUM) * QUANTUM


def sphere_points(n: int = 400) -> np.ndarray:
    """Points all over a sphere of radius 30 mm: not a height field along any axis."""
    p = np.random.default_rng(0).normal(size=(n, 3))
    return 30 * p / np.linalg.norm(p, axis=1, keepdims=True) + [140.0, 50.0, 10.0]


def grid_faces(n: int = GRID) -> np.ndarray:
    """Two triangles per cell of the ``n x n`` grid of :func:`scan_points`."""
    idx = np.arange(n * n).reshape(n, n)
    a, b = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel()
    c, d = idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    return np.concatenate([np.c_[a, b, d], np.c_[a, d, c]])


@dataclass(frozen=True)
class Env:
    """The valid files of one run, all inside ``root`` (the folder that must not change)."""

    root: Path
    scan: Path  # binary PLY range grid with faces (256 points)
    cloud: Path  # the same points, no faces (XYZ)
    net: Path  # network fitted to ``scan`` (seed 0, one pass)
    script: Path  # an empty filter script: load, then save
    compare: Path  # an ``asrbf compare`` output folder (for ``asrbf report``)


def build_valid(root: Path) -> Env:
    """Write the valid inputs into ``root`` (a fit and a small comparison run here)."""
    root.mkdir(parents=True, exist_ok=True)
    scan = am.save_mesh(am.Mesh(scan_points(), grid_faces()), root / "scan.ply")
    cloud = root / "cloud.xyz"
    np.savetxt(cloud, scan_points(), fmt="%.17g")
    net = root / "net.asrbf"
    script = root / "script.json"
    script.write_text("[]\n")
    compare = root / "cmp"
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        assert main(["fit", str(scan), "-o", str(net), "--passes", "1", "--json"]) == 0
        assert main(["compare", str(scan), "--network", str(net), "-o", str(compare),
                     "--no-meshes", "--som-iterations", "10", "--json"]) == 0
    return Env(root, scan, cloud, net, script, compare)


def copy_env(env: Env, root: Path) -> Env:
    """A private copy of ``env`` in ``root``."""
    shutil.copytree(env.root, root)
    return Env(root, *(root / p.relative_to(env.root)
                       for p in (env.scan, env.cloud, env.net, env.script, env.compare)))


# ============================================================================ bad inputs
#
# A case builder writes one input into the folder and returns its path.


def _text(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def _folder(path: Path) -> Path:
    path.mkdir()
    return path


def _bytes(path: Path, data: bytes) -> Path:
    path.write_bytes(data)
    return path


def _xyz(path: Path, points: np.ndarray) -> Path:
    np.savetxt(path, points, fmt="%.17g")
    return path


def _ply(env: Env, name: str, edit: Callable[[bytes], bytes]) -> Path:
    path = env.root / name
    path.write_bytes(edit(env.scan.read_bytes()))
    return path


def _header_count(data: bytes, element: str, count: int) -> bytes:
    """Rewrite ``element <name> <n>`` in a PLY header."""
    head, sep, body = data.partition(b"end_header\n")
    lines = [(f"element {element} {count}".encode() if ln.startswith(f"element {element} "
                                                                       .encode()) else ln)
             for ln in head.split(b"\n")]
    return b"\n".join(lines) + sep + body


def _faces_out_of_range(env: Env) -> Path:
    vertex = np.empty(GRID * GRID, dtype=[("x", "<f8"), ("y", "<f8"), ("z", "<f8")])
    for i, c in enumerate("xyz"):
        vertex[c] = scan_points()[:, i]
    faces = np.empty(3, dtype=[("vertex_indices", "O")])
    faces["vertex_indices"] = [np.array(f, dtype=np.int32) for f in
                               ([0, 1, 17], [0, 17, 999], [1, 2, -5])]
    path = env.root / "faces.ply"
    plyfile.PlyData([plyfile.PlyElement.describe(vertex, "vertex"),
                     plyfile.PlyElement.describe(faces, "face")], text=False).write(str(path))
    return path


def _with_bad_token(env: Env) -> Path:
    lines = [" ".join(f"{v:.17g}" for v in p) for p in scan_points()[:40]]
    lines.insert(30, "101.5 47.25 abc")
    return _text(env.root / "tokens.xyz", "\n".join(lines) + "\n")


def _non_finite(env: Env, value: str) -> Path:
    lines = [" ".join(f"{v:.17g}" for v in p) for p in scan_points()]
    lines[7] = f"101.5 {value} 12.0"
    return _text(env.root / f"{value}.xyz", "\n".join(lines) + "\n")


def _npy(path: Path, array: np.ndarray) -> Path:
    np.save(path, array)
    return path


def _collinear(env: Env) -> Path:
    t = np.linspace(0.0, 80.0, 60)
    return _xyz(env.root / "line.xyz", np.c_[100 + t, 20 + 0.75 * t, 5 + np.sin(t / 9)])


def _zero_extent(env: Env, axis: int) -> Path:
    pts = scan_points()
    pts[:, axis] = 42.0
    return _xyz(env.root / f"zero_{'xy'[axis]}.xyz", pts)


SCAN_CASES: dict[str, Callable[[Env], Path]] = {
    "missing": lambda e: e.root / "missing.ply",
    "directory": lambda e: _folder(e.root / "folder.ply"),
    "empty file": lambda e: _text(e.root / "empty.xyz", ""),
    "zero-byte PLY": lambda e: _text(e.root / "empty.ply", ""),
    "truncated PLY": lambda e: _ply(e, "truncated.ply", lambda b: b[: len(b) * 2 // 3]),
    "PLY header: more vertices": lambda e: _ply(
        e, "more.ply", lambda b: _header_count(b, "vertex", 100_000)),
    "PLY header: fewer faces": lambda e: _ply(
        e, "fewer.ply", lambda b: _header_count(b, "face", 100)),
    "unknown extension": lambda e: _text(e.root / "scan.abc", "1 2 3\n"),
    "non-numeric token": _with_bad_token,
    "binary point list": lambda e: _bytes(e.root / "binary.pts",
                                          scan_points().astype("<f8").tobytes()),
    "NPY with 4 columns": lambda e: _npy(e.root / "four.npy",
                                         np.c_[scan_points(), np.ones(len(scan_points()))]),
    "NaN coordinate": lambda e: _non_finite(e, "nan"),
    "inf coordinate": lambda e: _non_finite(e, "inf"),
    "1 point": lambda e: _text(e.root / "one.xyz", "100 20 5\n"),
    "3 points": lambda e: _text(e.root / "three.xyz", "100 20 5\n180 20 6\n100 80 7\n"),
    "identical points": lambda e: _xyz(e.root / "same.xyz", np.tile([140.0, 50, 10], (50, 1))),
    "collinear points": _collinear,
    "zero x extent": lambda e: _zero_extent(e, 0),
    "zero y extent": lambda e: _zero_extent(e, 1),
    "faces out of range": _faces_out_of_range,
    "point cloud": lambda e: e.cloud,  # valid, except where a mesh is required
}

#: What each scan case's one line says after ``<file>: ``.
SCAN_MESSAGES = {
    "missing": "no such file",
    "directory": "is a directory, not a scan file",
    "empty file": "empty file (0 bytes)",
    "zero-byte PLY": "empty file (0 bytes)",
    "truncated PLY": ("cannot read PLY: element 'face': row 137: early end-of-file: the "
                      "header announces 450 'face' rows (file truncated, or the header's "
                      "counts are wrong)"),
    "PLY header: more vertices": ("cannot read PLY: element 'vertex': row 499: early "
                                  "end-of-file: the header announces 100000 'vertex' rows"),
    "PLY header: fewer faces": "the header's counts do not match the data",
    "unknown extension": "unknown scan format '.abc'",
    "non-numeric token": "cannot read XYZ: line 31: 'abc' is not a number",
    "binary point list": "cannot read PTS: not a text point file (binary data)",
    "NPY with 4 columns": ("cannot read NPY: array has shape (256, 4), expected (N, 3): one "
                           "x, y, z row per point (save only those columns, e.g. "
                           "np.save(path, a[:, :3]))"),
    "NaN coordinate": "1 point has NaN or infinite coordinates",
    "inf coordinate": "1 point has NaN or infinite coordinates",
    "1 point": "only 1 point, at least 10 needed",
    "3 points": "only 3 points, at least 10 needed",
    "identical points": "all 50 points are identical",
    "collinear points": "all points lie on one line in (x, y)",
    "zero x extent": "all points share the same x (zero x extent)",
    "zero y extent": "all points share the same y (zero y extent)",
    "faces out of range": "cannot read PLY: 2 faces reference vertices outside [0, 256)",
    "point cloud": "",
}

#: Cases about the points' layout: a height field needs them, a mesh filter does not.
GEOMETRY_CASES = ("1 point", "3 points", "identical points", "collinear points",
                  "zero x extent", "zero y extent")


def _net_member(env: Env, name: str, edit: Callable[[dict[str, bytes]], None]) -> Path:
    with zipfile.ZipFile(env.net) as zf:
        members = {m: zf.read(m) for m in zf.namelist()}
    edit(members)
    path = env.root / name
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as zf:
        for m, data in members.items():
            zf.writestr(m, data)
    return path


def _meta(members: dict[str, bytes], **changes: object) -> None:
    meta = json.loads(bytes(np.lib.format.read_array(io.BytesIO(members["meta.npy"]))).decode())
    meta.update(changes)
    buf = io.BytesIO()
    np.lib.format.write_array(buf, np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8))
    members["meta.npy"] = buf.getvalue()


def _nan_weights(members: dict[str, bytes]) -> None:
    weights = np.lib.format.read_array(io.BytesIO(members["weights.npy"])).copy()
    weights[0] = np.nan
    buf = io.BytesIO()
    np.lib.format.write_array(buf, weights)
    members["weights.npy"] = buf.getvalue()


def _damaged(env: Env) -> Path:
    data = bytearray(env.net.read_bytes())
    with zipfile.ZipFile(env.net) as zf:
        info = zf.getinfo("centers.npy")
    start = info.header_offset + 30 + len(info.filename)  # the compressed data
    data[start: start + 16] = bytes(16)
    path = env.root / "damaged.asrbf"
    path.write_bytes(bytes(data))
    return path


def _plain_npz(env: Env) -> Path:
    path = env.root / "plain.asrbf"
    with open(path, "wb") as fh:
        np.savez(fh, centers=np.zeros((3, 2)), widths=np.ones(3))
    return path


def _foreign_zip(env: Env) -> Path:
    path = env.root / "foreign.asrbf"
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("readme.txt", "not a network")
    return path


NETWORK_CASES: dict[str, Callable[[Env], Path]] = {
    "missing": lambda e: e.root / "missing.asrbf",
    "directory": lambda e: _folder(e.root / "folder.asrbf"),
    "empty file": lambda e: _text(e.root / "empty.asrbf", ""),
    "truncated": lambda e: _bytes(e.root / "cut.asrbf", e.net.read_bytes()[:600]),
    "damaged member": _damaged,
    "format version 99": lambda e: _net_member(e, "v99.asrbf", lambda m: _meta(
        m, format_version=99)),
    "NaN parameter": lambda e: _net_member(e, "nan.asrbf", _nan_weights),
    "plain .npz": _plain_npz,
    "zip of something else": _foreign_zip,
    "scan given as network": lambda e: e.scan,
}

NETWORK_MESSAGES = {
    "missing": "no such file",
    "directory": "is a directory, not a network file",
    "empty file": "not an asrbf network file (empty file, 0 bytes)",
    "truncated": "corrupt or truncated network file (the zip archive is damaged)",
    "damaged member": "corrupt network file (",
    "format version 99": ("network file format version 99 is not supported (this "
                          "asrbf-mesh reads versions 1, 2)"),
    "NaN parameter": "corrupt network file (network parameters must be finite)",
    "plain .npz": "not an asrbf network file (no metadata)",
    "zip of something else": "not an asrbf network file (no metadata)",
    "scan given as network": "not an asrbf network file (not a zip archive)",
}


def _compare_json(env: Env, name: str, text: str) -> Path:
    folder = env.root / name
    folder.mkdir()
    (folder / "compare.json").write_text(text)
    return folder


def _without(env: Env, key: str) -> Path:
    d = json.loads((env.compare / "compare.json").read_text())
    del d[key]
    return _compare_json(env, f"no_{key}", json.dumps(d))


REPORT_CASES: dict[str, Callable[[Env], Path]] = {
    "missing": lambda e: e.root / "missing",
    "folder without compare.json": lambda e: _folder(e.root / "nothing"),
    "empty file": lambda e: _compare_json(e, "empty", ""),
    "invalid JSON": lambda e: _compare_json(e, "broken", '{"scan": '),
    "foreign JSON": lambda e: _compare_json(e, "list", "[1, 2, 3]"),
    "missing figure": lambda e: _without(e, "n_points"),
}

REPORT_MESSAGES = {
    "missing": "no such file (run `asrbf compare` first)",
    "folder without compare.json": "compare.json: no such file (run `asrbf compare` first)",
    "empty file": "compare.json: not a compare.json (empty file)",
    "invalid JSON": "compare.json: not a compare.json (invalid JSON: ",
    "foreign JSON": "compare.json: not a compare.json (keys scan, asrbf, som missing)",
    "missing figure": "compare.json: not a compare.json (n_points is missing or not a number)",
}

SCRIPT_CASES: dict[str, Callable[[Env], Path]] = {
    "missing": lambda e: e.root / "missing.json",
    "directory": lambda e: _folder(e.root / "folder.json"),
    "empty file": lambda e: _text(e.root / "empty.json", ""),
    "invalid JSON": lambda e: _text(e.root / "broken.json", '[{"filter": '),
    "not a list of steps": lambda e: _text(e.root / "dict.json", '{"filter": "x"}'),
}

SCRIPT_MESSAGES = {
    "missing": "no such file",
    "directory": "not a file",
    "empty file": "not a JSON filter script (Expecting value",
    "invalid JSON": "not a JSON filter script (",
    "not a list of steps": "a script must be a JSON list of steps, got dict",
}


# ============================================================================ command slots
#
# A slot builds the argv of one command with the input under test in one position;
# outputs go to ``<root>/out*`` so that "nothing written" is a plain folder comparison.


def _p(*parts: object) -> list[str]:
    return [str(p) for p in parts]


SCAN_SLOTS: dict[str, Callable[[Env, Path], list[str]]] = {
    "fit": lambda e, x: _p("fit", x, "-o", e.root / "out.asrbf", "--passes", "1"),
    "reconstruct/footprint": lambda e, x: _p("reconstruct", e.net, "--footprint", x, "-o",
                                             e.root / "out.ply", "--resolution", "20"),
    "fill-holes": lambda e, x: _p("fill-holes", x, "--network", e.net, "-o",
                                  e.root / "out.ply"),
    "lod": lambda e, x: _p("lod", x, "-o", e.root / "out", "--levels", "2", "--no-metro"),
    "metro/mesh": lambda e, x: _p("metro", x, e.scan, "--error-mesh", e.root / "out.ply"),
    "metro/reference": lambda e, x: _p("metro", e.scan, x, "--samples-out", e.root / "out.npz"),
    "compare": lambda e, x: _p("compare", x, "--network", e.net, "-o", e.root / "out",
                               "--no-meshes", "--som-iterations", "10"),
    "filter-script/input": lambda e, x: _p("filter-script", e.script, x, "-o",
                                           e.root / "out.ply"),
}

NETWORK_SLOTS: dict[str, Callable[[Env, Path], list[str]]] = {
    "info": lambda e, x: _p("info", x),
    "reconstruct": lambda e, x: _p("reconstruct", x, "-o", e.root / "out.ply",
                                   "--resolution", "20"),
    "fill-holes/network": lambda e, x: _p("fill-holes", e.scan, "--network", x, "-o",
                                          e.root / "out.ply"),
    "compare/network": lambda e, x: _p("compare", e.scan, "--network", x, "-o",
                                       e.root / "out", "--no-meshes"),
}

#: pymeshlab loads the filter-script input; these are its own one-line reasons.
FILTER_SCRIPT_MESSAGES = {
    "directory": "not a file",
    "zero-byte PLY": "cannot load (",  # ... Eof in header)
    "truncated PLY": "cannot load (",  # ... Unexpected EOF)
    "PLY header: more vertices": "cannot load (",
    "unknown extension": "cannot load (Unknown format for load: abc)",
    "NPY with 4 columns": "cannot load (Unknown format for load: npy)",
    "faces out of range": "cannot load (",  # ... Bad vertex index in face)
}


@dataclass(frozen=True)
class Case:
    """One row of the matrix: a command slot, an input case, and what must happen."""

    slot: str
    case: str
    make: Callable[[Env], Path]  # writes the input under test
    argv: Callable[[Env, Path], list[str]]
    message: str | None  # expected text after "<file>: "; None: the command succeeds
    warning: str | None = None  # expected warning on success
    output: str | None = None  # file or folder that must exist on success (below root)
    kind: str = "scan"  # what the input under test is (for the README table)

    @property
    def id(self) -> str:
        return f"{self.slot}: {self.case}"


def _scan_rows() -> list[Case]:
    rows = []
    for slot, argv in SCAN_SLOTS.items():
        for case, make in SCAN_CASES.items():
            message: str | None = SCAN_MESSAGES[case]
            if slot == "filter-script/input":
                if case in GEOMETRY_CASES:
                    continue  # a mesh filter takes any shape
                message = FILTER_SCRIPT_MESSAGES.get(case, message)
            if slot.startswith("metro/") and case in GEOMETRY_CASES:
                # Metro fits nothing: any mesh with a face, any reference with a point
                message = ("is a point set without faces; it must be a mesh"
                           if slot == "metro/mesh" else None)
                if message is None:
                    continue
            if case == "point cloud":
                if slot == "compare":
                    message = "compare needs a scan with faces"
                elif slot == "metro/mesh":
                    message = "is a point set without faces; it must be a mesh"
                else:
                    continue  # a point cloud is a valid scan
            rows.append(Case(slot, case, make, argv, message))
    rows.append(Case("metro/reference (--error-mesh)", "point cloud", lambda e: e.cloud,
                     lambda e, x: _p("metro", e.scan, x, "--error-mesh", e.root / "out.ply"),
                     "a point cloud without faces; --error-mesh needs a mesh reference"))
    return rows


def _odd(name: str, points: Callable[[], np.ndarray]) -> Callable[[Env], Path]:
    return lambda e: _xyz(e.root / f"{name}.xyz", points())


def _ply_of(name: str, points: Callable[[], np.ndarray]) -> Callable[[Env], Path]:
    return lambda e: am.save_mesh(am.Mesh(points(), grid_faces()), e.root / f"{name}.ply")


#: Valid-but-odd scans: (builder, expected warning or None). See also the invariance tests.
ODD_SCANS: dict[str, tuple[Callable[[Env], Path], str | None]] = {
    "duplicated points (every point twice)": (
        _odd("twice", lambda: np.repeat(scan_points(), 2, axis=0)),
        "50% of the points are exact copies of other points"),
    "duplicated points (every point 4 times)": (
        _odd("four", lambda: np.repeat(scan_points(), 4, axis=0)),
        "75% of the points are exact copies of other points"),
    "a few duplicated points": (
        _odd("few_dups", lambda: np.vstack([scan_points(), scan_points()[:3]])), None),
    "not a height field (sphere)": (
        _odd("sphere", sphere_points), "the data is not a height field in this frame"),
    "flat scan (zero z extent)": (
        _odd("flat", lambda: scan_points() * [1, 1, 0] + [0, 0, 7.5]), None),
    "points scaled by 1e12": (_ply_of("huge", lambda: scan_points() * 1e12), None),
    "points scaled by 1e-12": (_ply_of("tiny", lambda: scan_points() * 1e-12), None),
    "points shifted by 1e12": (_ply_of("far", lambda: scan_points() + 1e12), None),
}


def _valid_rows() -> list[Case]:
    """Controls (the valid inputs pass) and the valid-but-odd scans."""
    scan = SCAN_SLOTS
    rows = [
        Case("fit", "valid", lambda e: e.scan, scan["fit"], None, output="out.asrbf"),
        Case("reconstruct/footprint", "valid", lambda e: e.scan, scan["reconstruct/footprint"],
             None, output="out.ply"),
        Case("metro/reference", "point cloud", lambda e: e.cloud, scan["metro/reference"],
             None, output="out.npz"),
        Case("filter-script/input", "valid", lambda e: e.scan, scan["filter-script/input"],
             None, output="out.ply"),
        Case("filter-script/input", "3 points", SCAN_CASES["3 points"],
             scan["filter-script/input"], None, output="out.ply"),
        Case("info", "valid", lambda e: e.net, NETWORK_SLOTS["info"], None, kind="network"),
        Case("report/input", "valid", lambda e: e.compare, report_slot, None,
             output="out/summary.md", kind="compare result"),
    ]
    for case, (make, warning) in ODD_SCANS.items():
        rows.append(Case("fit", case, make, scan["fit"], None, warning, output="out.asrbf"))
    return rows


def report_slot(e: Env, x: Path) -> list[str]:
    """``asrbf report <x> -o out``."""
    return _p("report", x, "-o", e.root / "out")


def script_slot(e: Env, x: Path) -> list[str]:
    """``asrbf filter-script <x> scan.ply -o out.ply``."""
    return _p("filter-script", x, e.scan, "-o", e.root / "out.ply")


# ---------------------------------------------------------------------------- outputs
#
# For an output row the "input under test" is the output path itself.

OUTPUT_SLOTS: dict[str, tuple[str, Callable[[Env, Path], list[str]], Callable[[Env], Path]]] = {
    # slot: (kind, argv with the output, the input that "same as input" overwrites)
    "fit": ("file", lambda e, o: _p("fit", e.scan, "-o", o, "--passes", "1"),
            lambda e: e.scan),
    "reconstruct": ("file", lambda e, o: _p("reconstruct", e.net, "--footprint", e.scan,
                                            "-o", o, "--resolution", "20"), lambda e: e.scan),
    "fill-holes": ("file", lambda e, o: _p("fill-holes", e.scan, "--network", e.net, "-o", o),
                   lambda e: e.scan),
    "metro/error-mesh": ("file", lambda e, o: _p("metro", e.scan, e.scan, "--error-mesh", o),
                         lambda e: e.scan),
    "metro/samples-out": ("file", lambda e, o: _p("metro", e.scan, e.cloud, "--samples-out",
                                                  o), lambda e: e.cloud),
    "filter-script": ("file", lambda e, o: _p("filter-script", e.script, e.scan, "-o", o),
                      lambda e: e.scan),
    "lod": ("folder", lambda e, o: _p("lod", e.scan, "-o", o, "--levels", "2", "--no-metro"),
            lambda e: e.scan),
    "compare": ("folder", lambda e, o: _p("compare", e.scan, "--network", e.net, "-o", o,
                                          "--no-meshes", "--som-iterations", "10"),
                lambda e: e.scan),
    "report": ("folder", lambda e, o: _p("report", e.compare, "-o", o),
               lambda e: e.compare / "compare.json"),
}

_OUT_NAMES = {"fit": "out.asrbf", "metro/samples-out": "out.npz"}


def output_path(env: Env, slot: str, case: str) -> Path:
    """The output path of an output case, with the folder it needs."""
    name = _OUT_NAMES.get(slot, "out" if OUTPUT_SLOTS[slot][0] == "folder" else "out.ply")
    if case == "in a missing folder":
        return env.root / "missing" / name
    if case == "in a read-only folder":
        locked = env.root / "locked"
        locked.mkdir(exist_ok=True)
        locked.chmod(stat.S_IRUSR | stat.S_IXUSR | stat.S_IRGRP | stat.S_IXGRP)
        return locked / name
    if case == "an existing folder":  # with the extension the command asks for
        folder = env.root / f"existing{Path(name).suffix}"
        folder.mkdir(exist_ok=True)
        return folder
    assert case == "same as the input"
    return OUTPUT_SLOTS[slot][2](env)


def writable_anyway(path: Path) -> bool:
    """Whether this user can write in the read-only folder ``path`` all the same (root)."""
    return path.is_dir() and os.access(path, os.W_OK)


ROOT_SKIP = "running as root: a read-only folder is still writable (os.access)"


OUTPUT_MESSAGES = {
    "in a missing folder": "output directory {root}/missing does not exist",
    "in a read-only folder": "cannot write in {root}/locked (permission denied)",
    "an existing folder": "output path is a directory",
    "same as the input": "refusing to overwrite the input file",
}

_FOLDER_MESSAGES = {
    "in a read-only folder": "cannot create the output folder in {root}/locked "
                             "(permission denied)",
    "same as the input": "output path exists and is not a folder",
}


def _output_rows() -> list[Case]:
    rows = []
    for slot, (kind, argv, _) in OUTPUT_SLOTS.items():
        for case in OUTPUT_MESSAGES:
            message: str | None = OUTPUT_MESSAGES[case]
            output = None
            if kind == "folder":
                if case == "an existing folder":
                    continue  # that is what a folder output is
                if case == "in a missing folder":  # created with its parents, like mkdir -p
                    message, output = None, "missing/out"
                else:
                    message = _FOLDER_MESSAGES[case]
            elif slot == "fit" and case == "same as the input":
                message = "a network file must end in .asrbf"
            rows.append(Case(f"{slot} (output)", case, _output_maker(slot, case), argv,
                             message, output=output, kind=f"{kind} output"))
    return rows


def _output_maker(slot: str, case: str) -> Callable[[Env], Path]:
    return lambda e: output_path(e, slot, case)


CLI_MATRIX: list[Case] = [
    *_scan_rows(),
    *(Case(slot, case, NETWORK_CASES[case], argv, NETWORK_MESSAGES[case], kind="network")
      for slot, argv in NETWORK_SLOTS.items() for case in NETWORK_CASES),
    *(Case("report/input", case, make, report_slot, REPORT_MESSAGES[case],
           kind="compare result") for case, make in REPORT_CASES.items()),
    *(Case("filter-script/script", case, make, script_slot, SCRIPT_MESSAGES[case],
           kind="filter script") for case, make in SCRIPT_CASES.items()),
    *_output_rows(),
    *_valid_rows(),
]


# ============================================================================ running a row


@dataclass(frozen=True)
class Outcome:
    """What one command run did."""

    code: int
    stdout: str
    stderr: str
    subject: Path  # the input (or output) path under test


def snapshot(root: Path) -> dict[str, bytes | None]:
    """Every path below ``root`` (hidden ones included) with its bytes (None: a folder)."""
    return {p.relative_to(root).as_posix(): (p.read_bytes() if p.is_file() else None)
            for p in sorted(root.rglob("*"))}


def run_case(case: Case, env: Env, subject: Path | None = None) -> Outcome:
    """Run the command of ``case`` in-process on ``subject`` (built in ``env`` if None)."""
    subject = case.make(env) if subject is None else subject
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(case.argv(env, subject))
    return Outcome(code, out.getvalue(), err.getvalue(), subject)


def expected_message(case: Case, env: Env) -> str:
    return (case.message or "").format(root=env.root)


# ============================================================================ fixtures


@pytest.fixture(scope="module")
def valid(tmp_path_factory) -> Env:
    """The valid inputs, built once: a 256-point range grid, its network, a comparison."""
    return build_valid(tmp_path_factory.mktemp("valid") / "env")


@pytest.fixture
def env(valid: Env, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Env:
    """A private copy of the valid inputs for one test, run from ``tmp_path``."""
    monkeypatch.chdir(tmp_path)
    return copy_env(valid, tmp_path / "env")


# ============================================================================ the CLI matrix


BAD_ROWS = [c for c in CLI_MATRIX if c.message is not None]
GOOD_ROWS = [c for c in CLI_MATRIX if c.message is None]


@pytest.mark.parametrize("case", BAD_ROWS, ids=[c.id for c in BAD_ROWS])
def test_cli_bad_input(case: Case, env: Env) -> None:
    """One line ``asrbf: error: <file>: <problem>``, exit 2, the folder unchanged."""
    subject = case.make(env)
    if case.case == "in a read-only folder" and writable_anyway(subject.parent):
        pytest.skip(ROOT_SKIP)
    before = snapshot(env.root)  # with the input under test, before the command
    res = run_case(case, env, subject)
    assert Path.cwd() == env.root.parent  # a failed pymeshlab load used to chdir
    assert res.code == 2, res.stderr
    assert res.stdout == ""
    lines = res.stderr.splitlines()
    assert len(lines) == 1, res.stderr
    assert lines[0].startswith(f"asrbf: error: {subject}"), lines[0]
    assert expected_message(case, env) in lines[0]
    assert snapshot(env.root) == before  # no output, no temporary file, inputs untouched


@pytest.mark.parametrize("case", GOOD_ROWS, ids=[c.id for c in GOOD_ROWS])
def test_cli_valid_input(case: Case, env: Env) -> None:
    """Valid and valid-but-odd inputs: exit 0, a warning where due, a readable result."""
    res = run_case(case, env)
    assert Path.cwd() == env.root.parent
    assert res.code == 0, res.stderr
    lines = res.stderr.splitlines()
    if case.warning is None:
        assert lines == []
    else:
        assert len(lines) == 1, res.stderr
        assert lines[0].startswith("asrbf: warning: ") and case.warning in lines[0]
    if case.output is not None:
        assert (env.root / case.output).exists()
    assert not [p for p in env.root.rglob(".*")]  # no temporary file left
    if case.output and case.output.endswith(".asrbf"):
        net = am.Network.load(env.root / case.output)
        assert net.n_neurons > 0 or "flat" in case.case
        assert net.info["ebar"] < 0.2


# ============================================================================ the library


@pytest.mark.parametrize("name", [c for c in SCAN_CASES if c != "point cloud"])
def test_library_load_scan_bad_input(name: str, env: Env) -> None:
    """load_scan raises a ScanError with the very line the CLI prints."""
    path = SCAN_CASES[name](env)
    with pytest.raises(ScanError) as info:
        am.load_scan(path)
    msg = str(info.value)
    assert isinstance(info.value, AsrbfError)
    assert "\n" not in msg and msg.startswith(f"{path}: ") and SCAN_MESSAGES[name] in msg
    assert info.value.__cause__ is None
    res = run_case(Case("fit", name, SCAN_CASES[name], SCAN_SLOTS["fit"], ""), env, path)
    assert res.stderr == f"asrbf: error: {msg}\n"


@pytest.mark.parametrize("name", NETWORK_CASES)
def test_library_network_load_bad_input(name: str, env: Env) -> None:
    """Network.load raises a NetworkFileError with the very line the CLI prints."""
    path = NETWORK_CASES[name](env)
    with pytest.raises(NetworkFileError) as info:
        am.Network.load(path)
    msg = str(info.value)
    assert "\n" not in msg and msg.startswith(f"{path}: ") and NETWORK_MESSAGES[name] in msg
    res = run_case(Case("info", name, NETWORK_CASES[name], NETWORK_SLOTS["info"], ""), env,
                   path)
    assert res.stderr == f"asrbf: error: {msg}\n"


@pytest.mark.parametrize("name", REPORT_CASES)
def test_library_load_compare_bad_input(name: str, env: Env) -> None:
    path = REPORT_CASES[name](env)
    with pytest.raises(AsrbfError) as info:
        load_compare(path)
    msg = str(info.value)
    assert "\n" not in msg and msg.startswith(str(path)) and REPORT_MESSAGES[name] in msg


@pytest.mark.parametrize("case", ["in a missing folder", "in a read-only folder",
                                  "an existing folder", "same as the input"])
def test_library_outputs(case: str, env: Env) -> None:
    """Network.save and save_mesh refuse what the CLI refuses, with the same line."""
    net = am.Network.load(env.net)
    mesh = am.reconstruct(net, resolution=10)
    mesh_out = output_path(env, "reconstruct", case)
    if case == "in a read-only folder" and writable_anyway(mesh_out.parent):
        pytest.skip(ROOT_SKIP)
    net_out = output_path(env, "fit", case)
    if case == "same as the input":
        net_out = env.net
    before = snapshot(env.root)
    for save, out in ((lambda o: am.save_mesh(mesh, o, overwrite_inputs=[env.scan]), mesh_out),
                      (lambda o: net.save(o, inputs=(env.net,)), net_out)):
        with pytest.raises(AsrbfError) as info:
            save(out)
        msg = str(info.value)
        assert "\n" not in msg and msg.startswith(f"{out}: ")
        assert OUTPUT_MESSAGES[case].format(root=env.root) in msg
    assert snapshot(env.root) == before


@pytest.mark.parametrize(("points", "match"), [
    (np.zeros((3, 3)), "a fit needs at least 10 points, got 3"),
    (np.tile([1.0, 2.0, 3.0], (50, 1)), "zero x extent in the 'z' view frame"),
    (np.c_[np.arange(50.0), 2 * np.arange(50.0), np.sin(np.arange(50.0))],
     r"all points lie on one line in \(x, y\) of the 'z' view frame"),
    (np.c_[np.zeros(50), np.arange(50.0), np.arange(50.0) % 3], "zero x extent"),
    (np.array([[0.0, 0, 0]] * 10 + [[np.nan, 1, 2]]), "NaN or infinite"),
])
def test_library_fit_rejects_bad_arrays(points: np.ndarray, match: str) -> None:
    """fit on arrays (no file to name) still raises a one-line ScanError."""
    with pytest.raises(ScanError, match=match) as info:
        am.fit(points, progress=False, passes=1)
    assert "\n" not in str(info.value)


def test_library_collinear_in_the_chosen_frame() -> None:
    """Points spread in world (x, y) but on a line in the view frame's (x, y)."""
    t = np.linspace(0.0, 1.0, 60)
    pts = np.c_[t, np.cos(7 * t), 2 * t]  # view axis x: local (y, z) = (cos 7t, 2t) curve
    am.fit(pts, progress=False, passes=1, view_axis="z")  # fine seen along z... a curve
    line = np.c_[np.cos(7 * t), t, 3 * t]  # view axis x: local (y, z) on a line
    with pytest.raises(ScanError, match="one line in \\(x, y\\) of the 'x' view frame"):
        am.fit(line, progress=False, passes=1, view_axis="x")
    # a scan loaded from a file: the message names the file, as load_scan's do
    scan = am.Scan(points=line, source="scans/line.ply")
    with pytest.raises(ScanError, match="^scans/line.ply: .*one line in \\(x, y\\)"):
        am.fit(scan, progress=False, passes=1, view_axis="x")


def test_library_warnings_for_odd_scans() -> None:
    pts = scan_points()
    with pytest.warns(am.DuplicatePointsWarning, match="50% of the points are exact copies"):
        net = am.fit(np.repeat(pts, 2, axis=0), progress=False, passes=1)
    assert net.info["ebar"] < 0.05
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        am.fit(np.vstack([pts, pts[:3]]), progress=False, passes=1)  # a few: no warning
        am.fit(pts * [1, 1, 0], progress=False, passes=1)  # flat: valid, silent
    with pytest.warns(am.HeightFieldWarning, match="not a height field"):
        am.fit(sphere_points(), progress=False, passes=1)


def test_duplicates_do_not_change_the_sampling_spacing() -> None:
    """Copies of every point (4 and more hide all distinct neighbours) are ignored."""
    from asrbf_mesh._frame import sampling_spacing

    xy = np.random.default_rng(0).random((300, 2))
    one = sampling_spacing(xy)
    for copies in (2, 4, 7):
        assert sampling_spacing(np.repeat(xy, copies, axis=0)) == one


# ============================================================================ invariance


def _unit_surface(net: am.Network) -> np.ndarray:
    uv = np.random.default_rng(5).random((2000, 2))
    return net.evaluate(uv, unit=True)


@pytest.fixture(scope="module")
def base_net() -> am.Network:
    return am.fit(scan_points(), seed=3, progress=False, passes=1)


@pytest.mark.parametrize(("transform", "atol"), [
    (lambda p: p * 1e12, 1e-12),
    (lambda p: p * 1e-12, 1e-12),
    (lambda p: p + 1e12, 0.0),  # exact: see the module docstring
], ids=["scaled by 1e12", "scaled by 1e-12", "shifted by 1e12"])
def test_fit_is_scale_and_shift_invariant(base_net: am.Network, transform, atol: float) -> None:
    pts = scan_points()
    moved = transform(pts)
    net = am.fit(moved, seed=3, progress=False, passes=1)
    assert net.n_neurons == base_net.n_neurons
    assert net.info["ebar"] == pytest.approx(base_net.info["ebar"], rel=1e-9, abs=atol)
    np.testing.assert_allclose(_unit_surface(net), _unit_surface(base_net), rtol=0, atol=atol)
    # and in world units the surface lies on the moved points as well as before
    np.testing.assert_allclose(net.frame.to_unit(moved), base_net.frame.to_unit(pts),
                               rtol=0, atol=max(atol, 1e-15) * 10)
    if atol == 0.0:
        np.testing.assert_array_equal(net.centers, base_net.centers)
        np.testing.assert_array_equal(net.weights, base_net.weights)


def test_cli_fit_is_scale_and_shift_invariant(env: Env) -> None:
    """The CLI's networks of the rescaled files have the same K and E-bar as the scan's."""
    base = am.Network.load(env.net)
    for name in ("points scaled by 1e12", "points scaled by 1e-12", "points shifted by 1e12"):
        res = run_case(Case("fit", name, ODD_SCANS[name][0], SCAN_SLOTS["fit"], None), env)
        assert res.code == 0 and res.stderr == "", res.stderr
        net = am.Network.load(env.root / "out.asrbf")
        assert net.n_neurons == base.n_neurons
        assert net.info["ebar"] == pytest.approx(base.info["ebar"], rel=1e-9)
        np.testing.assert_allclose(_unit_surface(net), _unit_surface(base), rtol=0, atol=1e-12)
        (env.root / "out.asrbf").unlink()
