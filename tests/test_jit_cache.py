"""The per-user cache of compiled kernels (asrbf_mesh._jit_cache)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from asrbf_mesh import _jit_cache as jc

PACKAGE = Path(jc.__file__).resolve().parent


def test_the_key_follows_every_source_file_not_the_location(tmp_path: Path) -> None:
    a, b = tmp_path / "a" / "pkg", tmp_path / "b" / "pkg"
    for root in (a, b):
        (root / "sub").mkdir(parents=True)
        (root / "k.py").write_text("x = 1\n")
        (root / "sub" / "m.py").write_text("y = 2\n")
    assert jc.tree_key(a) == jc.tree_key(b)  # another clone of the same source
    (b / "sub" / "m.py").write_text("y = 3\n")  # a kernel's callee in another file
    assert jc.tree_key(a) != jc.tree_key(b)
    (b / "sub" / "m.py").write_text("y = 2\n")
    (b / "sub" / "m.py").rename(b / "m.py")  # same contents, another file
    assert jc.tree_key(a) != jc.tree_key(b)


@pytest.mark.skipif(bool(os.environ.get("NUMBA_CACHE_DIR")), reason="NUMBA_CACHE_DIR wins")
def test_the_kernels_are_cached_in_the_package_directory() -> None:
    from asrbf_mesh import _learn_kernels, _network_kernels
    from asrbf_mesh.evaluate import _som_kernels

    som = next(v for v in vars(_som_kernels).values() if hasattr(v, "_cache"))
    for kernel in (_learn_kernels.run_steps, _network_kernels.build_grid, som):
        path = Path(kernel._cache._cache_path)
        assert path.is_relative_to(jc.cache_dir()), path


def test_a_fresh_copy_of_the_source_finds_the_kernels_compiled(tmp_path: Path) -> None:
    """Another clone (or environment) on the same machine: no compilation, a cache hit."""
    probe = ("import sys; from asrbf_mesh import _learn_heap as h; import numpy as np\n"
             "k = np.zeros(4, np.int64)\n"
             "h._heap_push(k, k.copy(), k.copy(), np.int64(0), np.int64(1), np.int64(2),"
             " np.int64(3))\n"
             "assert h.__file__.startswith(sys.argv[1]), h.__file__\n"
             "print(sum(h._heap_push.stats.cache_hits.values()),"
             " sum(h._heap_push.stats.cache_misses.values()))\n")
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env["ASRBF_CACHE_DIR"] = str(tmp_path / "cache")
    env["ASRBF_NO_PREBUILT"] = "1"  # what a copy compiles itself, not the shipped kernels
    counts = []
    for clone in ("one", "two"):
        root = tmp_path / clone
        shutil.copytree(PACKAGE, root / "asrbf_mesh",
                        ignore=shutil.ignore_patterns("__pycache__"))
        out = subprocess.run([sys.executable, "-c", probe, str(root)], cwd=root, env=env,
                             capture_output=True, text=True, check=True)
        counts.append(tuple(int(v) for v in out.stdout.split()))
    assert counts[0] == (0, 1)  # the first copy compiles
    assert counts[1] == (1, 0)  # the second loads what the first compiled
    assert len(list((tmp_path / "cache").glob("kernels-*"))) == 1


def test_old_source_versions_are_pruned_when_idle(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.setenv("ASRBF_CACHE_DIR", str(tmp_path))
    old = time.time() - 3 * 86400
    dirs = []
    for i in range(jc.KEEP + 3):
        d = tmp_path / f"kernels-old{i}"
        d.mkdir()
        os.utime(d, (old + i, old + i))
        dirs.append(d)
    recent = tmp_path / "kernels-recent"
    recent.mkdir()  # beyond KEEP by age order too, but used today: kept
    os.utime(recent, (old - 10, old - 10))
    os.utime(recent)  # now
    jc._prune()
    left = {p.name for p in tmp_path.glob("kernels-*")}
    newest = {d.name for d in dirs[-(jc.KEEP - 1):]}  # recent is the newest of all
    assert "kernels-recent" in left and newest <= left
    assert len(left) == jc.KEEP


def test_compile_time_is_counted_once_per_compilation() -> None:
    """Nested compilations (a kernel compiling its callee) count once; a compiled call, not."""
    from numba import njit

    @njit
    def inner(x):
        return x + 1.0

    @njit
    def outer(x):
        return inner(x) * 2.0

    before = jc.compile_seconds()
    t = time.perf_counter()
    assert outer(1.0) == 4.0
    wall = time.perf_counter() - t
    spent = jc.compile_seconds() - before
    assert 0.0 < spent <= wall
    assert outer(2.0) == 6.0
    assert jc.compile_seconds() - before == spent


def test_a_fit_reports_its_compile_time_within_its_own(syn) -> None:
    import asrbf_mesh as am

    net = am.fit(syn.franke_points(30), seed=0, progress=False, passes=1)
    assert 0.0 <= net.info["compile_seconds"] <= net.info["fit_seconds"]


PROBE = ("import sys; from asrbf_mesh import _learn_heap as h; import numpy as np\n"
         "k = np.zeros(4, np.int64)\n"
         "h._heap_push(k, k.copy(), k.copy(), np.int64(0), np.int64(1), np.int64(2),"
         " np.int64(3))\n"
         "from numba.core import config\n"
         "print(sum(h._heap_push.stats.cache_hits.values()),"
         " sum(h._heap_push.stats.cache_misses.values()), config.CPU_NAME)\n")


def _probe(env: dict[str, str], target: str | None = None) -> tuple[int, int]:
    """(cache hits, misses) of a kernel's first call in a new process; check numba's target."""
    out = subprocess.run([sys.executable, "-c", PROBE], env=env, capture_output=True,
                         text=True, check=True)
    hits, misses, cpu = out.stdout.split()
    assert cpu == str(target), cpu
    return int(hits), int(misses)


@pytest.mark.skipif(bool(os.environ.get("NUMBA_CACHE_DIR")), reason="NUMBA_CACHE_DIR wins")
def test_a_prebuilt_set_loads_instead_of_compiling(tmp_path: Path) -> None:
    """A set compiled for an x86-64 level is unpacked on first import and loaded, not compiled;
    a set of other sources is left alone."""
    from asrbf_mesh import _prebuilt

    level = "x86-64-v3"
    if not _prebuilt.LEVELS[level] <= _prebuilt.level_features():
        pytest.skip(f"this processor cannot run {level} code")
    base = {k: v for k, v in os.environ.items() if not k.startswith(("NUMBA_", "ASRBF_"))}
    built = tmp_path / "built"
    env = dict(base, NUMBA_CPU_NAME=level, NUMBA_CPU_FEATURES=_prebuilt.FEATURES[level],
               ASRBF_NO_PREBUILT="1",
               ASRBF_CACHE_DIR=str(built))
    assert _probe(env, level) == (0, 1)  # compiled for the level
    sets = tmp_path / "sets"
    _prebuilt.pack(built / f"kernels-{jc.source_key()}", sets, level, jc.source_key())
    user = tmp_path / "user"
    env = dict(base, ASRBF_PREBUILT_DIR=str(sets), ASRBF_CACHE_DIR=str(user))
    assert _probe(env, level) == (1, 0)  # the shipped kernel, loaded; numba targets the level
    marker = user / f"kernels-{jc.source_key()}" / _prebuilt.MARKER
    assert marker.read_text().split()[0] == level
    assert _probe(env, level) == (1, 0)  # and in every later process
    assert _probe(dict(env, ASRBF_NO_PREBUILT="1")) == (0, 1)  # off: this machine's own code

    manifest = sets / "manifest.json"
    manifest.write_text(manifest.read_text().replace(jc.source_key(), "0" * 16))
    other = tmp_path / "other"
    env = dict(base, ASRBF_PREBUILT_DIR=str(sets), ASRBF_CACHE_DIR=str(other))
    assert _probe(env) == (0, 1)  # another source version's set: compiled for this machine
    marker = other / f"kernels-{jc.source_key()}" / _prebuilt.MARKER
    assert marker.read_text().split()[0] == "none"
    # a new manifest (the sets rebuilt for these sources) is judged again
    manifest.write_text(manifest.read_text().replace("0" * 16, jc.source_key()))
    _probe(env, level)
    assert marker.read_text().split()[0] == level


def test_the_shipped_kernels_are_built_from_these_sources() -> None:
    """The prebuilt sets name the sources they were compiled from and serve no others.

    After a change to any source file of the package, ``python scripts/build_kernels.py``
    builds them again; without it a new machine's first fit compiles for 12-15 s.
    """
    import json

    from asrbf_mesh import _prebuilt

    manifest = json.loads((_prebuilt.ARCHIVES / "manifest.json").read_text(encoding="utf-8"))
    assert manifest["source_key"] == jc.source_key(), "run: python scripts/build_kernels.py"
    assert set(manifest["levels"]) == set(_prebuilt.LEVELS)
    for name in manifest["levels"].values():
        assert (_prebuilt.ARCHIVES / name).is_file()
