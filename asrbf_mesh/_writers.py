"""The mesh writers behind :func:`asrbf_mesh._io.save_mesh`: PLY, OBJ, OFF and STL.

Each writer takes ``(path, vertices, faces, normals, quality)`` and writes the whole file
to ``path`` (the caller's temporary name; :func:`~asrbf_mesh._io.save_mesh` checks the
arguments and moves the file into place atomically).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import plyfile

from ._readers import STL_RECORD

__all__ = ["SUPPORTED_MESH_FORMATS", "WRITERS"]

#: File extensions :func:`~asrbf_mesh._io.save_mesh` can write (compared case-insensitively).
SUPPORTED_MESH_FORMATS: tuple[str, ...] = (".ply", ".obj", ".off", ".stl")


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


def _write_ply(tmp: Path, vertices: np.ndarray, faces: np.ndarray | None,
               normals: np.ndarray | None, quality: np.ndarray | None) -> None:
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


def _write_obj(tmp: Path, vertices: np.ndarray, faces: np.ndarray | None,
               normals: np.ndarray | None, quality: np.ndarray | None) -> None:
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


def _write_off(tmp: Path, vertices: np.ndarray, faces: np.ndarray | None,
               normals: np.ndarray | None, quality: np.ndarray | None) -> None:
    """ASCII OFF (normals and quality are not stored)."""
    n_faces = 0 if faces is None else len(faces)
    with open(tmp, "w", encoding="ascii", newline="\n") as fh:
        fh.write(f"OFF\n{len(vertices)} {n_faces} 0\n")
        np.savetxt(fh, vertices, fmt="%.17g %.17g %.17g")
        if n_faces:
            np.savetxt(fh, faces, fmt="3 %d %d %d")


def _write_stl(tmp: Path, vertices: np.ndarray, faces: np.ndarray | None,
               normals: np.ndarray | None, quality: np.ndarray | None) -> None:
    """Binary STL (float32, unit face normals; unused vertices are lost)."""
    assert faces is not None
    tri = vertices[faces]
    fn = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    norm = np.linalg.norm(fn, axis=1, keepdims=True)
    fn = np.divide(fn, norm, out=np.zeros_like(fn), where=norm > 0)
    rec = np.zeros(len(faces), dtype=STL_RECORD)
    rec["normal"] = fn
    rec["v"] = tri
    header = b"binary STL written by asrbf-mesh".ljust(80, b" ")
    with open(tmp, "wb") as fh:
        fh.write(header)
        fh.write(np.array([len(faces)], dtype="<u4").tobytes())
        fh.write(rec.tobytes())


#: The writer of each extension.
WRITERS = {".ply": _write_ply, ".obj": _write_obj, ".off": _write_off, ".stl": _write_stl}
