"""Run every ``asrbf`` subcommand on two scans and write a manifest of their outputs.

The manifest pins what the command line produces, so that two versions of the code (e.g.
before and after a refactor) or two runs of the same code can be compared::

    git worktree add ../before REV   # the code before the change
    python scripts/check_outputs.py --root ../before --out /tmp/outs_before
    python scripts/check_outputs.py --root . --out /tmp/outs_after
    python scripts/check_outputs.py --diff /tmp/outs_before/manifest.json \\
        /tmp/outs_after/manifest.json

Each command runs as ``PYTHON -m asrbf_mesh.cli ...`` in a subprocess, with ``--root`` first
on ``PYTHONPATH`` (checked: ``asrbf_mesh`` and ``meshlab_filter`` must import from there) and
``OUT/runs`` as its working folder. The scans are copied to ``OUT/runs/inputs`` and every
path on a command line is relative, so the outputs do not depend on where the code or the
work folder is. Each command writes into its own folder ``OUT/runs/<step>/``. The
subprocesses get ``PYTHONHASHSEED=0`` and ``MPLBACKEND=Agg``.

``OUT/manifest.json`` holds per command: the arguments, the exit code, the first line of
stderr, the ``--json`` stdout with the volatile keys removed (:data:`VOLATILE_KEYS`) and a
digest of every file in the command's folder:

- ``.asrbf`` and ``.npz`` (zips of ``.npy`` members): the sha256 of each array (dtype, shape
  and bytes), the ``meta`` member of a network as normalized JSON, so zip member dates or
  compression do not count;
- ``.json``: the sha256 of the normalized JSON (volatile keys removed, keys sorted);
- text (``.md``, ``.html``, ...): the sha256 after masking durations and the version
  (:data:`TEXT_MASKS`) and the ``seconds`` column of Markdown tables;
- anything else: the sha256 of the bytes.

Absolute paths under the work folder, the source root or the interpreter's prefix are
rewritten to ``<work>``, ``<root>``, ``<prefix>`` in every string. The wall time of each
command is in ``OUT/timings.json`` (not in the manifest). ``--diff A B`` prints every
difference between two manifests and exits with 1 if there is one.
"""

from __future__ import annotations

import argparse
import hashlib
import io
import json
import os
import re
import shutil
import subprocess
import sys
import time
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

DEFAULT_ROOT = Path(__file__).resolve().parent.parent

# Keys whose values change from run to run (wall-clock figures, versions, machine names);
# removed wherever they occur in stdout JSON or in a JSON output file.
VOLATILE_KEYS = frozenset({
    "seconds", "fit_seconds", "learn_seconds", "polish_seconds", "metro_seconds",
    "us_per_step",  # wall clock (fit, lod, compare, filter-script, batch)
    "asrbf_mesh_version",  # lod manifest
    "pid", "worker",  # batch records: process id, dask worker address
})
# Masked in text outputs (Markdown, HTML) and in non-JSON stdout before hashing: durations
# ("fit 0.2 s", "53.3 us/step") and the package version (demo's first line).
TEXT_MASKS = (
    (re.compile(r"\b\d+(?:\.\d+)?(?:e[+-]?\d+)? ?(?:s|ms|us|µs)\b"), "<duration>"),
    (re.compile(r"asrbf-mesh \d+\.\d+\S*"), "asrbf-mesh <version>"),
)
# Markdown table columns whose cells are masked (batch summary.md: "seconds").
VOLATILE_COLUMNS = frozenset({"seconds"})
TEXT_SUFFIXES = frozenset({".md", ".html", ".htm", ".txt", ".csv", ".svg", ".log"})
ZIP_SUFFIXES = frozenset({".asrbf", ".npz"})

FACE = "inputs/face000.ply"
BUNNY = "inputs/bun000_crop.ply"
SCRIPT = "inputs/script.json"
# A 2-step filter script: ours, then one of pymeshlab's (README, "MeshLab filters").
FILTER_SCRIPT = [
    {"filter": "meshing_close_holes_asrbf", "params": {"maxholesize": "5%"}},
    {"filter": "meshing_remove_duplicate_faces"},
]


def steps() -> list[tuple[str, list[str]]]:
    """Return the commands to run, in order: ``(step name, asrbf arguments)``.

    Every output goes into the folder named after its step; later steps read earlier
    outputs through relative paths.
    """
    out: list[tuple[str, list[str]]] = []
    for tag, scan in (("face", FACE), ("bunny", BUNNY)):
        net = f"fit-{tag}/net.asrbf"
        out += [
            (f"fit-{tag}", ["fit", scan, "-o", net, "--seed", "0", "--json"]),
            (f"fit-{tag}-float32", ["fit", scan, "-o", f"fit-{tag}-float32/net.asrbf",
                                    "--seed", "0", "--float32", "--json"]),
            (f"info-{tag}", ["info", net, "--json"]),
            (f"info-{tag}-float32", ["info", f"fit-{tag}-float32/net.asrbf", "--json"]),
            (f"reconstruct-{tag}", ["reconstruct", net, "-o", f"reconstruct-{tag}/mesh.ply",
                                    "--json"]),
            (f"reconstruct-{tag}-footprint",
             ["reconstruct", net, "-o", f"reconstruct-{tag}-footprint/mesh.ply",
              "--footprint", scan, "--json"]),
            (f"reconstruct-{tag}-full",
             ["reconstruct", net, "-o", f"reconstruct-{tag}-full/mesh.ply",
              "--resolution", "100", "--mode", "full", "--margin", "0.1", "--json"]),
            (f"fill-holes-{tag}", ["fill-holes", scan, "-o", f"fill-holes-{tag}/filled.ply",
                                   "--json"]),
            (f"fill-holes-{tag}-network",
             ["fill-holes", scan, "-o", f"fill-holes-{tag}-network/filled.ply",
              "--network", net, "--json"]),
            (f"lod-{tag}", ["lod", scan, "-o", f"lod-{tag}/lod", "--json"]),
            (f"lod-{tag}-refit", ["lod", scan, "-o", f"lod-{tag}-refit/lod", "--method",
                                  "refit", "--levels", "3", "--compare-qem", "--json"]),
            (f"metro-{tag}", ["metro", f"reconstruct-{tag}-footprint/mesh.ply", scan,
                              "--error-mesh", f"metro-{tag}/error.ply",
                              "--samples-out", f"metro-{tag}/samples.npz", "--json"]),
            (f"compare-{tag}", ["compare", scan, "-o", f"compare-{tag}/compare",
                                "--som-iterations", "2000", "--json"]),
            (f"filter-script-{tag}", ["filter-script", SCRIPT, scan, "-o",
                                      f"filter-script-{tag}/out.ply", "--json"]),
        ]
    out += [
        ("report", ["report", "compare-face/compare", "compare-bunny/compare", "-o",
                    "report/summary", "--json"]),
        ("demo", ["demo", "-o", "demo/asrbf-demo", "--seed", "0"]),
        ("batch", ["batch", BUNNY, "-o", "batch/out", "--task", "fit", "--workers", "1",
                   "--json"]),
    ]
    return out


# -- normalization ------------------------------------------------------------------------

class Normalizer:
    """Remove volatile keys and rewrite machine-specific absolute paths."""

    def __init__(self, prefixes: dict[str, str]):
        pairs = {}
        for p, tag in prefixes.items():
            pairs[p] = tag
            pairs[os.path.realpath(p)] = tag
        # longest first, so /a/b/runs wins over /a/b
        self.prefixes = sorted(pairs.items(), key=lambda x: -len(x[0]))

    def text(self, s: str) -> str:
        for p, tag in self.prefixes:
            s = s.replace(p, tag)
        return s

    def json(self, obj: Any) -> Any:
        if isinstance(obj, dict):
            return {k: self.json(v) for k, v in obj.items() if k not in VOLATILE_KEYS}
        if isinstance(obj, list):
            return [self.json(v) for v in obj]
        if isinstance(obj, str):
            return self.text(obj)
        return obj


def mask_text(text: str) -> str:
    """Mask :data:`TEXT_MASKS` and the :data:`VOLATILE_COLUMNS` of Markdown tables."""
    for rx, repl in TEXT_MASKS:
        text = rx.sub(repl, text)
    lines = text.split("\n")
    masked: set[int] = set()
    for i, line in enumerate(lines):
        if not line.startswith("|"):
            masked = set()
            continue
        cells = line.split("|")
        if i + 1 < len(lines) and lines[i + 1].startswith("|---"):  # a header row
            masked = {j for j, c in enumerate(cells) if c.strip() in VOLATILE_COLUMNS}
        elif masked and not line.startswith("|---"):
            lines[i] = "|".join("<masked>" if j in masked else c for j, c in enumerate(cells))
    return "\n".join(lines)


def _sha(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def _canonical(obj: Any) -> bytes:
    return json.dumps(obj, sort_keys=True, separators=(",", ":")).encode()


def _hash_zip(path: Path, norm: Normalizer) -> dict[str, str]:
    """Digest of each ``.npy`` member of a zip (``meta`` as normalized JSON)."""
    out: dict[str, str] = {}
    with zipfile.ZipFile(path) as zf:
        for name in sorted(zf.namelist()):
            raw = zf.read(name)
            if not name.endswith(".npy"):
                out[name] = _sha(raw)
                continue
            arr = np.lib.format.read_array(io.BytesIO(raw), allow_pickle=False)
            if name == "meta.npy" and arr.dtype == np.uint8:
                out[name] = "json:" + _sha(_canonical(norm.json(json.loads(arr.tobytes()))))
            else:
                arr = np.ascontiguousarray(arr)
                head = f"{arr.dtype.str}{arr.shape}".encode()
                out[name] = _sha(head + arr.tobytes())
    return out


def hash_file(path: Path, norm: Normalizer) -> str | dict[str, str]:
    """Digest of one output file (see the module docstring)."""
    suffix = path.suffix.lower()
    if suffix in ZIP_SUFFIXES and zipfile.is_zipfile(path):
        return _hash_zip(path, norm)
    data = path.read_bytes()
    if suffix == ".json":
        try:
            return "json:" + _sha(_canonical(norm.json(json.loads(data))))
        except ValueError:
            pass
    if suffix in TEXT_SUFFIXES:
        try:
            text = norm.text(data.decode("utf-8"))
        except UnicodeDecodeError:
            return _sha(data)
        return "text:" + _sha(mask_text(text).encode())
    return _sha(data)


def hash_tree(folder: Path, norm: Normalizer) -> dict[str, Any]:
    """Digest of every file under ``folder``, by path relative to it."""
    if not folder.is_dir():
        return {}
    return {p.relative_to(folder).as_posix(): hash_file(p, norm)
            for p in sorted(folder.rglob("*")) if p.is_file()}


# -- running ------------------------------------------------------------------------------

def _python_cmd(args: argparse.Namespace) -> list[str]:
    return args.python.split()


def _env(root: Path) -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(root)] + (
        [env["PYTHONPATH"]] if env.get("PYTHONPATH") else []))
    env["PYTHONHASHSEED"] = "0"
    env["MPLBACKEND"] = "Agg"
    return env


def _probe(python: list[str], root: Path, env: dict[str, str]) -> dict[str, str]:
    """Check the packages import from ``root``; return the face map path and interpreter
    prefix."""
    code = ("import json, sys, asrbf_mesh, meshlab_filter; print(json.dumps({"
            "'asrbf_mesh': asrbf_mesh.__file__, 'meshlab_filter': meshlab_filter.__file__, "
            "'face_map': str(asrbf_mesh.face_map_path()), 'prefix': sys.prefix}))")
    res = subprocess.run([*python, "-c", code], env=env, cwd=root, capture_output=True,
                         text=True, check=False)
    if res.returncode:
        sys.exit(f"check_outputs: cannot import asrbf_mesh with {python}:\n{res.stderr}")
    info = json.loads(res.stdout)
    for pkg in ("asrbf_mesh", "meshlab_filter"):
        if not Path(info[pkg]).resolve().is_relative_to(root.resolve()):
            sys.exit(f"check_outputs: {pkg} imports from {info[pkg]}, not from {root} "
                     "(pass a --python wrapper that puts --root first on sys.path)")
    return info


def _prepare(out: Path, root: Path, bunny: Path, face: Path) -> Path:
    if out.exists() and any(out.iterdir()) and not (out / "manifest.json").exists() \
            and not (out / "runs").exists():
        sys.exit(f"check_outputs: {out} is not empty and not an earlier output folder")
    work = out / "runs"
    if work.exists():
        shutil.rmtree(work)
    (work / "inputs").mkdir(parents=True)
    shutil.copyfile(face, work / FACE)
    shutil.copyfile(bunny, work / BUNNY)
    (work / SCRIPT).write_text(json.dumps(FILTER_SCRIPT, indent=1) + "\n")
    return work


def run(args: argparse.Namespace) -> int:
    root = Path(args.root).resolve()
    out = Path(args.out).resolve()
    python = _python_cmd(args)
    env = _env(root)
    info = _probe(python, root, env)
    bunny = Path(args.bunny) if args.bunny else root / "tests" / "data" / "bun000_crop.ply"
    work = _prepare(out, root, bunny, Path(info["face_map"]))
    norm = Normalizer({str(work): "<work>", str(root): "<root>", info["prefix"]: "<prefix>",
                       str(Path(info["face_map"]).parent): "<face-dir>"})
    inputs = hash_tree(work / "inputs", norm)

    todo = steps()
    if args.only:
        wanted = set(args.only)
        todo = [s for s in todo if s[0] in wanted]
    manifest: dict[str, Any] = {"inputs": inputs, "steps": {}}
    timings: dict[str, float] = {}
    t_all = time.perf_counter()
    failed = 0
    for name, argv in todo:
        (work / name).mkdir(parents=True, exist_ok=True)
        t0 = time.perf_counter()
        res = subprocess.run([*python, "-m", "asrbf_mesh.cli", *argv], cwd=work, env=env,
                             capture_output=True, text=True, check=False)
        timings[name] = round(time.perf_counter() - t0, 2)
        stdout: Any
        try:
            stdout = norm.json(json.loads(res.stdout))
        except ValueError:  # no --json (demo): the text, durations masked
            stdout = mask_text(norm.text(res.stdout)).splitlines()
        lines = res.stderr.strip().splitlines()
        manifest["steps"][name] = {
            "argv": argv,
            "exit_code": res.returncode,
            "stderr_first_line": norm.text(lines[0]) if lines else "",
            "stdout": stdout,
            "files": hash_tree(work / name, norm),
        }
        failed += res.returncode != 0
        print(f"{name:<28} exit {res.returncode}  {timings[name]:8.2f} s"
              + (f"  {lines[-1][:100]}" if res.returncode and lines else ""), flush=True)
    timings["total"] = round(time.perf_counter() - t_all, 2)
    (out / "manifest.json").write_text(json.dumps(manifest, indent=1, sort_keys=True) + "\n")
    (out / "timings.json").write_text(json.dumps(
        {"root": str(root), "python": python, "seconds": timings}, indent=1) + "\n")
    print(f"{len(todo)} commands, {failed} failed, {timings['total']:.1f} s; "
          f"wrote {out / 'manifest.json'}")
    return 1 if failed else 0


# -- diff ---------------------------------------------------------------------------------

def _flatten(obj: Any, prefix: str, out: dict[str, Any]) -> None:
    if isinstance(obj, dict) and obj:
        for k, v in obj.items():
            _flatten(v, f"{prefix}.{k}" if prefix else str(k), out)
    elif isinstance(obj, list) and obj:
        for i, v in enumerate(obj):
            _flatten(v, f"{prefix}[{i}]", out)
    else:
        out[prefix] = obj


_MISSING = "<missing>"


def diff(a_path: str, b_path: str) -> int:
    """Print every difference between two manifests; return 1 if there is one."""
    flat: list[dict[str, Any]] = []
    for p in (a_path, b_path):
        f: dict[str, Any] = {}
        _flatten(json.loads(Path(p).read_text()), "", f)
        flat.append(f)
    a, b = flat
    keys = sorted(set(a) | set(b))
    rows = [(k, a.get(k, _MISSING), b.get(k, _MISSING)) for k in keys
            if a.get(k, _MISSING) != b.get(k, _MISSING)]
    if not rows:
        print(f"no differences ({len(keys)} entries)")
        return 0

    def cell(v: Any) -> str:
        s = v if isinstance(v, str) else json.dumps(v)
        return s if len(s) <= 72 else s[:69] + "..."

    w = max(len(k) for k, _, _ in rows)
    print(f"{'entry':<{w}}  {'A: ' + a_path:<74}  B: {b_path}")
    for k, va, vb in rows:
        print(f"{k:<{w}}  {cell(va):<74}  {cell(vb)}")
    print(f"{len(rows)} differences of {len(keys)} entries")
    return 1


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--root", default=str(DEFAULT_ROOT),
                   help="source root put first on PYTHONPATH [default: %(default)s]")
    p.add_argument("--python", default=sys.executable,
                   help="python command to run the CLI with (may hold arguments) "
                        "[default: %(default)s]")
    p.add_argument("--out", help="output folder: OUT/manifest.json, OUT/timings.json, OUT/runs")
    p.add_argument("--bunny", help="the small scan [default: ROOT/tests/data/bun000_crop.ply]")
    p.add_argument("--only", nargs="+", metavar="STEP", help="run only these steps")
    p.add_argument("--list", action="store_true", help="list the steps and exit")
    p.add_argument("--diff", nargs=2, metavar=("A.json", "B.json"),
                   help="compare two manifests instead of running")
    args = p.parse_args(argv)
    if args.diff:
        return diff(*args.diff)
    if args.list:
        for name, cmd in steps():
            print(f"{name:<28} asrbf {' '.join(cmd)}")
        return 0
    if not args.out:
        p.error("--out is required (or --diff / --list)")
    return run(args)


if __name__ == "__main__":
    sys.exit(main())
