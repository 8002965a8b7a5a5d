"""The data types: :class:`Mesh` (reconstruction, hole filling, LOD) and :class:`Scan`.

Both are immutable; their constructors check what they are given and raise a one-line
:class:`~asrbf_mesh.errors.ScanError` that names the bad field.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from ._validate import check_points, float_array, plural, readonly
from .errors import ScanError

__all__ = ["Mesh", "Scan", "collinear_xy", "compact"]


@dataclass(frozen=True, eq=False)
class Mesh:
    """An immutable triangle mesh in physical (scan) units.

    Parameters
    ----------
    vertices : (V, 3) float64 array
        Vertex positions.
    faces : (F, 3) int64 array
        Triangle vertex indices, counter-clockwise seen from +view axis.
    vertex_normals : (V, 3) float64 array, optional
        Unit vertex normals.
    vertex_quality : (V,) float64 array, optional
        Per-vertex scalar (MeshLab's "quality"), e.g. a residual or a fill mask.

    Raises
    ------
    ScanError
        If ``vertices`` is not (V, 3) finite numbers, ``faces`` not (F, 3) integers
        indexing them, or a per-vertex array has the wrong shape; the message names it.
    """

    vertices: np.ndarray
    faces: np.ndarray
    vertex_normals: np.ndarray | None = None
    vertex_quality: np.ndarray | None = None

    def __post_init__(self) -> None:
        """Check and convert the arrays, then freeze them.

        Raises
        ------
        ScanError
            Naming ``vertices``, ``faces``, ``vertex_normals`` or ``vertex_quality``.
        """
        v = check_points(self.vertices, "vertices", min_points=0)
        try:
            f = np.ascontiguousarray(self.faces, dtype=np.int64)
        except (TypeError, ValueError):
            raise ScanError(f"faces must be an (F, 3) array of integers, "
                            f"got {type(self.faces).__name__}") from None
        if f.size == 0:
            f = f.reshape(0, 3)
        elif f.ndim != 2 or f.shape[1] != 3:
            raise ScanError(f"faces must be an (F, 3) array, got shape {f.shape}")
        if f.size and (f.min() < 0 or f.max() >= len(v)):
            raise ScanError(f"faces index vertices outside [0, {len(v)})")
        object.__setattr__(self, "vertices", v)
        object.__setattr__(self, "faces", f)
        for name, width in (("vertex_normals", 3), ("vertex_quality", None)):
            arr = getattr(self, name)
            if arr is None:
                continue
            arr = float_array(arr, name)
            want = (len(v), width) if width else (len(v),)
            if arr.shape != want:
                raise ScanError(f"{name} must have shape {want}, got {arr.shape}")
            object.__setattr__(self, name, arr)
        for arr in (self.vertices, self.faces, self.vertex_normals, self.vertex_quality):
            if arr is not None:
                arr.flags.writeable = False

    @property
    def n_vertices(self) -> int:
        """Number of vertices."""
        return int(len(self.vertices))

    @property
    def n_faces(self) -> int:
        """Number of triangles."""
        return int(len(self.faces))


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
        If ``points`` is not (N, 3) real numbers (or holds NaN or infinity), ``faces``
        is not (F, 3) integer, a face indexes a point that does not exist, or
        ``grid_shape`` is not two positive ints. The message names the field (and the
        ``source``, when there is one).

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
        pts = check_points(pts, f"{where}points", min_points=0)
        object.__setattr__(self, "points", readonly(pts, self.points))

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
                        f"{where}{plural(n_bad, 'face')} {verb} points outside [0, {n})"
                    )
                f = np.ascontiguousarray(f, dtype=np.int64)
                faces = readonly(f, self.faces)
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
        """Return the scan as a :class:`~asrbf_mesh.Mesh` (arrays are shared).

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


def collinear_xy(xy: np.ndarray) -> bool:
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



def compact(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Drop the vertices no face references (in numpy; keeps the others' order).

    Parameters
    ----------
    vertices : (V, 3) array
    faces : (F, 3) int array

    Returns
    -------
    vertices : (V', 3) float64 array
    faces : (F, 3) int64 array
        Re-indexed into the kept vertices.

    Examples
    --------
    >>> v, f = compact(np.zeros((5, 3)), np.array([[4, 1, 2]]))
    >>> len(v), f.tolist()
    (3, [[2, 0, 1]])
    """
    f = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    used = np.unique(f)
    return np.asarray(vertices, dtype=np.float64)[used], np.searchsorted(used, f)
