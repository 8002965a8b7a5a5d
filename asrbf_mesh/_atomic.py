"""Atomic file output: write to a temporary name beside the target, then rename."""

from __future__ import annotations

import contextlib
import fnmatch
import os
import shutil
import signal
import tempfile
import threading
from collections.abc import Iterator, Sequence
from pathlib import Path

from .errors import AsrbfError

__all__ = ["atomic_dir", "atomic_path", "check_output_dir", "check_output_path"]


def check_output_path(path: str | os.PathLike, *inputs: str | os.PathLike | None) -> Path:
    """Validate an output path: its directory exists and it is not one of ``inputs``.

    Raises
    ------
    AsrbfError
        If the directory is missing or not writable, the path is a directory, or it
        names an input file.
    """
    out = Path(path)
    if out.is_dir():
        raise AsrbfError(f"{out}: output path is a directory")
    parent = out.parent if str(out.parent) else Path(".")
    if not parent.is_dir():
        raise AsrbfError(f"{out}: output directory {parent} does not exist")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise AsrbfError(f"{out}: cannot write in {parent} (permission denied)")
    for src in inputs:
        if src is None:
            continue
        s = Path(src)
        if s.exists() and out.exists() and os.path.samefile(s, out):
            raise AsrbfError(f"{out}: refusing to overwrite the input file")
    return out


def check_output_dir(path: str | os.PathLike) -> Path:
    """Validate an output folder before any work: it is a folder or can be created.

    A missing folder is fine (the writer creates it with its missing parents) when its
    closest existing ancestor is a writable folder. Nothing is created here.

    Raises
    ------
    AsrbfError
        If ``path`` exists and is not a folder, or the folder (or its missing parents)
        cannot be created in the closest existing ancestor.
    """
    out = Path(path)
    if out.exists() and not out.is_dir():
        raise AsrbfError(f"{out}: output path exists and is not a folder")
    base = out
    while not base.exists() and base != base.parent:
        base = base.parent
    if not base.is_dir():
        raise AsrbfError(f"{out}: cannot create the output folder: {base} is not a folder")
    if not os.access(base, os.W_OK | os.X_OK):
        what = "write in" if base == out else "create the output folder in"
        raise AsrbfError(f"{out}: cannot {what} {base} (permission denied)")
    return out


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path in the target's directory; rename it onto ``path`` on success.

    The temporary file keeps the target's suffix so that writers choosing a format
    by extension behave. On any exception the temporary file is removed and the
    target is left untouched.
    """
    out = Path(path)
    parent = out.parent if str(out.parent) else Path(".")
    tmp_path: Path | None = None
    try:
        with _signals_held():  # no interrupt between creating the file and arming cleanup
            try:
                fd, tmp = tempfile.mkstemp(prefix=f".{out.name}.", suffix=f".tmp{out.suffix}",
                                           dir=parent)
            except OSError as exc:
                raise AsrbfError(f"{out}: cannot write in {parent} ({exc.strerror})") from None
            os.close(fd)
            tmp_path = Path(tmp)
            umask = os.umask(0)
            os.umask(umask)
            os.chmod(tmp_path, 0o666 & ~umask)  # mkstemp makes 0600; outputs get normal rights
        yield tmp_path
        os.replace(tmp_path, out)
    except BaseException:
        if tmp_path is not None:
            with contextlib.suppress(OSError):
                tmp_path.unlink()
        raise


@contextlib.contextmanager
def _signals_held() -> Iterator[None]:
    """Hold SIGINT and SIGTERM back while a few renames or a cleanup run (main thread only).

    A signal that arrives meanwhile is delivered to the previous handler at the end, so
    an interrupted command still stops, but never halfway through moving its outputs.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    got: list[int] = []
    old = {s: signal.signal(s, lambda signum, frame: got.append(signum))
           for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for s, h in old.items():
            signal.signal(s, h)
        if got:
            handler = old[got[0]]
            if callable(handler):
                handler(got[0], None)
            elif handler == signal.SIG_DFL:
                signal.raise_signal(got[0])


def _make_parents(folder: Path) -> list[Path]:
    """Create ``folder`` and its missing parents; return those created, deepest first."""
    missing = []
    p = folder
    while not p.exists() and p != p.parent:
        missing.append(p)
        p = p.parent
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise AsrbfError(f"{folder}: cannot create the output folder ({exc.strerror})") from None
    return missing


def _remove_empty(folders: list[Path]) -> None:
    for p in folders:
        with contextlib.suppress(OSError):
            p.rmdir()


def _swap_in(new: Path, out: Path) -> None:
    """Rename ``new`` onto ``out``, an existing folder: old aside, new in, old deleted."""
    aside = Path(tempfile.mkdtemp(prefix=f".{out.name}.old-", dir=out.parent))
    os.replace(out, aside)  # onto the empty folder just made
    try:
        os.replace(new, out)
    except BaseException:
        os.replace(aside, out)
        raise
    shutil.rmtree(aside, ignore_errors=True)


def _install(tmp: Path, out: Path, owns: Sequence[str]) -> None:
    if not out.exists():
        os.replace(tmp, out)
        return
    entries = list(out.iterdir())
    if all(any(fnmatch.fnmatch(e.name, pat) for pat in owns) for e in entries):
        _swap_in(tmp, out)  # empty, or a previous run's: its stale files go
        return
    # a folder holding other files too: move the new entries in, leave the others
    for entry in sorted(tmp.iterdir()):
        target = out / entry.name
        if target.is_dir() and not target.is_symlink():
            _swap_in(entry, target)
        else:
            os.replace(entry, target)
    tmp.rmdir()


@contextlib.contextmanager
def atomic_dir(path: str | os.PathLike, owns: Sequence[str] = ()) -> Iterator[Path]:
    """Yield a hidden temporary folder beside ``path``; it takes the place of ``path`` on success.

    The folder output appears whole or not at all: the work writes into
    ``.NAME.tmp-<random>`` in the same parent (created with its missing parents), renamed
    onto ``path`` at the end. An existing ``path`` that is empty or holds only names
    matching the glob patterns ``owns`` (a previous run of the same command) is
    replaced, so files of the earlier run do not linger; a folder holding anything
    else keeps it, and receives the new entries one by one. On any exception
    (interrupts included) the temporary folder and the parents created are removed.

    Raises
    ------
    AsrbfError
        If ``path`` is a file, or the folder cannot be created.
    """
    out = Path(path)
    if out.exists() and not out.is_dir():
        raise AsrbfError(f"{out}: output path exists and is not a folder")
    parent = out.parent if str(out.parent) else Path(".")
    created = _make_parents(parent)
    tmp: Path | None = None
    try:
        # an interrupt between creating the folder and entering this block would leave
        # it behind: signals wait until the folder is created and its cleanup armed
        with _signals_held():
            try:
                tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.tmp-", dir=parent))
            except OSError as exc:
                raise AsrbfError(f"{out}: cannot write in {parent} ({exc.strerror})") from None
            umask = os.umask(0)
            os.umask(umask)
            os.chmod(tmp, 0o777 & ~umask)  # mkdtemp makes 0700; outputs get normal rights
        yield tmp
        with _signals_held():
            _install(tmp, out, owns)
    except BaseException:
        with _signals_held():
            if tmp is not None:
                shutil.rmtree(tmp, ignore_errors=True)
            _remove_empty(created)
        raise
