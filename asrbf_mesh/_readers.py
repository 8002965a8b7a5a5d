"""The per-format scan readers behind :func:`asrbf_mesh._io.load_scan`.

One parser per format (PLY, OBJ, OFF, STL, XYZ/PTS/TXT, NPY), each returning the points,
the triangles (or ``None``) and the range-grid shape, and raising :class:`ParseError`
(a message without the path, which the caller adds) for a file it cannot read. The
header parsing and format checks that the streaming reader (:mod:`asrbf_mesh._stream`)
needs as well live here too, so that both read a file by the same rules:
:func:`read_ply_data` and :func:`ply_vertex` (PLY), :func:`npy_header` and
:func:`check_npy_points` (NPY), :func:`check_text` and :func:`is_count_line` (point
lists).
"""

from __future__ import annotations

import os
import re
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import BinaryIO

import numpy as np
import plyfile

from ._ply_ascii import read_ascii_body
from ._validate import one_line, plural
from .errors import ScanError

__all__ = [
    "SUPPORTED_SCAN_FORMATS",
    "FORMAT_NAMES",
    "READERS",
    "STL_RECORD",
    "TEXT_PROBE",
    "ParseError",
    "PointBlocks",
    "check_scan_path",
    "check_npy_points",
    "check_text",
    "is_count_line",
    "npy_header",
    "ply_vertex",
    "read_ply_data",
]

#: File extensions :func:`~asrbf_mesh._io.load_scan` understands (compared case-insensitively).
SUPPORTED_SCAN_FORMATS: tuple[str, ...] = (
    ".ply",
    ".obj",
    ".off",
    ".stl",
    ".xyz",
    ".pts",
    ".txt",
    ".npy",
    # range data, read by asrbf_mesh._range_io (depth images, elevation grids, LiDAR)
    ".png",
    ".tif",
    ".tiff",
    ".npz",
    ".las",
    ".laz",
)

#: The format's name in messages, by extension.
FORMAT_NAMES = {
    ".ply": "PLY",
    ".obj": "OBJ",
    ".off": "OFF",
    ".stl": "STL",
    ".xyz": "XYZ",
    ".pts": "PTS",
    ".txt": "TXT",
    ".npy": "NPY",
    ".png": "PNG",
    ".tif": "TIFF",
    ".tiff": "TIFF",
    ".npz": "NPZ",
    ".las": "LAS",
    ".laz": "LAZ",
}

#: Bytes at the start of a point list that :func:`check_text` looks at.
TEXT_PROBE = 8192


class ParseError(Exception):
    """A format-specific problem found by one of the parsers (message without path)."""


# --------------------------------------------------------------------------- helpers

def _fan(flat: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """Fan-triangulate polygons given as concatenated indices and per-polygon lengths.

    Polygon ``(a, b, c, d, ...)`` becomes ``(a, b, c), (a, c, d), ...``; the output keeps
    the polygons' order.
    """
    lengths = np.asarray(lengths, dtype=np.int64)
    if len(lengths) == 0:
        return np.empty((0, 3), dtype=np.int64)
    if lengths.min() < 3:
        k = int(np.flatnonzero(lengths < 3)[0])
        raise ParseError(f"face {k} has {int(lengths[k])} vertices (at least 3 needed)")
    starts = np.cumsum(lengths) - lengths
    n_tris = lengths - 2
    out_start = np.cumsum(n_tris) - n_tris
    out = np.empty((int(n_tris.sum()), 3), dtype=np.int64)
    for k in np.unique(lengths):
        sel = np.flatnonzero(lengths == k)
        poly = flat[starts[sel, None] + np.arange(k)]
        for i in range(1, int(k) - 1):
            rows = out_start[sel] + (i - 1)
            out[rows, 0] = poly[:, 0]
            out[rows, 1] = poly[:, i]
            out[rows, 2] = poly[:, i + 1]
    return out


def _object_lists(lists: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Concatenate an object array of 1-D integer arrays; return ``(flat, lengths)``."""
    if lists.dtype != object:
        arr = np.asarray(lists)
        if arr.ndim == 2:
            n, k = arr.shape
            return arr.astype(np.int64).ravel(), np.full(n, k, dtype=np.int64)
        raise ParseError(f"unexpected list array of shape {arr.shape}")
    lengths = np.fromiter((len(a) for a in lists), dtype=np.int64, count=len(lists))
    if lengths.sum() == 0:
        return np.empty(0, dtype=np.int64), lengths
    flat = np.concatenate([np.asarray(a).ravel() for a in lists if len(a)])
    if flat.dtype.kind not in "iu":
        raise ParseError(f"list indices must be integers, got {flat.dtype}")
    return flat.astype(np.int64), lengths


def _check_indices(faces: np.ndarray, n_points: int, what: str = "face") -> None:
    """Raise :class:`ParseError` if some index of ``faces`` is outside ``[0, n_points)``."""
    if faces.size == 0:
        return
    bad = (faces < 0) | (faces >= n_points)
    if bad.any():
        n_bad = int(bad.reshape(len(faces), -1).any(axis=1).sum())
        first = int(faces[bad][0])
        verb = "references" if n_bad == 1 else "reference"
        raise ParseError(
            f"{plural(n_bad, what)} {verb} vertices outside [0, {n_points}) (e.g. index {first})"
        )



# --------------------------------------------------------------------------- range grids


def _triangulate_range_grid(points: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """Triangulate a range grid of vertex indices (``-1`` = no sample).

    Each 2x2 block of cells with four samples gives two triangles split along the
    shorter 3-D diagonal (ties: the ``(r, c)``-``(r+1, c+1)`` diagonal); a block with
    exactly three samples gives one triangle. Triangles come out in row-major block
    order with MeshLab's winding (counter-clockwise seen from +z for Stanford scans);
    if their area-weighted normal sum nevertheless points to -z, all are flipped so the
    surface faces a scanner looking down the -z axis.
    """
    rows, cols = grid.shape
    if rows < 2 or cols < 2:
        return np.empty((0, 3), dtype=np.int64)
    v0 = grid[:-1, :-1].ravel()  # (r, c)
    v1 = grid[:-1, 1:].ravel()  # (r, c+1)
    v2 = grid[1:, :-1].ravel()  # (r+1, c)
    v3 = grid[1:, 1:].ravel()  # (r+1, c+1)
    ok0, ok1, ok2, ok3 = v0 >= 0, v1 >= 0, v2 >= 0, v3 >= 0
    n_ok = ok0.astype(np.int8) + ok1 + ok2 + ok3
    quad = n_ok == 4
    tri = n_ok == 3

    nb = len(v0)
    first = np.zeros((nb, 3), dtype=np.int64)
    second = np.zeros((nb, 3), dtype=np.int64)

    q = np.flatnonzero(quad)
    if len(q):
        d03 = np.sum((points[v0[q]] - points[v3[q]]) ** 2, axis=1)
        d12 = np.sum((points[v1[q]] - points[v2[q]]) ** 2, axis=1)
        main = d03 <= d12
        qa, qb = q[main], q[~main]
        first[qa] = np.column_stack((v3[qa], v2[qa], v0[qa]))
        second[qa] = np.column_stack((v0[qa], v1[qa], v3[qa]))
        first[qb] = np.column_stack((v2[qb], v0[qb], v1[qb]))
        second[qb] = np.column_stack((v1[qb], v3[qb], v2[qb]))

    t = np.flatnonzero(tri)
    if len(t):
        a, b, c, d = v0[t], v1[t], v2[t], v3[t]
        cand = np.stack(
            [
                np.column_stack((b, d, c)),  # (r, c) missing
                np.column_stack((d, c, a)),  # (r, c+1) missing
                np.column_stack((a, b, d)),  # (r+1, c) missing
                np.column_stack((c, a, b)),  # (r+1, c+1) missing
            ]
        )
        missing = np.argmin(np.column_stack((ok0[t], ok1[t], ok2[t], ok3[t])), axis=1)
        first[t] = cand[missing, np.arange(len(t))]

    keep = np.column_stack((quad | tri, quad))
    faces = np.stack((first, second), axis=1)[keep]
    if len(faces):
        p = points[faces]
        normal_sum = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]).sum(axis=0)
        if normal_sum[2] < 0:
            faces = np.ascontiguousarray(faces[:, ::-1])
    return faces


def _grid_dims(ply: plyfile.PlyData) -> tuple[int | None, int | None]:
    """``(num_rows, num_cols)`` from a PLY header's ``obj_info`` (or comment) lines."""
    rows = cols = None
    for line in list(ply.obj_info) + list(ply.comments):
        parts = line.split()
        if len(parts) >= 2 and parts[0] in ("num_rows", "num_cols"):
            try:
                value = int(parts[1])
            except ValueError:
                raise ParseError(f"bad {parts[0]} value {parts[1]!r} in header") from None
            if parts[0] == "num_rows":
                rows = value
            else:
                cols = value
    return rows, cols


# --------------------------------------------------------------------------- parsers

_Parsed = tuple[np.ndarray, np.ndarray | None, tuple[int, int] | None]


def _list_property(element: plyfile.PlyElement, names: Iterable[str]) -> str:
    """Name of the first of ``names`` that is a property of ``element``."""
    for name in names:
        if name in element:
            return name
    raise ParseError(
        f"element '{element.name}' has no {' / '.join(repr(n) for n in names)} property"
    )


def read_ply_data(fh: BinaryIO) -> plyfile.PlyData:
    """Read a PLY file (ASCII or binary) with :mod:`plyfile`, memory-mapping binary data.

    Faces of three vertices take plyfile's memory-mapped fast path; polygons of several
    sizes are read row by row. An ASCII body of one row per line is parsed by numpy
    (:mod:`asrbf_mesh._ply_ascii`). Raises :class:`ParseError` when the file is shorter, or
    (binary) longer, than its header announces.
    """
    start = fh.tell()
    parse_header = getattr(plyfile.PlyData, "_parse_header", None)  # (plyfile's, private)
    try:
        head = parse_header(fh) if parse_header is not None else None
    except (plyfile.PlyParseError, ValueError):
        head = None  # plyfile's read below says what is wrong
    if head is not None and head.text and read_ascii_body(head, fh.read()):
        return head
    fh.seek(start)
    fast = {"face": {"vertex_indices": 3, "vertex_index": 3}}
    try:
        try:
            ply = plyfile.PlyData.read(fh, mmap="r", known_list_len=fast)
        except plyfile.PlyElementParseError as exc:
            if exc.message != "unexpected list length":
                raise
            # Polygons of several sizes: no memory-mapped fast path, read row by row.
            fh.seek(0)
            ply = plyfile.PlyData.read(fh, mmap="r")
    except plyfile.PlyElementParseError as exc:
        if exc.message != "early end-of-file" or exc.element is None:
            raise
        raise ParseError(
            f"{one_line(exc)}: the header announces {exc.element.count} "
            f"'{exc.element.name}' rows (file truncated, or the header's counts are wrong)"
        ) from None
    if not ply.text:
        # plyfile stops after the announced elements: data left over (more than the
        # blank or NUL padding some writers append) means that the header's counts
        # do not describe the file.
        extra = os.fstat(fh.fileno()).st_size - fh.tell()
        if extra > 0 and fh.read().strip(b" \t\r\n\x00"):
            counts = ", ".join(f"{e.count} {e.name}" for e in ply.elements)
            raise ParseError(
                f"{plural(extra, 'byte')} after the elements the header announces "
                f"({counts}): the header's counts do not match the data"
            )
    return ply


def ply_vertex(ply: plyfile.PlyData) -> plyfile.PlyElement:
    """Return the ``vertex`` element, checked to have numeric ``x``, ``y`` and ``z``."""
    if "vertex" not in [e.name for e in ply.elements]:
        raise ParseError("no 'vertex' element")
    vert = ply["vertex"]
    for c in "xyz":
        if c not in vert:
            raise ParseError(f"the vertex element has no '{c}' property")
        if vert.data[c].dtype.kind not in "iuf":
            raise ParseError(f"vertex property '{c}' is not numeric")
    return vert


def _read_ply(path: Path) -> _Parsed:
    """Parse a PLY file (ASCII or binary): vertices, then faces or the range grid."""
    with open(path, "rb") as fh:
        ply = read_ply_data(fh)
    vert = ply_vertex(ply)
    names = [e.name for e in ply.elements]
    points = np.column_stack([np.asarray(vert.data[c], dtype=np.float64) for c in "xyz"])
    points = points.reshape(-1, 3)
    n = len(points)

    has_faces = "face" in names and ply["face"].count > 0
    faces = None
    grid_shape = None
    if "range_grid" in names:
        rows, cols = _grid_dims(ply)
        grid_el = ply["range_grid"]
        if rows is not None and cols is not None and rows * cols == grid_el.count:
            grid_shape = (rows, cols)
        elif not has_faces:
            if rows is None or cols is None:
                raise ParseError("range_grid element but no num_rows/num_cols in the header")
            raise ParseError(
                f"range_grid has {grid_el.count} cells but num_rows x num_cols = "
                f"{rows} x {cols} = {rows * cols}"
            )
    if has_faces:
        face = ply["face"]
        prop = _list_property(face, ("vertex_indices", "vertex_index"))
        flat, lengths = _object_lists(face.data[prop])
        faces = _fan(flat, lengths)
        _check_indices(faces, n)
    elif grid_shape is not None:
        grid_el = ply["range_grid"]
        prop = _list_property(grid_el, ("vertex_indices", "vertex_index"))
        flat, lengths = _object_lists(grid_el.data[prop])
        cell = np.full(len(lengths), -1, dtype=np.int64)
        has = lengths > 0
        starts = np.cumsum(lengths) - lengths
        cell[has] = flat[starts[has]]
        bad = has & ((cell < 0) | (cell >= n))
        if bad.any():
            n_bad = int(bad.sum())
            verb = "references" if n_bad == 1 else "reference"
            raise ParseError(
                f"{plural(n_bad, 'range_grid cell')} {verb} vertices outside "
                f"[0, {n}) (e.g. index {int(cell[bad][0])})"
            )
        faces = _triangulate_range_grid(points, cell.reshape(grid_shape))
    return points, faces, grid_shape


def _read_text(path: Path) -> str:
    """Read a file as text (undecodable bytes become U+FFFD and fail later)."""
    return path.read_bytes().decode("utf-8", errors="replace")


def _face_indices(tokens: list[str]) -> np.ndarray:
    """Convert OBJ face tokens (``'7'``, ``'7/1'``, ``'7//3'``, ``'-2/1/1'``) to ints."""
    heads = [t.partition("/")[0] for t in tokens]
    try:
        return np.array(heads, dtype=np.int64) if heads else np.empty(0, dtype=np.int64)
    except ValueError:
        bad = next((h for h in heads if not re.fullmatch(r"[+-]?\d+", h)), "?")
        raise ParseError(f"bad face index {bad!r}") from None


def _read_obj(path: Path) -> _Parsed:
    """Parse the ``v`` and ``f`` lines of a Wavefront OBJ file."""
    verts: list[list[str]] = []
    face_tokens: list[str] = []
    lengths: list[int] = []
    bases: list[int] = []
    for lineno, line in enumerate(_read_text(path).splitlines(), start=1):
        parts = line.split()
        if not parts:
            continue
        key = parts[0]
        if key == "v":
            if len(parts) < 4:
                raise ParseError(f"line {lineno}: a vertex needs 3 coordinates")
            verts.append(parts[1:4])
        elif key == "f":
            face_tokens.extend(parts[1:])
            lengths.append(len(parts) - 1)
            bases.append(len(verts))
    try:
        points = np.array(verts, dtype=np.float64).reshape(-1, 3)
    except ValueError as exc:
        raise ParseError(f"bad vertex coordinate ({one_line(exc)})") from None
    if not lengths:
        return points, None, None
    idx = _face_indices(face_tokens)
    lens = np.array(lengths, dtype=np.int64)
    base = np.repeat(np.array(bases, dtype=np.int64), lens)
    if (idx == 0).any():
        raise ParseError("face index 0 (OBJ indices start at 1)")
    # Positive indices are 1-based; negative ones count back from the last vertex so far.
    idx = np.where(idx > 0, idx - 1, base + idx)
    faces = _fan(idx, lens)
    _check_indices(faces, len(points))
    return points, faces, None


_OFF_KEYWORD = re.compile(r"(?:ST)?(?:C|N|CN|NC)?OFF")


def _read_off(path: Path) -> _Parsed:
    """Parse an ASCII OFF file (also ``COFF``, ``NOFF``, ``CNOFF``, ``STOFF``)."""
    lines = []
    for raw in _read_text(path).splitlines():
        line = raw.split("#", 1)[0].strip()
        if line:
            lines.append(line)
    if not lines:
        raise ParseError("no OFF header")
    head = lines[0].split()
    if not _OFF_KEYWORD.fullmatch(head[0]):
        raise ParseError(f"expected an OFF keyword on the first line, got {head[0]!r}")
    if len(head) > 1 and head[1].upper() == "BINARY":
        raise ParseError("binary OFF is not supported")
    count_tokens, body_start = head[1:], 1
    if not count_tokens:
        if len(lines) < 2:
            raise ParseError("missing vertex/face counts")
        count_tokens, body_start = lines[1].split(), 2
    try:
        nv, nf = int(count_tokens[0]), int(count_tokens[1])
    except (IndexError, ValueError):
        raise ParseError(f"bad counts line {' '.join(count_tokens)!r}") from None
    if nv < 0 or nf < 0:
        raise ParseError(f"negative counts {nv} {nf}")
    vlines = lines[body_start : body_start + nv]
    flines = lines[body_start + nv : body_start + nv + nf]
    if len(vlines) < nv:
        raise ParseError(f"header announces {nv} vertices but the file has {len(vlines)}")
    if len(flines) < nf:
        raise ParseError(f"header announces {nf} faces but the file has {len(flines)}")
    points = (
        np.loadtxt(vlines, dtype=np.float64, usecols=(0, 1, 2), ndmin=2) if nv else np.empty((0, 3))
    )
    if nf == 0:
        return points, None, None
    faces = None
    try:  # fast path: all face lines have the same shape ("3 a b c [r g b]")
        table = np.loadtxt(flines, dtype=np.float64, ndmin=2)
        k = table[:, 0]
        if np.all(k == k[0]) and 3 <= k[0] <= table.shape[1] - 1:
            kk = int(k[0])
            poly = table[:, 1 : kk + 1]
            if np.all(poly == np.round(poly)):
                flat = poly.astype(np.int64).ravel()
                faces = _fan(flat, np.full(nf, kk, dtype=np.int64))
    except ValueError:
        faces = None
    if faces is None:  # mixed polygon sizes or per-face colours of varying width
        flat_tokens: list[str] = []
        lens = np.empty(nf, dtype=np.int64)
        for i, line in enumerate(flines):
            parts = line.split()
            try:
                k = int(parts[0])
            except ValueError:
                raise ParseError(f"face {i}: bad vertex count {parts[0]!r}") from None
            if len(parts) < k + 1:
                raise ParseError(f"face {i}: announces {k} vertices, has {len(parts) - 1}")
            flat_tokens.extend(parts[1 : k + 1])
            lens[i] = k
        try:
            flat = np.array(flat_tokens, dtype=np.int64)
        except ValueError:
            raise ParseError("non-integer face index") from None
        faces = _fan(flat, lens)
    _check_indices(faces, len(points))
    return points, faces, None


STL_RECORD = np.dtype([("normal", "<f4", (3,)), ("v", "<f4", (3, 3)), ("attr", "<u2")])
_STL_VERTEX = re.compile(rb"vertex\s+(\S+)\s+(\S+)\s+(\S+)")


def _merge_vertices(corners: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Merge exactly equal corner rows; vertices keep the order of first appearance."""
    if len(corners) == 0:
        return np.empty((0, 3)), np.empty((0, 3), dtype=np.int64)
    uniq, first, inverse = np.unique(corners, axis=0, return_index=True, return_inverse=True)
    order = np.argsort(first, kind="stable")
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    return uniq[order], rank[inverse.reshape(-1)].reshape(-1, 3)


def _read_stl(path: Path) -> _Parsed:
    """Parse a binary or ASCII STL file and merge identical vertices."""
    data = path.read_bytes()
    n_bin = int(np.frombuffer(data[80:84], dtype="<u4")[0]) if len(data) >= 84 else -1
    if n_bin >= 0 and len(data) == 84 + 50 * n_bin:
        rec = np.frombuffer(data, dtype=STL_RECORD, count=n_bin, offset=84)
        corners = rec["v"].astype(np.float64).reshape(-1, 3)
    elif data.lstrip()[:5].lower() == b"solid":
        found = _STL_VERTEX.findall(data)
        if len(found) % 3:
            raise ParseError(f"{len(found)} vertex lines, not a multiple of 3")
        try:
            corners = np.array(found, dtype=np.float64).reshape(-1, 3)
        except ValueError:
            raise ParseError("non-numeric vertex coordinate") from None
    else:
        expected = 84 + 50 * n_bin if n_bin >= 0 else 84
        raise ParseError(
            f"not ASCII (no 'solid') and not binary: the header announces "
            f"{max(n_bin, 0)} triangles = {expected} bytes, the file has {len(data)}"
        )
    points, faces = _merge_vertices(corners)
    return points, (faces if len(faces) else None), None


#: Control bytes: no text point file holds them.
_CONTROL = bytes(c for c in range(32) if chr(c) not in "\t\n\r\f\v") + b"\x7f"


def is_count_line(line: str | bytes) -> bool:
    """Whether a point list's first data line is a point count (PTS style): one integer."""
    s = line.strip()
    return s.isdigit() and s.isascii()


def check_text(head: bytes) -> None:
    """Raise :class:`ParseError` if ``head``, a point list's first bytes, is binary data.

    A NUL byte, or more than 10 % of control characters and invalid UTF-8, is binary.
    """
    if b"\x00" in head:
        raise ParseError("not a text point file (binary data)")
    text = head.decode("utf-8", errors="replace")
    control = len(head) - len(head.translate(None, _CONTROL))
    if control + text.count("\ufffd") > 0.1 * len(text):
        raise ParseError("not a text point file (binary data)")


def _read_xyz(path: Path) -> _Parsed:
    """Parse a whitespace- or comma-separated point list (XYZ, PTS, TXT)."""
    data = path.read_bytes()
    check_text(data[:TEXT_PROBE])
    text = data.decode("utf-8", errors="replace").replace(",", " ")
    lines = text.splitlines()
    for i, line in enumerate(lines):  # skip a leading point count (PTS style)
        stripped = line.strip()
        if not stripped or stripped.startswith("#"):
            continue
        if is_count_line(stripped):
            lines[i] = ""
        break
    numbered = [(i, ln) for i, ln in enumerate(lines, start=1) if ln.split("#", 1)[0].strip()]
    if not numbered:
        return np.empty((0, 3)), None, None
    body = [ln for _, ln in numbered]
    try:
        points = np.loadtxt(body, dtype=np.float64, comments="#", usecols=(0, 1, 2), ndmin=2)
    except ValueError:
        _raise_bad_xyz_line(numbered)
        raise
    return points, None, None


def _raise_bad_xyz_line(numbered: list[tuple[int, str]]) -> None:
    """Raise :class:`ParseError` naming the first line that is not ``x y z ...`` numbers."""
    for lineno, line in numbered:
        tokens = line.split("#", 1)[0].split()
        if len(tokens) < 3:
            raise ParseError(f"line {lineno}: expected x y z, got {plural(len(tokens), 'value')}")
        for token in tokens[:3]:
            try:
                float(token)
            except ValueError:
                shown = token if len(token) <= 20 else token[:17] + "..."
                raise ParseError(f"line {lineno}: {shown!r} is not a number") from None


def npy_header(fh: BinaryIO) -> tuple[tuple[int, ...], bool, np.dtype]:
    """Read an NPY header: ``(shape, fortran_order, dtype)``; ``fh`` is left at the data."""
    version = np.lib.format.read_magic(fh)
    read = (np.lib.format.read_array_header_1_0 if version == (1, 0)
            else np.lib.format.read_array_header_2_0)
    return read(fh)


def check_npy_points(shape: tuple[int, ...], dtype: np.dtype) -> None:
    """Raise :class:`ParseError` unless an NPY array is (N, 3) real numbers: x, y, z.

    Any other column count is refused rather than guessed at: an (N, 4) array may hold
    x, y, z and an intensity, or x, y, z, w, or anything else.
    """
    if dtype.kind not in "iuf":
        raise ParseError(f"array dtype {dtype} is not a real numeric type")
    if len(shape) != 2 or shape[1] != 3:
        raise ParseError(f"array has shape {shape}, expected (N, 3): one x, y, z row per "
                         "point (save only those columns, e.g. np.save(path, a[:, :3]))")


def _read_npy(path: Path) -> _Parsed:
    """Load an ``(N, 3)`` numeric array from a ``.npy`` file (no pickles)."""
    with open(path, "rb") as fh:
        shape, _, dtype = npy_header(fh)
    check_npy_points(shape, dtype)
    arr = np.load(path, allow_pickle=False)
    return np.array(arr, dtype=np.float64), None, None


READERS: dict[str, Callable[[Path], _Parsed]] = {
    ".ply": _read_ply,
    ".obj": _read_obj,
    ".off": _read_off,
    ".stl": _read_stl,
    ".xyz": _read_xyz,
    ".pts": _read_xyz,
    ".txt": _read_xyz,
    ".npy": _read_npy,
}


# --------------------------------------------------------------------------- paths, blocks


def check_scan_path(path: str | os.PathLike[str], formats: Sequence[str],
                    unknown: str) -> tuple[Path, str]:
    """Check that ``path`` is a non-empty file with one of ``formats``; return it and its name.

    ``unknown`` words the format error, with ``{shown}`` standing for the extension.

    Raises
    ------
    ScanError
        One line starting with the path: missing, a directory, another format, empty or
        unreadable.
    """
    p = Path(path)
    name = os.fsdecode(path)
    if not p.exists():
        raise ScanError(f"{name}: no such file")
    if p.is_dir():
        raise ScanError(f"{name}: is a directory, not a scan file")
    if p.suffix.lower() not in formats:
        shown = f"'{p.suffix}'" if p.suffix else "(no extension)"
        raise ScanError(f"{name}: {unknown.format(shown=shown)} "
                        f"(expected one of {', '.join(formats)})")
    try:
        size = p.stat().st_size
    except OSError as exc:
        raise ScanError(f"{name}: cannot read ({exc.strerror})") from None
    if size == 0:
        raise ScanError(f"{name}: empty file (0 bytes)")
    return p, name


class PointBlocks(ABC):
    """Random access, by block, to the (N, 3) points of a file.

    Attributes
    ----------
    path : str
    n : int
        Number of points.
    chunk : int
        Points per block (the last block may hold fewer).
    """

    def __init__(self, path: str, n: int, chunk: int) -> None:
        self.path, self.n, self.chunk = path, n, chunk

    @property
    def n_blocks(self) -> int:
        """Number of blocks."""
        return -(-self.n // self.chunk)

    @abstractmethod
    def block(self, b: int) -> np.ndarray:
        """Points of block ``b``, (m, 3) float64."""

    def bounds(self, b: int) -> tuple[int, int]:
        """First and one-past-last point index of block ``b``."""
        return b * self.chunk, min((b + 1) * self.chunk, self.n)
