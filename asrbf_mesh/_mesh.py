"""The triangle mesh type shared by reconstruction, hole filling and LOD."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Mesh", "compact"]


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
    """

    vertices: np.ndarray
    faces: np.ndarray
    vertex_normals: np.ndarray | None = None
    vertex_quality: np.ndarray | None = None

    def __post_init__(self) -> None:
        v = np.ascontiguousarray(self.vertices, dtype=np.float64)
        f = np.ascontiguousarray(self.faces, dtype=np.int64).reshape(-1, 3)
        if v.ndim != 2 or v.shape[1] != 3:
            raise ValueError(f"vertices must have shape (V, 3), got {v.shape}")
        if f.size and (f.min() < 0 or f.max() >= len(v)):
            raise ValueError(f"faces index vertices outside [0, {len(v)})")
        object.__setattr__(self, "vertices", v)
        object.__setattr__(self, "faces", f)
        for name, width in (("vertex_normals", 3), ("vertex_quality", None)):
            arr = getattr(self, name)
            if arr is None:
                continue
            arr = np.ascontiguousarray(arr, dtype=np.float64)
            want = (len(v), width) if width else (len(v),)
            if arr.shape != want:
                raise ValueError(f"{name} must have shape {want}, got {arr.shape}")
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
