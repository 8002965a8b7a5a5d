"""Reading range scans and writing triangle meshes: the front of the file formats.

:func:`load_scan` turns a scan file (PLY, OBJ, OFF, STL, XYZ/PTS/TXT point lists or
NPY arrays) into an immutable :class:`~asrbf_mesh.Scan`: float64 points, optional
triangles, and the range-grid shape when the file carried one (Stanford ``range_grid``
PLY files are triangulated the way MeshLab does it). :func:`save_mesh` writes a
:class:`~asrbf_mesh.Mesh` as binary PLY, OBJ, OFF or binary STL, atomically.
The parsers are in :mod:`asrbf_mesh._readers`, the writers in :mod:`asrbf_mesh._writers`.

Every problem with an input file surfaces as a one-line
:class:`~asrbf_mesh.errors.ScanError` that starts with the file's path.
"""

from __future__ import annotations

import importlib.util
import os
import warnings
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

from ._atomic import atomic_path, check_output_path
from ._mesh import Mesh, Scan, collinear_xy
from ._readers import FORMAT_NAMES, READERS, SUPPORTED_SCAN_FORMATS, check_scan_path
from ._validate import check_int, one_line, plural
from ._writers import SUPPORTED_MESH_FORMATS, WRITERS
from .errors import ScanError

__all__ = [
    "Scan",
    "load_scan",
    "save_mesh",
    "check_scan_path",
    "face_map_path",
    "SUPPORTED_SCAN_FORMATS",
    "SUPPORTED_MESH_FORMATS",
]

_FACE_MAP_PARTS = ("tests", "sample_meshes", "rangemaps", "face000.ply")


def load_scan(
    path: str | os.PathLike[str], *, min_points: int = 10, height_field: bool = True,
    options: Any = None,
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
            skipped. A binary file is refused as such.
        ``.npy``
            An (N, 3) real array: x, y, z. Other column counts are refused (an extra
            column may be an intensity, a weight or anything else).
        ``.png``, ``.tif``, ``.tiff``, ``.npz`` (and ``.npy`` with ``options.cell``)
            Range grids: depth images (16-bit PNG, 16-bit or float TIFF) and elevation
            grids (GeoTIFF, arrays), triangulated by pixel adjacency and cut at depth
            jumps (:mod:`asrbf_mesh._range_io`).
        ``.las``, ``.laz``
            LiDAR point clouds (the ``lidar`` extra), filtered by class and return.
    min_points : int, default 10
        Fewest points accepted.
    options : RangeOptions or dict, optional
        How to read range data (:class:`~asrbf_mesh._range_io.RangeOptions`: depth
        scale, no-data value, intrinsics, cell size, LiDAR classes and returns).
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
    min_points = check_int(min_points, "min_points", 1)
    from ._range_io import RangeOptions, is_range_path, load_range

    opts = RangeOptions.of(options)
    p, name = check_scan_path(path, SUPPORTED_SCAN_FORMATS, "unknown scan format {shown}")
    if is_range_path(p, opts):
        scan = load_range(p, opts)[0]
        _check_points(scan.points, name, min_points, height_field)
        return scan
    ext = p.suffix.lower()
    reader = READERS[ext]

    fmt = FORMAT_NAMES[ext]
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            points, faces, grid_shape = reader(p)
            points = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    except MemoryError:
        raise
    except OSError as exc:
        reason = exc.strerror or one_line(exc)
        raise ScanError(f"{name}: cannot read {fmt}: {reason}") from None
    except Exception as exc:  # parser boundary: never leak a third-party traceback
        raise ScanError(f"{name}: cannot read {fmt}: {one_line(exc)}") from None

    _check_points(points, name, min_points, height_field)
    return Scan(points=points, faces=faces, source=name, grid_shape=grid_shape)


def _check_points(points: np.ndarray, name: str, min_points: int, height_field: bool) -> None:
    """Raise :class:`ScanError` for non-finite points, too few, or (height field) no area."""
    finite = np.isfinite(points).all(axis=1)
    if not finite.all():
        n_bad = int((~finite).sum())
        verb = "has" if n_bad == 1 else "have"
        raise ScanError(f"{name}: {plural(n_bad, 'point')} {verb} NaN or infinite coordinates")
    if len(points) < min_points:
        n_pts = plural(len(points), "point")
        raise ScanError(f"{name}: only {n_pts}, at least {min_points} needed")
    if height_field:
        _check_footprint(points, name)


def _check_footprint(points: np.ndarray, name: str) -> None:
    """Raise :class:`ScanError` unless the points spread over an area in (x, y)."""
    extent = np.ptp(points, axis=0)
    if not extent.any():
        raise ScanError(f"{name}: all {plural(len(points), 'point')} are identical")
    for axis, coord in ((0, "x"), (1, "y")):
        if extent[axis] == 0:
            raise ScanError(
                f"{name}: all points share the same {coord} (zero {coord} extent); "
                "a height field needs an x and a y extent"
            )
    if collinear_xy(points[:, :2]):
        raise ScanError(
            f"{name}: all points lie on one line in (x, y); "
            "a height field needs points spread over an area in x and y"
        )



# --------------------------------------------------------------------------- save_mesh


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
    writer = WRITERS.get(ext)
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
        raise ScanError(f"{name}: cannot write ({exc.strerror or one_line(exc)})") from None
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
