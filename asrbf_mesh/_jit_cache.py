"""Where numba caches the package's compiled kernels: a per-user directory that outlives installs.

numba caches a compiled kernel beside its source file (``__pycache__``), so a fresh clone,
a new virtual environment with a regular install, or a reinstall starts cold, and the first
fit spends about 10 s compiling. Importing this module (every module that defines kernels
does so before defining them) points numba's cache for the files of this package at one
per-user directory instead, named after a hash of every source file of the package: any
installation of the same source on the machine (another clone, another environment, a
reinstall) finds the kernels compiled, and a change to any source file gives a new
directory. The hash covers all files because a cached kernel contains the kernels it calls,
which may live in other files (numba checks only the kernel's own file).

The directory is ``$ASRBF_CACHE_DIR``, else ``$XDG_CACHE_HOME/asrbf-mesh``, else
``~/.cache/asrbf-mesh``. When ``NUMBA_CACHE_DIR`` is set, numba's own locator uses it, as
it would without this module; when the directory cannot be written, numba's default
locators apply. Directories of other sources are removed once more than
:data:`KEEP` newer ones exist and they have not been used for a day.
"""

from __future__ import annotations

import functools
import hashlib
import os
import shutil
import threading
import time
from pathlib import Path

from numba.core import caching as _caching
from numba.core import config as _config
from numba.core import event as _event

__all__ = ["PackageCacheLocator", "cache_dir", "compile_seconds", "install", "source_key",
           "tree_key"]

#: Directories of other source versions kept besides the current one.
KEEP = 3

_PACKAGE = Path(__file__).resolve().parent


def tree_key(root: Path) -> str:
    """Return a hash of the ``*.py`` files under ``root`` (relative paths and contents)."""
    digest = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        digest.update(path.relative_to(root).as_posix().encode())
        digest.update(b"\0")
        digest.update(path.read_bytes())
        digest.update(b"\0")
    return digest.hexdigest()[:16]


@functools.cache
def source_key() -> str:
    """Return the hash of every source file of the package, 16 hex digits (:func:`tree_key`)."""
    return tree_key(_PACKAGE)


def _root() -> Path:
    env = os.environ.get("ASRBF_CACHE_DIR")
    if env:
        return Path(env)
    xdg = os.environ.get("XDG_CACHE_HOME")
    return (Path(xdg) if xdg else Path.home() / ".cache") / "asrbf-mesh"


def cache_dir() -> Path:
    """Return the directory of this source version's compiled kernels."""
    return _root() / f"kernels-{source_key()}"


def _make_locator():
    """Return the locator class, or None where numba's caching internals differ."""
    try:
        base = (_caching._SourceFileBackedLocatorMixin, _caching._CacheLocator)
    except AttributeError:
        return None

    class PackageCacheLocator(*base):
        """numba cache locator for the files of this package: :func:`cache_dir`."""

        def __init__(self, py_func, py_file) -> None:
            self._py_file = py_file
            self._lineno = py_func.__code__.co_firstlineno
            sub = Path(py_file).resolve().relative_to(_PACKAGE).parent  # e.g. evaluate/
            self._cache_path = str(cache_dir() / sub)

        def get_cache_path(self) -> str:
            """Return the directory the function is cached in."""
            return self._cache_path

        @classmethod
        def from_function(cls, py_func, py_file):
            """Locate a function of this package (None for others, or with NUMBA_CACHE_DIR)."""
            if _config.CACHE_DIR:
                return None
            try:
                Path(py_file).resolve().relative_to(_PACKAGE)
            except (ValueError, OSError):
                return None
            return super().from_function(py_func, py_file)  # None: cannot be written

    return PackageCacheLocator


PackageCacheLocator = _make_locator()


def _prune(keep: int = KEEP, idle_seconds: float = 86400.0) -> None:
    """Remove the directories of other source versions beyond the ``keep`` newest, if idle."""
    here = cache_dir()
    try:
        if here.is_dir():
            os.utime(here)  # in use: newest
        others = sorted((p for p in here.parent.glob("kernels-*") if p != here and p.is_dir()),
                        key=lambda p: p.stat().st_mtime, reverse=True)
    except OSError:
        return
    now = time.time()
    for old in others[keep:]:
        try:
            if now - old.stat().st_mtime > idle_seconds:
                shutil.rmtree(old, ignore_errors=True)
        except OSError:
            pass


def install() -> None:
    """Put :data:`PackageCacheLocator` first among numba's cache locators (once)."""
    impl = getattr(_caching, "CacheImpl", None) or getattr(_caching, "_CacheImpl", None)
    classes = getattr(impl, "_locator_classes", None)
    if PackageCacheLocator is None or not isinstance(classes, list):
        return  # another numba: its own locators, as without this module
    if PackageCacheLocator not in classes:
        classes.insert(0, PackageCacheLocator)
        _prune()
        if not _config.CACHE_DIR:  # the prebuilt kernels go where this locator looks
            from ._prebuilt import install as install_prebuilt

            install_prebuilt(cache_dir(), source_key())


class _CompileClock(_event.Listener):
    """Sums the wall time numba spends compiling, outermost compilations only.

    numba compiles under one process-wide lock, so the outermost compilations of all
    threads never overlap: their sum is the time the process spent compiling.
    """

    def __init__(self) -> None:
        self.seconds = 0.0
        self._lock = threading.Lock()
        self._local = threading.local()

    def on_start(self, event: _event.Event) -> None:
        depth = getattr(self._local, "depth", 0)
        if depth == 0:
            self._local.start = time.perf_counter()
        self._local.depth = depth + 1

    def on_end(self, event: _event.Event) -> None:
        self._local.depth -= 1
        if self._local.depth == 0:
            with self._lock:
                self.seconds += time.perf_counter() - self._local.start


_CLOCK = _CompileClock()
_event.register("numba:compile", _CLOCK)


def compile_seconds() -> float:
    """Seconds this process has spent compiling kernels so far (a cached kernel: none)."""
    return _CLOCK.seconds


install()
