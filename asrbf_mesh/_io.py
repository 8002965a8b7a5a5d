"""Reading range scans and writing triangle meshes.

:func:`load_scan` turns a scan file (PLY, OBJ, OFF, STL, XYZ/PTS/TXT point lists or
NPY arrays) into an immutable :class:`Scan`: float64 points, optional triangles, and the
range-grid shape when the file carried one (Stanford ``range_grid`` PLY files are
triangulated the way MeshLab does it). :func:`save_mesh` writes a
:class:`~asrbf_mesh._mesh.Mesh` as binary PLY, OBJ, OFF or binary STL, atomically.

Every problem with an input file surfaces as a one-line
:class:`~asrbf_mesh.errors.ScanError` that starts with the file's path.
"""

from __future__ import annotations

import importlib.util
import os
import re
import warnings
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import plyfile

from ._atomic import atomic_path, check_output_path
from ._mesh import Mesh
from .errors import ConfigError, ScanError

__all__ = [
    "Scan",
    "load_scan",
    "save_mesh",
    "face_map_path",
    "SUPPORTED_SCAN_FORMATS",
    "SUPPORTED_MESH_FORMATS",
]

#: File extensions :func:`load_scan` understands (compared case-insensitively).
SUPPORTED_SCAN_FORMATS: tuple[str, ...] = (
    ".ply",
    ".obj",
    ".off",
    ".stl",
    ".xyz",
    ".pts",
    ".txt",
    ".npy",
)

#: File extensions :func:`save_mesh` can write (compared case-insensitively).
SUPPORTED_MESH_FORMATS: tuple[str, ...] = (".ply", ".obj", ".off", ".stl")

_FORMAT_NAMES = {
    ".ply": "PLY",
    ".obj": "OBJ",
    ".off": "OFF",
    ".stl": "STL",
    ".xyz": "XYZ",
    ".pts": "PTS",
    ".txt": "TXT",
    ".npy": "NPY",
}

_FACE_MAP_PARTS = ("tests", "sample_meshes", "rangemaps", "face000.ply")

_MAX_REASON = 200


class _ParseError(Exception):
    """A format-specific problem found by one of the parsers (message without path)."""


# --------------------------------------------------------------------------- Scan


def _readonly_copy(value: object, arr: np.ndarray) -> np.ndarray:
    """Return ``arr`` made read-only, copying it first if it may alias a writeable input."""
    if isinstance(value, np.ndarray) and value.flags.writeable and np.may_share_memory(arr, value):
        arr = arr.copy()
    arr.flags.writeable = False
    return arr


@dataclass(frozen=True, eq=False)
class Scan:
    """An immutable range scan: points, optional triangles and provenance.

    Parameters
    ----------
    points : (N, 3) array_like of float
        Point coordinates in scan units. Stored as a C-contiguous, read-only float64
        array (copied when the input is a writeable array it would otherwise alias).
    faces : (F, 3) array_like of int, optional
        Triangles as indices into ``points``. Stored as a read-only int64 array; an
        empty face list is stored as ``None`` (a point cloud).
    source : str or os.PathLike, optional
        Path the scan was loaded from; stored as ``str``.
    grid_shape : tuple of int, optional
        ``(rows, cols)`` of the range grid the file carried, if any.

    Raises
    ------
    ScanError
        If ``points`` is not (N, 3) numeric, ``faces`` is not (F, 3) integer, a face
        indexes a point that does not exist, or ``grid_shape`` is not two positive ints.

    Examples
    --------
    >>> scan = Scan([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.5]], faces=[[0, 1, 2]])
    >>> scan.n_points, scan.points.dtype, scan.faces.dtype
    (3, dtype('float64'), dtype('int64'))
    >>> round(scan.bbox_diagonal, 3)
    1.5
    """

    points: np.ndarray
    faces: np.ndarray | None = None
    source: str | None = None
    grid_shape: tuple[int, int] | None = None

    def __post_init__(self) -> None:
        """Validate and convert the fields, then freeze the arrays."""
        source = None if self.source is None else os.fspath(self.source)
        if source is not None and not isinstance(source, str):
            raise ScanError(f"source must be a path string, got {type(source).__name__}")
        object.__setattr__(self, "source", source)
        where = f"{source}: " if source else ""

        try:
            pts = np.asarray(self.points)
        except (TypeError, ValueError) as exc:
            raise ScanError(f"{where}points are not a numeric array ({exc})") from None
        if pts.dtype.kind not in "iuf":
            raise ScanError(f"{where}points must be real numbers, got dtype {pts.dtype}")
        if pts.ndim != 2 or pts.shape[1] != 3:
            raise ScanError(f"{where}points must have shape (N, 3), got {pts.shape}")
        pts = np.ascontiguousarray(pts, dtype=np.float64)
        object.__setattr__(self, "points", _readonly_copy(self.points, pts))

        faces = self.faces
        if faces is not None:
            try:
                f = np.asarray(faces)
            except (TypeError, ValueError) as exc:
                raise ScanError(f"{where}faces are not an integer array ({exc})") from None
            if f.size == 0:
                faces = None
            else:
                if f.dtype.kind not in "iu":
                    raise ScanError(f"{where}faces must be integers, got dtype {f.dtype}")
                if f.ndim != 2 or f.shape[1] != 3:
                    raise ScanError(f"{where}faces must have shape (F, 3), got {f.shape}")
                n = len(pts)
                bad = (f < 0) | (f >= n)
                if bad.any():
                    n_bad = int(bad.any(axis=1).sum())
                    verb = "indexes" if n_bad == 1 else "index"
                    raise ScanError(
                        f"{where}{_plural(n_bad, 'face')} {verb} points outside [0, {n})"
                    )
                f = np.ascontiguousarray(f, dtype=np.int64)
                faces = _readonly_copy(self.faces, f)
        object.__setattr__(self, "faces", faces)

        if self.grid_shape is not None:
            try:
                rows, cols = (int(x) for x in self.grid_shape)
            except (TypeError, ValueError):
                raise ScanError(
                    f"{where}grid_shape must be (rows, cols), got {self.grid_shape!r}"
                ) from None
            if rows < 1 or cols < 1:
                raise ScanError(f"{where}grid_shape must be positive, got {(rows, cols)}")
            object.__setattr__(self, "grid_shape", (rows, cols))

    def __repr__(self) -> str:
        return (
            f"Scan(n_points={self.n_points}, n_faces={self.n_faces}, "
            f"source={self.source!r}, grid_shape={self.grid_shape!r})"
        )

    @property
    def n_points(self) -> int:
        """Number of points."""
        return int(len(self.points))

    @property
    def n_faces(self) -> int:
        """Number of triangles (0 for a point cloud)."""
        return 0 if self.faces is None else int(len(self.faces))

    @property
    def bbox_diagonal(self) -> float:
        """Length of the diagonal of the axis-aligned bounding box (0.0 when empty)."""
        if len(self.points) == 0:
            return 0.0
        return float(np.linalg.norm(np.ptp(self.points, axis=0)))

    def to_mesh(self) -> Mesh:
        """Return the scan as a :class:`~asrbf_mesh._mesh.Mesh` (arrays are shared).

        Returns
        -------
        Mesh
            Mesh whose vertices are the scan points (unused points included).

        Raises
        ------
        ScanError
            If the scan has no faces.
        """
        if self.faces is None:
            name = self.source or "scan"
            raise ScanError(f"{name}: the scan has no faces (a point cloud), not a mesh")
        return Mesh(vertices=self.points, faces=self.faces)


# --------------------------------------------------------------------------- helpers


def _one_line(exc: BaseException) -> str:
    """Format an exception as a short single line."""
    text = " ".join(str(exc).split())
    if not text:
        text = type(exc).__name__
    if len(text) > _MAX_REASON:
        text = text[: _MAX_REASON - 3] + "..."
    return text


def _plural(n: int, word: str) -> str:
    """``'1 point'`` / ``'3 points'``."""
    return f"{n} {word}{'' if n == 1 else 's'}"


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
        raise _ParseError(f"face {k} has {int(lengths[k])} vertices (at least 3 needed)")
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
        raise _ParseError(f"unexpected list array of shape {arr.shape}")
    lengths = np.fromiter((len(a) for a in lists), dtype=np.int64, count=len(lists))
    if lengths.sum() == 0:
        return np.empty(0, dtype=np.int64), lengths
    flat = np.concatenate([np.asarray(a).ravel() for a in lists if len(a)])
    if flat.dtype.kind not in "iu":
        raise _ParseError(f"list indices must be integers, got {flat.dtype}")
    return flat.astype(np.int64), lengths


def _check_indices(faces: np.ndarray, n_points: int, what: str = "face") -> None:
    """Raise :class:`_ParseError` if some index of ``faces`` is outside ``[0, n_points)``."""
    if faces.size == 0:
        return
    bad = (faces < 0) | (faces >= n_points)
    if bad.any():
        n_bad = int(bad.reshape(len(faces), -1).any(axis=1).sum())
        first = int(faces[bad][0])
        verb = "references" if n_bad == 1 else "reference"
        raise _ParseError(
            f"{_plural(n_bad, what)} {verb} vertices outside [0, {n_points}) (e.g. index {first})"
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
                raise _ParseError(f"bad {parts[0]} value {parts[1]!r} in header") from None
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
    raise _ParseError(
        f"element '{element.name}' has no {' / '.join(repr(n) for n in names)} property"
    )


def _read_ply(path: Path) -> _Parsed:
    """Parse a PLY file (ASCII or binary) with :mod:`plyfile`."""
    fast = {"face": {"vertex_indices": 3, "vertex_index": 3}}
    with open(path, "rb") as fh:
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
            raise _ParseError(
                f"{_one_line(exc)}: the header announces {exc.element.count} "
                f"'{exc.element.name}' rows (file truncated, or the header's counts are wrong)"
            ) from None
        if not ply.text:
            # plyfile stops after the announced elements: data left over (more than the
            # blank or NUL padding some writers append) means that the header's counts
            # do not describe the file.
            extra = os.fstat(fh.fileno()).st_size - fh.tell()
            if extra > 0 and fh.read().strip(b" \t\r\n\x00"):
                counts = ", ".join(f"{e.count} {e.name}" for e in ply.elements)
                raise _ParseError(
                    f"{_plural(extra, 'byte')} after the elements the header announces "
                    f"({counts}): the header's counts do not match the data"
                )

    names = [e.name for e in ply.elements]
    if "vertex" not in names:
        raise _ParseError("no 'vertex' element")
    vert = ply["vertex"]
    for c in "xyz":
        if c not in vert:
            raise _ParseError(f"the vertex element has no '{c}' property")
        if vert.data[c].dtype.kind not in "iuf":
            raise _ParseError(f"vertex property '{c}' is not numeric")
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
                raise _ParseError("range_grid element but no num_rows/num_cols in the header")
            raise _ParseError(
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
            raise _ParseError(
                f"{_plural(n_bad, 'range_grid cell')} {verb} vertices outside "
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
        raise _ParseError(f"bad face index {bad!r}") from None


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
                raise _ParseError(f"line {lineno}: a vertex needs 3 coordinates")
            verts.append(parts[1:4])
        elif key == "f":
            face_tokens.extend(parts[1:])
            lengths.append(len(parts) - 1)
            bases.append(len(verts))
    try:
        points = np.array(verts, dtype=np.float64).reshape(-1, 3)
    except ValueError as exc:
        raise _ParseError(f"bad vertex coordinate ({_one_line(exc)})") from None
    if not lengths:
        return points, None, None
    idx = _face_indices(face_tokens)
    lens = np.array(lengths, dtype=np.int64)
    base = np.repeat(np.array(bases, dtype=np.int64), lens)
    if (idx == 0).any():
        raise _ParseError("face index 0 (OBJ indices start at 1)")
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
        raise _ParseError("no OFF header")
    head = lines[0].split()
    if not _OFF_KEYWORD.fullmatch(head[0]):
        raise _ParseError(f"expected an OFF keyword on the first line, got {head[0]!r}")
    if len(head) > 1 and head[1].upper() == "BINARY":
        raise _ParseError("binary OFF is not supported")
    count_tokens, body_start = head[1:], 1
    if not count_tokens:
        if len(lines) < 2:
            raise _ParseError("missing vertex/face counts")
        count_tokens, body_start = lines[1].split(), 2
    try:
        nv, nf = int(count_tokens[0]), int(count_tokens[1])
    except (IndexError, ValueError):
        raise _ParseError(f"bad counts line {' '.join(count_tokens)!r}") from None
    if nv < 0 or nf < 0:
        raise _ParseError(f"negative counts {nv} {nf}")
    vlines = lines[body_start : body_start + nv]
    flines = lines[body_start + nv : body_start + nv + nf]
    if len(vlines) < nv:
        raise _ParseError(f"header announces {nv} vertices but the file has {len(vlines)}")
    if len(flines) < nf:
        raise _ParseError(f"header announces {nf} faces but the file has {len(flines)}")
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
                raise _ParseError(f"face {i}: bad vertex count {parts[0]!r}") from None
            if len(parts) < k + 1:
                raise _ParseError(f"face {i}: announces {k} vertices, has {len(parts) - 1}")
            flat_tokens.extend(parts[1 : k + 1])
            lens[i] = k
        try:
            flat = np.array(flat_tokens, dtype=np.int64)
        except ValueError:
            raise _ParseError("non-integer face index") from None
        faces = _fan(flat, lens)
    _check_indices(faces, len(points))
    return points, faces, None


_STL_RECORD = np.dtype([("normal", "<f4", (3,)), ("v", "<f4", (3, 3)), ("attr", "<u2")])
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
        rec = np.frombuffer(data, dtype=_STL_RECORD, count=n_bin, offset=84)
        corners = rec["v"].astype(np.float64).reshape(-1, 3)
    elif data.lstrip()[:5].lower() == b"solid":
        found = _STL_VERTEX.findall(data)
        if len(found) % 3:
            raise _ParseError(f"{len(found)} vertex lines, not a multiple of 3")
        try:
            corners = np.array(found, dtype=np.float64).reshape(-1, 3)
        except ValueError:
            raise _ParseError("non-numeric vertex coordinate") from None
    else:
        expected = 84 + 50 * n_bin if n_bin >= 0 else 84
        raise _ParseError(
            f"not ASCII (no 'solid') and not binary: the header announces "
            f"{max(n_bin, 0)} triangles = {expected} bytes, the file has {len(data)}"
        )
    points, faces = _merge_vertices(corners)
    return points, (faces if len(faces) else None), None


def _read_xyz(path: Path) -> _Parsed:
    """Parse a whitespace- or comma-separated point list (XYZ, PTS, TXT)."""
    text = _read_text(path).replace(",", " ")
    lines = text.splitlines()
    for i, line in enumerate(lines):  # skip a leading point count (PTS style)
        stripped = line.strip()
        if not stripped or stripped.startswith("#"):
            continue
        if re.fullmatch(r"\d+", stripped):
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
    """Raise :class:`_ParseError` naming the first line that is not ``x y z ...`` numbers."""
    for lineno, line in numbered:
        tokens = line.split("#", 1)[0].split()
        if len(tokens) < 3:
            raise _ParseError(f"line {lineno}: expected x y z, got {_plural(len(tokens), 'value')}")
        for token in tokens[:3]:
            try:
                float(token)
            except ValueError:
                shown = token if len(token) <= 20 else token[:17] + "..."
                raise _ParseError(f"line {lineno}: {shown!r} is not a number") from None


def _read_npy(path: Path) -> _Parsed:
    """Load an ``(N, >=3)`` numeric array from a ``.npy`` file (no pickles)."""
    arr = np.load(path, allow_pickle=False)
    if not isinstance(arr, np.ndarray):
        raise _ParseError("not a single array")
    if arr.dtype.kind not in "iuf":
        raise _ParseError(f"array dtype {arr.dtype} is not a real numeric type")
    if arr.ndim != 2 or arr.shape[1] < 3:
        raise _ParseError(f"array has shape {arr.shape}, expected (N, 3) or (N, >=3)")
    return np.array(arr[:, :3], dtype=np.float64), None, None


_READERS: dict[str, Callable[[Path], _Parsed]] = {
    ".ply": _read_ply,
    ".obj": _read_obj,
    ".off": _read_off,
    ".stl": _read_stl,
    ".xyz": _read_xyz,
    ".pts": _read_xyz,
    ".txt": _read_xyz,
    ".npy": _read_npy,
}


# --------------------------------------------------------------------------- load_scan


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


def load_scan(
    path: str | os.PathLike[str], *, min_points: int = 10, height_field: bool = True
) -> Scan:
    """Load a range scan or mesh file as a :class:`Scan`.

    Parameters
    ----------
    path : str or os.PathLike
        Scan file; the format is chosen by its extension (case-insensitive), one of
        :data:`SUPPORTED_SCAN_FORMATS`:

        ``.ply``
            ASCII or binary. Vertex ``x, y, z`` of any numeric type. A ``face`` element
            gives the triangles (polygons are fanned); otherwise a Stanford
            ``range_grid`` element (with ``num_rows``/``num_cols`` in ``obj_info``) is
            triangulated: two triangles per complete 2x2 block of samples, split along
            the shorter diagonal, one triangle per block with three samples.
        ``.obj``
            ``v`` and ``f`` lines; ``a/b/c`` and negative indices; polygons fanned.
        ``.off``
            ASCII ``OFF``, ``COFF``, ``NOFF``, ``CNOFF``, ``STOFF``; ``#`` comments.
        ``.stl``
            ASCII or binary; exactly equal corners are merged into shared vertices.
        ``.xyz``, ``.pts``, ``.txt``
            One point per line, columns separated by whitespace or commas, the first
            three are x, y, z; ``#`` comments; a leading single-integer count line is
            skipped.
        ``.npy``
            An (N, 3) or (N, >=3) real array; the first three columns are used.
    min_points : int, default 10
        Fewest points accepted.
    height_field : bool, default True
        Also reject points that cannot make a height field over (x, y): all identical,
        no x or y extent, or all on one line in (x, y). ``False`` checks the file only
        (for a mesh of any shape).

    Returns
    -------
    Scan
        Points (unused mesh vertices kept), faces or ``None``, the source path and the
        range-grid shape ``(rows, cols)`` when the file had one.

    Raises
    ------
    ScanError
        One line starting with ``path`` if the file is missing, a directory, empty,
        of an unknown format, unreadable or corrupt (including truncated data and a
        binary PLY whose header counts do not match its data), has faces indexing
        missing vertices, NaN or infinite coordinates, fewer than ``min_points``
        points, or (with ``height_field``) points all identical, with no extent in x
        or in y, or all on one line in (x, y) (a height field needs an area; a zero z
        extent, a flat scan, is fine).
    ConfigError
        If ``min_points`` is less than 1.
    """
    if isinstance(min_points, bool) or not isinstance(min_points, (int, np.integer)):
        raise ConfigError(f"min_points must be an integer, got {min_points!r}")
    if min_points < 1:
        raise ConfigError(f"min_points must be at least 1, got {min_points}")
    p, name = check_scan_path(path, SUPPORTED_SCAN_FORMATS, "unknown scan format {shown}")
    ext = p.suffix.lower()
    reader = _READERS[ext]

    fmt = _FORMAT_NAMES[ext]
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            points, faces, grid_shape = reader(p)
            points = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    except MemoryError:
        raise
    except OSError as exc:
        reason = exc.strerror or _one_line(exc)
        raise ScanError(f"{name}: cannot read {fmt}: {reason}") from None
    except Exception as exc:  # parser boundary: never leak a third-party traceback
        raise ScanError(f"{name}: cannot read {fmt}: {_one_line(exc)}") from None

    finite = np.isfinite(points).all(axis=1)
    if not finite.all():
        n_bad = int((~finite).sum())
        verb = "has" if n_bad == 1 else "have"
        raise ScanError(f"{name}: {_plural(n_bad, 'point')} {verb} NaN or infinite coordinates")
    if len(points) < min_points:
        n_pts = _plural(len(points), "point")
        raise ScanError(f"{name}: only {n_pts}, at least {min_points} needed")
    if height_field:
        _check_footprint(points, name)
    return Scan(points=points, faces=faces, source=name, grid_shape=grid_shape)


def _collinear_xy(xy: np.ndarray) -> bool:
    """Whether (N, 2) points lie on one line, up to rounding of their coordinates.

    The RMS distance from the best-fitting line (the smaller principal axis) is
    compared with the longer one and with the float64 resolution at the points'
    magnitude, so that a shift of the whole scan by 1e12 changes nothing.
    """
    if len(xy) < 3:
        return True
    centred = xy - xy.mean(axis=0)
    hi, lo = np.linalg.svd(centred, compute_uv=False) / np.sqrt(len(xy))
    resolution = 64 * np.finfo(np.float64).eps * float(np.abs(xy).max())
    return bool(lo <= max(1e-9 * hi, resolution))


def _check_footprint(points: np.ndarray, name: str) -> None:
    """Raise :class:`ScanError` unless the points spread over an area in (x, y)."""
    extent = np.ptp(points, axis=0)
    if not extent.any():
        raise ScanError(f"{name}: all {_plural(len(points), 'point')} are identical")
    for axis, coord in ((0, "x"), (1, "y")):
        if extent[axis] == 0:
            raise ScanError(
                f"{name}: all points share the same {coord} (zero {coord} extent); "
                "a height field needs an x and a y extent"
            )
    if _collinear_xy(points[:, :2]):
        raise ScanError(
            f"{name}: all points lie on one line in (x, y); "
            "a height field needs points spread over an area in x and y"
        )


# --------------------------------------------------------------------------- save_mesh


def _ply_header(vertex: np.ndarray, n_faces: int) -> bytes:
    """Binary little-endian PLY header for ``vertex`` and ``n_faces`` triangles.

    The header comes from :mod:`plyfile`; the body is written by the caller with
    ``tobytes`` because plyfile serialises list properties one row at a time.
    """
    elements = [plyfile.PlyElement.describe(vertex, "vertex")]
    if n_faces:
        # np.empty touches no memory: it only tells describe() the count and types.
        face = np.empty(n_faces, dtype=[("vertex_indices", "<i4", (3,))])
        el = plyfile.PlyElement.describe(
            face, "face", len_types={"vertex_indices": "u1"}, val_types={"vertex_indices": "i4"}
        )
        elements.append(el)
    ply = plyfile.PlyData(elements, text=False, byte_order="<", comments=["asrbf-mesh"])
    return ply.header.encode("ascii") + b"\n"


def _write_ply(
    tmp: Path,
    vertices: np.ndarray,
    faces: np.ndarray | None,
    normals: np.ndarray | None,
    quality: np.ndarray | None,
) -> None:
    """Binary little-endian PLY with optional normals and quality."""
    fields = [("x", "<f8"), ("y", "<f8"), ("z", "<f8")]
    if normals is not None:
        fields += [("nx", "<f4"), ("ny", "<f4"), ("nz", "<f4")]
    if quality is not None:
        fields.append(("quality", "<f4"))
    vert = np.empty(len(vertices), dtype=fields)
    for i, c in enumerate("xyz"):
        vert[c] = vertices[:, i]
    if normals is not None:
        for i, c in enumerate(("nx", "ny", "nz")):
            vert[c] = normals[:, i]
    if quality is not None:
        vert["quality"] = quality
    n_faces = 0 if faces is None else len(faces)
    with open(tmp, "wb") as fh:
        fh.write(_ply_header(vert, n_faces))
        fh.write(vert.tobytes())
        if n_faces:
            body = np.empty(n_faces, dtype=[("n", "u1"), ("v", "<i4", (3,))])
            body["n"] = 3
            body["v"] = faces
            fh.write(body.tobytes())


def _write_obj(
    tmp: Path,
    vertices: np.ndarray,
    faces: np.ndarray | None,
    normals: np.ndarray | None,
    quality: np.ndarray | None,
) -> None:
    """Wavefront OBJ (``v``, optional ``vn``, ``f`` lines, 1-based)."""
    with open(tmp, "w", encoding="ascii", newline="\n") as fh:
        fh.write("# asrbf-mesh\n")
        np.savetxt(fh, vertices, fmt="v %.17g %.17g %.17g")
        if normals is not None:
            np.savetxt(fh, normals, fmt="vn %.9g %.9g %.9g")
        if faces is not None and len(faces):
            f1 = faces + 1
            if normals is not None:
                np.savetxt(fh, np.repeat(f1, 2, axis=1), fmt="f %d//%d %d//%d %d//%d")
            else:
                np.savetxt(fh, f1, fmt="f %d %d %d")


def _write_off(
    tmp: Path,
    vertices: np.ndarray,
    faces: np.ndarray | None,
    normals: np.ndarray | None,
    quality: np.ndarray | None,
) -> None:
    """ASCII OFF (normals and quality are not stored)."""
    n_faces = 0 if faces is None else len(faces)
    with open(tmp, "w", encoding="ascii", newline="\n") as fh:
        fh.write(f"OFF\n{len(vertices)} {n_faces} 0\n")
        np.savetxt(fh, vertices, fmt="%.17g %.17g %.17g")
        if n_faces:
            np.savetxt(fh, faces, fmt="3 %d %d %d")


def _write_stl(
    tmp: Path,
    vertices: np.ndarray,
    faces: np.ndarray | None,
    normals: np.ndarray | None,
    quality: np.ndarray | None,
) -> None:
    """Binary STL (float32, unit face normals; unused vertices are lost)."""
    assert faces is not None
    tri = vertices[faces]
    fn = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    norm = np.linalg.norm(fn, axis=1, keepdims=True)
    fn = np.divide(fn, norm, out=np.zeros_like(fn), where=norm > 0)
    rec = np.zeros(len(faces), dtype=_STL_RECORD)
    rec["normal"] = fn
    rec["v"] = tri
    header = b"binary STL written by asrbf-mesh".ljust(80, b" ")
    with open(tmp, "wb") as fh:
        fh.write(header)
        fh.write(np.array([len(faces)], dtype="<u4").tobytes())
        fh.write(rec.tobytes())


_WRITERS = {".ply": _write_ply, ".obj": _write_obj, ".off": _write_off, ".stl": _write_stl}


def save_mesh(
    mesh: Mesh | Scan,
    path: str | os.PathLike[str],
    *,
    overwrite_inputs: Iterable[str | os.PathLike[str] | None] = (),
) -> Path:
    """Write a mesh (or a scan) to a file, atomically; the format follows the extension.

    Parameters
    ----------
    mesh : Mesh or Scan
        What to write. A :class:`Scan` with faces is written as its mesh; a scan
        without faces is written as points only (PLY, OBJ or OFF; not STL).
    path : str or os.PathLike
        Output file, one of :data:`SUPPORTED_MESH_FORMATS` (case-insensitive):
        ``.ply`` (binary little-endian; float64 x, y, z, plus float32 ``nx, ny, nz``
        and ``quality`` when the mesh has vertex normals / quality), ``.obj``
        (with ``vn`` normals when present), ``.off``, ``.stl`` (binary, float32).
    overwrite_inputs : iterable of path, optional
        Input files that must not be overwritten; a scan's own ``source`` is always
        protected.

    Returns
    -------
    pathlib.Path
        The written path.

    Raises
    ------
    ScanError
        If the extension is unknown, a faceless scan is saved as STL, or writing fails.
        Nothing is written in those cases.
    AsrbfError
        If the output directory is missing, ``path`` is a directory, or ``path`` is one
        of the protected input files.
    TypeError
        If ``mesh`` is neither a :class:`Mesh` nor a :class:`Scan`.
    """
    out = Path(path)
    name = os.fsdecode(path)
    ext = out.suffix.lower()
    writer = _WRITERS.get(ext)
    if writer is None:
        shown = f"'{out.suffix}'" if out.suffix else "(no extension)"
        raise ScanError(
            f"{name}: unknown mesh format {shown} "
            f"(expected one of {', '.join(SUPPORTED_MESH_FORMATS)})"
        )
    protected = [p for p in overwrite_inputs if p is not None]
    normals = quality = None
    if isinstance(mesh, Scan):
        vertices, faces = mesh.points, mesh.faces
        if mesh.source is not None:
            protected.append(mesh.source)
        if faces is None and ext == ".stl":
            raise ScanError(f"{name}: STL cannot store a point cloud without faces")
    elif isinstance(mesh, Mesh):
        vertices, faces = mesh.vertices, mesh.faces
        normals, quality = mesh.vertex_normals, mesh.vertex_quality
    else:
        raise TypeError(f"save_mesh expects a Mesh or a Scan, got {type(mesh).__name__}")
    if faces is not None and len(faces) == 0:
        faces = None
        if ext == ".stl":
            raise ScanError(f"{name}: STL cannot store a mesh without faces")
    if faces is not None and len(vertices) > np.iinfo(np.int32).max:
        raise ScanError(f"{name}: too many vertices ({len(vertices)}) for 32-bit indices")
    check_output_path(out, *protected)
    try:
        with atomic_path(out) as tmp:
            writer(tmp, vertices, faces, normals, quality)
    except OSError as exc:
        raise ScanError(f"{name}: cannot write ({exc.strerror or _one_line(exc)})") from None
    return out


# --------------------------------------------------------------------------- sample data


def face_map_path() -> Path:
    """Path of the face range map that ships with :mod:`pymeshlab`'s test data.

    The file is ``pymeshlab/tests/sample_meshes/rangemaps/face000.ply`` (binary PLY,
    85,849 vertices, 166,259 triangles). :mod:`pymeshlab` is located without being
    imported.

    Returns
    -------
    pathlib.Path
        Absolute path of ``face000.ply``.

    Raises
    ------
    ScanError
        If :mod:`pymeshlab` is not installed or its installation lacks the file.
    """
    try:
        spec = importlib.util.find_spec("pymeshlab")
    except (ImportError, ValueError):
        spec = None
    if spec is None:
        raise ScanError(
            "pymeshlab is not installed; the sample face range map "
            f"({'/'.join(_FACE_MAP_PARTS)}) ships with it"
        )
    roots = list(spec.submodule_search_locations or [])
    if not roots and spec.origin:
        roots = [str(Path(spec.origin).parent)]
    candidates = [Path(root).joinpath(*_FACE_MAP_PARTS) for root in roots]
    for cand in candidates:
        if cand.is_file():
            return cand.resolve()
    where = candidates[0] if candidates else Path("pymeshlab", *_FACE_MAP_PARTS)
    raise ScanError(f"{where}: face range map not found in the installed pymeshlab package")
