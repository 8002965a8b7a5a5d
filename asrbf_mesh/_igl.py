"""Adapter for libigl (``igl``): the only module that imports it."""

from __future__ import annotations

from typing import Any

import numpy as np

from ._mesh import Mesh

__all__ = ["point_mesh_distance", "boundary_loops", "k_harmonic", "orient_faces"]


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


def k_harmonic(V: np.ndarray, F: np.ndarray, b: np.ndarray, bc: np.ndarray, k: int) -> np.ndarray:
    """Values at every vertex minimizing the k-harmonic energy with ``bc`` fixed at ``b``.

    ``igl.harmonic`` with its inputs checked first (finite positions, triangles and
    fixed vertices indexing existing vertices, one value row per fixed vertex), so that a
    bad input raises ``ValueError`` instead of reaching the library.
    """
    import igl

    V = np.ascontiguousarray(V, dtype=np.float64)
    F = np.ascontiguousarray(F, dtype=np.int64)
    b = np.ascontiguousarray(b, dtype=np.int64).reshape(-1)
    bc = np.ascontiguousarray(bc, dtype=np.float64).reshape(len(b), -1)
    if not (np.all(np.isfinite(V)) and np.all(np.isfinite(bc))):
        raise ValueError("k_harmonic: positions and fixed values must be finite")
    if F.ndim != 2 or F.shape[1] != 3 or len(F) == 0 or F.min() < 0 or F.max() >= len(V):
        raise ValueError("k_harmonic: triangles must index the vertices")
    if len(b) == 0 or b.min() < 0 or b.max() >= len(V) or len(np.unique(b)) != len(b):
        raise ValueError("k_harmonic: fixed vertices must be distinct vertex indices")
    return np.asarray(igl.harmonic(V, F, b, bc, int(k)), dtype=np.float64)


def orient_faces(faces: np.ndarray, components: bool = False) -> Any:
    """Faces flipped so that each orientable connected patch turns one way (libigl's BFS).

    With ``components``, also each face's patch id. The faces must be (F, 3) indices
    >= 0 (a ``ValueError`` otherwise, before the library sees them).
    """
    import igl

    f = np.ascontiguousarray(faces, dtype=np.int64)
    if f.ndim != 2 or f.shape[1] != 3 or (f.size and f.min() < 0):
        raise ValueError("orient_faces: faces must be (F, 3) vertex indices")
    if len(f) == 0:
        return (f.copy(), np.zeros(0, np.int64)) if components else f.copy()
    out, comp = igl.bfs_orient(f)
    out = np.asarray(out, dtype=np.int64)
    return (out, np.asarray(comp, dtype=np.int64)) if components else out
