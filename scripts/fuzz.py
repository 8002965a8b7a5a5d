"""Coverage-guided fuzzing (atheris / libFuzzer) of the scan loaders and the .asrbf loader.

Run from the repository root (atheris: ``pip install atheris``)::

    python scripts/fuzz.py all --seconds 600          # each target 10 minutes, in turn
    python scripts/fuzz.py scan --seconds 60          # one target
    python scripts/fuzz.py asrbf --seconds 60 --record BENCHMARKS.md

Targets
-------
``scan``
    :func:`asrbf_mesh.load_scan` on a file whose format (one of the supported
    extensions) is chosen by the input's first byte and whose content is the rest.
``asrbf``
    :meth:`asrbf_mesh.Network.load` on (by the first byte) the raw input as the file,
    a valid network whose JSON metadata is replaced by the input, or a valid network
    one of whose ``.npy`` members is replaced by the input.

The contract checked on every input: the loader either raises the package's own
one-line error (:class:`asrbf_mesh.errors.AsrbfError`: what the CLI prints with exit
code 2) or returns an object that is whole — a scan with finite points and faces that
index them, a network that evaluates to finite depths over its domain and saves again.
Anything else (another exception, a NaN, a hang over ``--timeout`` seconds, memory over
``--rss-mb``) is a finding: libFuzzer stops and writes the input to ``fuzz/crash-*``;
such inputs become regression tests (``tests/test_fuzz_regressions.py``).

Seed corpora (small valid files of every format) are written to ``fuzz/corpus/TARGET``
on first use; libFuzzer adds the inputs that reach new code there.
"""

from __future__ import annotations

import argparse
import io
import os
import re
import subprocess
import sys
import tempfile
import time
import warnings
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
FUZZ = ROOT / "fuzz"
TARGETS = ("scan", "asrbf")
EXTS = (".ply", ".obj", ".off", ".stl", ".xyz", ".pts", ".txt", ".npy", ".png", ".tif", ".npz",
        ".las")
#: How range files are read (a depth scale for integer images, a cell size for arrays).
RANGE_OPTIONS = {".png": {"depth_scale": 1000.0}, ".tif": {"depth_scale": 1000.0},
                 ".npz": {"cell": 2.0}}
_TMP = Path(tempfile.mkdtemp(prefix="asrbf-fuzz-", dir="/dev/shm" if os.path.isdir(
    "/dev/shm") else None))


# --------------------------------------------------------------------------- seeds


def _seed_scans() -> dict[str, bytes]:
    """Small valid files of every supported format (first byte: the extension index)."""
    import numpy as np

    from asrbf_mesh._io import save_mesh
    from asrbf_mesh._mesh import Mesh

    rng = np.random.default_rng(0)
    g = np.stack(np.meshgrid(np.arange(4.0), np.arange(3.0)), -1).reshape(-1, 2)
    v = np.c_[g, 0.1 * rng.random(len(g))]
    f = np.array([[r * 4 + c, r * 4 + c + 1, r * 4 + c + 4] for r in range(2) for c in range(3)])
    seeds: dict[str, bytes] = {}
    for ext in (".ply", ".obj", ".off", ".stl"):
        out = _TMP / f"seed{ext}"
        save_mesh(Mesh(v, f), out)
        seeds[f"mesh{ext}"] = bytes([EXTS.index(ext)]) + out.read_bytes()
    ascii_ply = ("ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
                 "property float z\nelement face 2\nproperty list uchar int vertex_indices\n"
                 "end_header\n0 0 0\n1 0 0\n0 1 0\n1 1 0.5\n3 0 1 2\n4 1 3 2 0\n")
    seeds["ascii.ply"] = bytes([0]) + ascii_ply.encode()
    grid_ply = ("ply\nformat ascii 1.0\nobj_info num_cols 2\nobj_info num_rows 2\n"
                "element vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
                "element range_grid 4\nproperty list uchar int vertex_indices\nend_header\n"
                "0 0 0\n1 0 0\n0 1 0\n1 1 1\n1 0\n1 1\n1 2\n1 3\n")
    seeds["grid.ply"] = bytes([0]) + grid_ply.encode()
    xyz = "# points\n4\n" + "".join(f"{a:.3f}, {b:.3f} {c:.3f}\n" for a, b, c in v)
    seeds["pts.xyz"] = bytes([EXTS.index(".xyz")]) + xyz.encode()
    stl = "solid s\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\n" \
          "endloop\nendfacet\nendsolid s\n"
    seeds["ascii.stl"] = bytes([EXTS.index(".stl")]) + stl.encode()
    buf = io.BytesIO()
    np.save(buf, v)
    seeds["pts.npy"] = bytes([EXTS.index(".npy")]) + buf.getvalue()
    seeds.update(_seed_range(rng))
    return seeds


def _seed_range(rng) -> dict[str, bytes]:
    """Small range files: 16-bit PNG and float TIFF depth images, an NPZ grid, a LAS cloud."""
    import numpy as np
    from PIL import Image

    depth = (1000 + 50 * rng.random((8, 10))).astype(np.uint16)
    depth[3:5, 4:6] = 0
    seeds: dict[str, bytes] = {}
    buf = io.BytesIO()
    Image.fromarray(depth).save(buf, format="PNG")
    seeds["depth.png"] = bytes([EXTS.index(".png")]) + buf.getvalue()
    import tifffile

    buf = io.BytesIO()
    tifffile.imwrite(buf, depth.astype(np.float32) / 1000.0)
    seeds["depth.tif"] = bytes([EXTS.index(".tif")]) + buf.getvalue()
    buf = io.BytesIO()
    np.savez(buf, elevation=depth.astype(np.float64), cell=np.asarray(2.0))
    seeds["dem.npz"] = bytes([EXTS.index(".npz")]) + buf.getvalue()
    try:
        import laspy
    except ImportError:
        return seeds
    las = laspy.LasData(laspy.LasHeader(point_format=6, version="1.4"))
    xy = rng.random((30, 2)) * 10
    las.x, las.y, las.z = xy[:, 0], xy[:, 1], np.sin(xy[:, 0])
    las.classification = np.full(30, 2, np.uint8)
    out = _TMP / "seed.las"
    las.write(out)
    seeds["cloud.las"] = bytes([EXTS.index(".las")]) + out.read_bytes()
    return seeds


def _valid_network() -> bytes:
    import numpy as np

    import asrbf_mesh as am

    rng = np.random.default_rng(0)
    xy = rng.random((300, 2))
    net = am.fit(np.c_[xy, 0.3 * np.sin(3 * xy[:, 0]) * xy[:, 1]], seed=0, progress=False,
                 passes=1)
    return net.save(_TMP / "seed.asrbf").read_bytes()


def _seed_networks() -> dict[str, bytes]:
    raw = _valid_network()
    seeds = {"raw": bytes([0]) + raw}
    with zipfile.ZipFile(io.BytesIO(raw)) as zf:
        names = sorted(zf.namelist())
        import numpy as np

        meta = bytes(np.load(io.BytesIO(zf.read("meta.npy"))))
        seeds["meta"] = bytes([1]) + meta
        for i, name in enumerate(names):
            seeds[f"member-{name}"] = bytes([2, i]) + zf.read(name)
    return seeds


def write_corpus(target: str) -> Path:
    """Write the seed corpus of ``target`` (kept if it exists) and return its folder."""
    d = FUZZ / "corpus" / target
    d.mkdir(parents=True, exist_ok=True)
    seeds = _seed_scans() if target == "scan" else _seed_networks()
    for name, data in seeds.items():
        path = d / f"seed-{name}"
        if not path.exists():
            path.write_bytes(data)
    return d


# --------------------------------------------------------------------------- targets


class Finding(AssertionError):
    """The loader broke its contract."""


def check_scan(data: bytes) -> bool:
    """Load ``data`` as a scan file; a ScanError or a whole scan, nothing else.

    Returns whether the file loaded; raises :class:`Finding` on a broken contract.
    """
    import numpy as np

    from asrbf_mesh._io import load_scan
    from asrbf_mesh.errors import AsrbfError

    if not data:
        return False
    ext = EXTS[(data[0] & 0x7F) % len(EXTS)]
    path = _TMP / f"in{ext}"
    path.write_bytes(data[1:])
    hf = bool(data[0] & 0x80)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            scan = load_scan(path, min_points=1, height_field=hf,
                             options=RANGE_OPTIONS.get(ext))
    except AsrbfError as exc:
        msg = str(exc)
        if "\n" in msg or not msg.startswith(str(path)):
            raise Finding(f"error message is not one line naming the file: {msg!r}") from None
        return False
    p = scan.points
    if p.ndim != 2 or p.shape[1] != 3 or len(p) < 1 or not np.all(np.isfinite(p)):
        raise Finding(f"bad points {p.shape}")
    if scan.faces is not None:
        f = scan.faces
        if f.ndim != 2 or f.shape[1] != 3 or (len(f) and (f.min() < 0 or f.max() >= len(p))):
            raise Finding(f"faces out of range or misshapen {f.shape}")
    return True


def _network_file(data: bytes) -> bytes:
    """The .asrbf bytes for an ``asrbf`` input (see the module docstring)."""
    import numpy as np

    mode = data[0] % 3
    if mode == 0:
        return data[1:]
    raw = _network_file.valid  # type: ignore[attr-defined]
    buf = io.BytesIO()
    with zipfile.ZipFile(io.BytesIO(raw)) as src, zipfile.ZipFile(buf, "w") as dst:
        names = sorted(src.namelist())
        victim = "meta.npy" if mode == 1 else names[data[1] % len(names)] if len(data) > 1 \
            else names[0]
        body = data[1:] if mode == 1 else data[2:]
        for name in names:
            if name != victim:
                dst.writestr(name, src.read(name))
            elif mode == 1:
                npy = io.BytesIO()
                np.save(npy, np.frombuffer(body, dtype=np.uint8))
                dst.writestr(name, npy.getvalue())
            else:
                dst.writestr(name, body)
    return buf.getvalue()


def check_network(data: bytes) -> bool:
    """Load ``data`` as a network file; a NetworkFileError or a whole network.

    Returns whether the file loaded; raises :class:`Finding` on a broken contract.
    """
    import numpy as np

    from asrbf_mesh._network import Network
    from asrbf_mesh.errors import AsrbfError

    if not data:
        return False
    path = _TMP / "in.asrbf"
    path.write_bytes(_network_file(data))
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            net = Network.load(path)
    except AsrbfError as exc:
        msg = str(exc)
        if "\n" in msg or not msg.startswith(str(path)):
            raise Finding(f"error message is not one line naming the file: {msg!r}") from None
        return False
    uv = np.stack(np.meshgrid(np.linspace(-0.1, 1.1, 7), np.linspace(-0.1, 1.1, 7)),
                  -1).reshape(-1, 2)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        z = net.evaluate(uv, unit=True)
        world = net.frame.to_world(np.c_[uv, z])
        local = net.evaluate(net.frame.xy_from_unit(uv))
    if not (np.all(np.isfinite(z)) and np.all(np.isfinite(world))
            and np.all(np.isfinite(local))):
        raise Finding("a loaded network evaluates to NaN or inf over its domain")
    net.save(_TMP / "again.asrbf")
    return True


CHECKS = {"scan": check_scan, "asrbf": check_network}


# --------------------------------------------------------------------------- runner


def _instrument(atheris) -> None:
    """Add coverage feedback to the loaders' Python code (never to numba kernels)."""
    import inspect

    import plyfile

    from asrbf_mesh import _config as config
    from asrbf_mesh import _frame as frame
    from asrbf_mesh import _io as io
    from asrbf_mesh import _mesh as mesh
    from asrbf_mesh import _network as network
    from asrbf_mesh import _readers as readers

    for module in (io, readers, mesh, network, frame, config, plyfile):
        for obj in list(vars(module).values()):
            if getattr(obj, "__module__", None) != module.__name__:
                continue
            funcs = [obj] if inspect.isfunction(obj) else [
                m for m in vars(obj).values() if inspect.isfunction(m)] if inspect.isclass(
                obj) else []
            funcs += [m.__func__ for m in (vars(obj).values() if inspect.isclass(obj) else ())
                      if isinstance(m, (classmethod, staticmethod))]
            for fn in funcs:
                atheris.instrument_func(fn)


def run_one(target: str, seconds: int, timeout: int, rss_mb: int) -> None:
    """Fuzz one target in this process (libFuzzer exits the process at the end)."""
    import atheris

    corpus = write_corpus(target)  # fits a network: before any instrumentation
    if target == "asrbf":
        _network_file.valid = _valid_network()  # type: ignore[attr-defined]
    _instrument(atheris)
    check = CHECKS[target]
    (FUZZ / "crashes").mkdir(parents=True, exist_ok=True)
    atheris.Setup([sys.argv[0], str(corpus), f"-max_total_time={seconds}",
                   f"-timeout={timeout}", f"-rss_limit_mb={rss_mb}", "-print_final_stats=1",
                   f"-artifact_prefix={FUZZ / 'crashes'}/{target}-"], lambda b: check(b) and None)
    atheris.Fuzz()


def _stats(text: str) -> dict[str, str]:
    """Runs, coverage and corpus size from libFuzzer's output."""
    out = {}
    if m := re.search(r"Done (\d+) runs in (\d+) second", text):
        out["runs"], out["seconds"] = m.group(1), m.group(2)
    if m := re.findall(r"cov: (\d+) ft: (\d+) corp: (\d+)/", text):
        out["cov"], out["ft"], out["corpus"] = m[-1]
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("target", choices=[*TARGETS, "all"])
    ap.add_argument("--seconds", type=int, default=600, help="per target (default 600)")
    ap.add_argument("--timeout", type=int, default=20, help="seconds one input may take")
    ap.add_argument("--rss-mb", type=int, default=2048, help="memory limit (default 2048)")
    ap.add_argument("--record", type=Path, help="append the results table to this file")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        run_one(args.target, args.seconds, args.timeout, args.rss_mb)
        return 0
    rows = []
    for target in TARGETS if args.target == "all" else (args.target,):
        t0 = time.time()
        done = subprocess.run([sys.executable, __file__, target, "--child",
                               f"--seconds={args.seconds}", f"--timeout={args.timeout}",
                               f"--rss-mb={args.rss_mb}"], capture_output=True, text=True)
        log = FUZZ / f"{target}.log"
        log.write_text(done.stdout + done.stderr)
        st = _stats(done.stderr)
        found = "none" if done.returncode == 0 else f"FINDING (exit {done.returncode}, {log})"
        rows.append((target, st.get("runs", "?"), f"{time.time() - t0:.0f}", st.get("cov", "?"),
                     st.get("corpus", "?"), found))
        print(f"{target}: {rows[-1]}", flush=True)
    head = "| target | inputs run | seconds | coverage (edges) | corpus | findings |\n" \
           "|---|---|---|---|---|---|\n"
    table = head + "".join("| " + " | ".join(r) + " |\n" for r in rows)
    print(table)
    if args.record:
        with open(args.record, "a") as fh:
            fh.write(f"\n`python scripts/fuzz.py {args.target} --seconds {args.seconds}` "
                     f"({time.strftime('%Y-%m-%d')}):\n\n{table}")
    return 0 if all(r[-1] == "none" for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
