"""Build the prebuilt kernel sets shipped in ``asrbf_mesh/_prebuilt/`` (``asrbf_mesh._prebuilt``).

Run from the repository root, after the last change to any ``.py`` file of the package
(the sets name the sources they were compiled from, and a set of other sources is never
used):

    python scripts/build_kernels.py

For each x86-64 level (``asrbf_mesh._prebuilt.LEVELS``), a fresh per-user cache is filled
by running, with numba targeting that level (``NUMBA_CPU_NAME``, ``NUMBA_CPU_FEATURES`` from
``_prebuilt.FEATURES``), what a new user runs first: ``asrbf demo`` (a fit of the face map),
``reconstruct``, ``fill-holes`` and ``lod`` on it, plus every kernel a learning command needs
after learning (``python -m asrbf_mesh._warm``). The cache is packed as ``<level>.tar.xz``
beside a ``manifest.json``. A command's kernels that no set holds compile on first use, as before.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
os.environ["ASRBF_NO_PREBUILT"] = "1"  # this process judges no set: it is writing them

from asrbf_mesh import _jit_cache, _prebuilt  # noqa: E402


def _run(args: list[str], env: dict[str, str]) -> None:
    out = subprocess.run(args, env=env, cwd=ROOT, capture_output=True, text=True)
    if out.returncode != 0:
        raise SystemExit(f"build_kernels: {' '.join(args)} failed:\n{out.stderr[-2000:]}")


def build(level: str, workdir: Path) -> Path:
    """Compile the kernels for ``level`` into a fresh cache; return its kernel directory."""
    cache = workdir / level
    env = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_")}
    env.update(NUMBA_CPU_NAME=level, NUMBA_CPU_FEATURES=_prebuilt.FEATURES[level],
               ASRBF_CACHE_DIR=str(cache),
               ASRBF_NO_PREBUILT="1", ASRBF_NO_WARM="1")
    py = sys.executable
    face = subprocess.run([py, "-c", "import asrbf_mesh as a; print(a.face_map_path())"],
                          env=env, cwd=ROOT, capture_output=True, text=True,
                          check=True).stdout.strip()
    out = workdir / f"{level}-out"
    cli = [py, "-m", "asrbf_mesh.cli"]
    _run([py, "-m", "asrbf_mesh._warm"], env)
    _run(cli + ["demo", "-o", str(out / "demo")], env)  # a fit of the face map and more
    _run(cli + ["reconstruct", str(out / "demo" / "face.asrbf"), "-o", str(out / "face.ply"),
                "--footprint", face], env)
    _run(cli + ["fill-holes", face, "-o", str(out / "filled.ply")], env)
    _run(cli + ["lod", face, "-o", str(out / "lod")], env)
    return cache / f"kernels-{_jit_cache.source_key()}"


def main() -> None:
    """Build every level's set and write the manifest."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--levels", nargs="+", default=list(_prebuilt.LEVELS),
                    choices=list(_prebuilt.LEVELS))
    args = ap.parse_args()
    dest = _prebuilt.ARCHIVES  # (pack keeps the manifest's other levels of these sources)
    with tempfile.TemporaryDirectory(prefix="asrbf-kernels-") as tmp:
        for level in args.levels:
            t0 = time.perf_counter()
            kernels = build(level, Path(tmp))
            archive = _prebuilt.pack(kernels, dest, level, _jit_cache.source_key())
            n = sum(1 for _ in kernels.rglob("*.nbi"))
            print(f"{level}: {n} kernels, {archive.stat().st_size / 1e6:.2f} MB "
                  f"({time.perf_counter() - t0:.0f} s)")
    print(f"wrote {dest / 'manifest.json'}")


if __name__ == "__main__":
    main()
