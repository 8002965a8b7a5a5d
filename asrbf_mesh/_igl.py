"""Adapter for libigl (``igl``): the only module that imports it."""

from __future__ import annotations

import numpy as np

from ._mesh import Mesh

__all__ = ["point_mesh_distance", "boundary_loops"]


def point_mesh_distance(points: np.ndarray, mesh: Mesh) -> np.ndarray:
    """Unsigned distance of (M, 3) points to the nearest point of a triangle mesh, (M,)."""
    import igl

    sq, _, _ = igl.point_mesh_squared_distance(
        np.ascontiguousarray(points, dtype=np.float64), mesh.vertices,
        np.ascontiguousarray(mesh.faces, dtype=np.int64))
    return np.sqrt(np.asarray(sq, dtype=np.float64))


def boundary_loops(faces: np.ndarray) -> list[np.ndarray]:
    """Boundary loops (vertex index arrays) of a triangle mesh, as libigl finds them."""
    import igl

    return [np.asarray(loop, dtype=np.int64)
            for loop in igl.boundary_loop_all(np.ascontiguousarray(faces, dtype=np.int64))]
