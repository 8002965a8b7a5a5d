"""Adapter for :mod:`fast_simplification`: the only module of the package that imports it.

fast-simplification (a wrapper of Sven Forstmann's Fast-Quadric-Mesh-Simplification)
keeps its mesh in module-level C++ state between ``load`` and ``simplify``: calls are
not thread-safe, so this adapter serializes them with a lock.

Written against fast-simplification 0.2 (``preserve_border`` exists since 0.1.9;
without it the decimation erodes a range scan's open border, docs/design.md).
"""

from __future__ import annotations

import threading

import fast_simplification
import numpy as np

from .._mesh import Mesh, compact
from .._validate import check_float, check_int, one_line
from ..errors import AsrbfError, ScanError

__all__ = ["fast_decimate"]

_LOCK = threading.Lock()


def fast_decimate(mesh: Mesh, *, target_faces: int, preserve_border: bool = True,
                  aggressiveness: float = 7.0) -> Mesh:
    """Quadric decimation with fast-simplification.

    Parameters
    ----------
    mesh : Mesh
        Scan units; unreferenced vertices are dropped first.
    target_faces : int
        Requested face count. With ``preserve_border`` no edge touching a border vertex
        collapses, so a ragged border puts a floor under the reachable count (≈ 5,100
        faces on the face map) and the result then has more faces than requested. A
        target at or above the mesh's face count returns the (compacted) mesh unchanged.
    preserve_border : bool
        Keep the open border (fast-simplification's ``preserve_border``; its own default
        is False).
    aggressiveness : float
        fast-simplification's ``agg`` (its default 7): higher is faster and coarser;
        low values may stop short of the target.

    Returns
    -------
    Mesh
        Compact (no unreferenced vertices), float64 vertices.

    Raises
    ------
    ScanError
        Not a mesh, or a mesh without faces.
    ConfigError
        Bad ``target_faces`` or ``aggressiveness``.
    AsrbfError
        An error inside fast-simplification.

    Notes
    -----
    The target is passed as ``target_count`` (an absolute face count) rather than
    ``target_reduction``: the fraction would be rounded down by the library.

    Examples
    --------
    >>> from asrbf_mesh._surface import grid_faces
    >>> x, y = np.meshgrid(np.linspace(0, 1, 20), np.linspace(0, 1, 20))
    >>> v = np.c_[x.ravel(), y.ravel(), (x * y).ravel()]
    >>> out = fast_decimate(Mesh(v, grid_faces(20, 20)), target_faces=200,
    ...                     preserve_border=False)
    >>> 190 <= out.n_faces <= 200
    True
    """
    if not isinstance(mesh, Mesh):
        raise ScanError(f"mesh must be an asrbf_mesh.Mesh, got {type(mesh).__name__}")
    if mesh.n_faces == 0:
        raise ScanError("mesh has no faces")
    target_faces = check_int(target_faces, "target_faces", 1)
    aggressiveness = check_float(aggressiveness, "aggressiveness", low=0.0)
    v, f = compact(mesh.vertices, mesh.faces)
    if target_faces >= len(f):
        return Mesh(v, f)
    try:
        with _LOCK:
            pts, tris = fast_simplification.simplify(
                np.ascontiguousarray(v, dtype=np.float64), np.ascontiguousarray(f, np.int32),
                target_count=int(target_faces), agg=float(aggressiveness), verbose=False,
                return_collapses=False, lossless=False, preserve_border=bool(preserve_border))
    except Exception as exc:
        raise AsrbfError(f"fast-simplification failed: {one_line(exc, 200)}") from None
    tris = np.asarray(tris, dtype=np.int64).reshape(-1, 3)
    if len(tris) == 0:
        raise AsrbfError("fast-simplification returned an empty mesh")
    return Mesh(*compact(np.asarray(pts, dtype=np.float64), tris))
