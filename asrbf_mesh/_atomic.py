"""Atomic file output: write to a temporary name beside the target, then rename."""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path

from .errors import AsrbfError

__all__ = ["atomic_path", "check_output_dir", "check_output_path"]


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
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{out.name}.", suffix=f".tmp{out.suffix}", dir=parent)
    except OSError as exc:
        raise AsrbfError(f"{out}: cannot write in {parent} ({exc.strerror})") from None
    os.close(fd)
    tmp_path = Path(tmp)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp_path, 0o666 & ~umask)  # mkstemp creates 0600; outputs get normal permissions
    try:
        yield tmp_path
        os.replace(tmp_path, out)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp_path.unlink()
        raise
