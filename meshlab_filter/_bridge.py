"""pymeshlab.Mesh <-> asrbf_mesh Scan / Mesh, vertex quality in place, the network cache.

The array conversions reuse :mod:`asrbf_mesh.evaluate._meshlab` (``_from_ml``); what is added here
is what the filters need beyond it: a :class:`~asrbf_mesh.Scan` of a layer, a new
layer with vertex normals, vertex and face quality, and writing vertex quality into an
existing layer.
"""

from __future__ import annotations

import hashlib
import weakref
from collections import OrderedDict
from typing import Any

import numpy as np
import pymeshlab

from asrbf_mesh._fit import fit
from asrbf_mesh._io import Scan
from asrbf_mesh._mesh import Mesh
from asrbf_mesh._network import Network
from asrbf_mesh.evaluate._meshlab import _from_ml

from ._params import MeshlabFilterError

__all__ = ["NetworkCache", "add_layer", "layer_mesh", "layer_scan", "mesh_of",
           "set_vertex_quality"]


def mesh_of(ms: pymeshlab.MeshSet, mesh_id: int | None, filter_name: str) -> pymeshlab.Mesh:
    """Return the layer ``mesh_id`` of ``ms`` (None: the current one), checked.

    Raises
    ------
    MeshlabFilterError
        ``ms`` is not a MeshSet, it is empty, or ``mesh_id`` does not exist (pymeshlab's
        wording for the last two).
    """
    if not isinstance(ms, pymeshlab.MeshSet):
        raise MeshlabFilterError(f"{filter_name}: expected a pymeshlab.MeshSet, got "
                                 f"{type(ms).__name__}")
    if ms.mesh_number() == 0:
        raise MeshlabFilterError(f"{filter_name} requires at least one mesh loaded in the "
                                 "MeshSet.")
    if mesh_id is None:
        return ms.current_mesh()
    if not ms.mesh_id_exists(int(mesh_id)):
        raise MeshlabFilterError(f"Mesh ID {mesh_id} not found in MeshSet.")
    return ms.mesh(int(mesh_id))


def layer_mesh(m: pymeshlab.Mesh) -> Mesh:
    """Vertices and faces of a layer as a :class:`~asrbf_mesh.Mesh` (compacts ``m``)."""
    return _from_ml(m)


def layer_scan(m: pymeshlab.Mesh) -> Scan:
    """Return a layer as a :class:`~asrbf_mesh.Scan`: its vertices, and faces if any.

    A non-compact layer is compacted in place first (deleted elements dropped), so
    vertex ``i`` of the scan is vertex ``i`` of the layer.
    """
    mesh = layer_mesh(m)
    return Scan(mesh.vertices, mesh.faces if mesh.n_faces else None)


def add_layer(ms: pymeshlab.MeshSet, mesh: Mesh, label: str, *,
              face_quality: np.ndarray | None = None) -> int:
    """Add ``mesh`` (with its vertex quality) as a new current layer.

    Vertex normals are not passed on: pymeshlab's ``Mesh`` constructor replaces them by
    its own (angle-weighted, not normalized) when the mesh has faces.

    Returns
    -------
    int
        The new layer's id.
    """
    kw: dict[str, Any] = {"vertex_matrix": np.ascontiguousarray(mesh.vertices, np.float64),
                          "face_matrix": np.ascontiguousarray(mesh.faces, np.int32)}
    if mesh.vertex_quality is not None:
        kw["v_scalar_array"] = np.ascontiguousarray(mesh.vertex_quality, np.float64)
    if face_quality is not None:
        kw["f_scalar_array"] = np.ascontiguousarray(face_quality, np.float64)
    ms.add_mesh(pymeshlab.Mesh(**kw), mesh_name=label, set_as_current=True)
    return int(ms.current_mesh_id())


def _has_attribute(m: pymeshlab.Mesh, name: str) -> bool:
    try:
        m.vertex_custom_scalar_attribute_array(name)
    except pymeshlab.PyMeshLabException:
        return False
    return True


def set_vertex_quality(ms: pymeshlab.MeshSet, mesh_id: int, values: np.ndarray,
                       attribute: str, quality: str | None = None) -> None:
    """Write per-vertex ``values`` into layer ``mesh_id``: custom attribute, then quality.

    pymeshlab has no setter for the vertex quality of a mesh in a MeshSet. What it has:
    ``Mesh.add_vertex_custom_scalar_attribute`` (in place; a name can be added once) and
    the per-vertex function filters, which may read custom attributes. So ``values``
    become the attribute ``attribute`` (through a fresh helper attribute
    ``<attribute>_<k>`` when it already exists, then
    ``compute_new_custom_scalar_attribute_per_vertex``), and the vertex quality is set to
    the muparser expression ``quality`` (default: the attribute itself) with
    ``compute_scalar_by_function_per_vertex``. Custom attributes are not written to
    files. The current layer is restored afterwards.
    """
    m = ms.mesh(mesh_id)
    vals = np.ascontiguousarray(values, dtype=np.float64)
    current = ms.current_mesh_id()
    ms.set_current_mesh(mesh_id)
    try:
        if _has_attribute(m, attribute):
            k = 1
            while _has_attribute(m, f"{attribute}_{k}"):
                k += 1
            m.add_vertex_custom_scalar_attribute(vals, f"{attribute}_{k}")
            ms.compute_new_custom_scalar_attribute_per_vertex(name=attribute,
                                                              expr=f"{attribute}_{k}")
        else:
            m.add_vertex_custom_scalar_attribute(vals, attribute)
        ms.compute_scalar_by_function_per_vertex(q=quality or attribute, normalize=False,
                                                 map=False, onselected=False)
    finally:
        ms.set_current_mesh(current)


# --------------------------------------------------------------------------- cache


def points_digest(points: np.ndarray) -> str:
    """Content hash of an (N, 3) float64 array: BLAKE2b of its bytes and shape."""
    h = hashlib.blake2b(digest_size=16)
    h.update(repr(points.shape).encode())
    h.update(np.ascontiguousarray(points, dtype=np.float64).tobytes())
    return h.hexdigest()


class NetworkCache:
    """Fitted networks per (MeshSet, layer id, vertex hash, fit parameters), LRU-bounded.

    A layer whose vertices change gets a new hash, hence a new fit. Entries hold a weak
    reference to their MeshSet and serve only that very object (Python reuses the ids
    of dead objects); the entries of a MeshSet that is gone are dropped at the next
    look-up. Not meant to be shared between threads.

    Parameters
    ----------
    maxsize : int
        Networks kept at most (least recently used dropped first).
    """

    def __init__(self, maxsize: int = 8) -> None:
        self.maxsize = int(maxsize)
        self.hits = 0
        self.misses = 0
        self._entries: OrderedDict[tuple, tuple[weakref.ref, Network]] = OrderedDict()

    def __len__(self) -> int:
        return len(self._entries)

    def clear(self) -> None:
        """Drop every network and reset the counters."""
        self._entries.clear()
        self.hits = self.misses = 0

    def info(self) -> dict[str, int]:
        """Return ``hits``, ``misses``, ``size`` and ``maxsize``."""
        return {"hits": self.hits, "misses": self.misses, "size": len(self._entries),
                "maxsize": self.maxsize}

    def network(self, ms: pymeshlab.MeshSet, mesh_id: int, scan: Scan, *, seed: int,
                view_axis: str, pieces: str = "auto") -> Network:
        """Return the model of layer ``mesh_id`` (whose points are ``scan``), fitting once.

        The model is piecewise (``pieces="auto"``) or the single network (``"1"``); the
        key holds the layer, its points' digest, the seed, the view axis and ``pieces``.

        Raises
        ------
        AsrbfError
            The fit failed (too few points, zero extent, ...).
        """
        for key in [k for k, (ref, _) in self._entries.items() if ref() is None]:
            del self._entries[key]
        key = (id(ms), int(mesh_id), points_digest(scan.points), int(seed), view_axis,
               str(pieces))
        entry = self._entries.get(key)
        if entry is not None and entry[0]() is ms:
            self._entries.move_to_end(key)
            self.hits += 1
            return entry[1]
        net = fit(scan, seed=seed, view_axis=view_axis, pieces=pieces, progress=False)
        self.misses += 1
        self._entries[key] = (weakref.ref(ms), net)
        while len(self._entries) > self.maxsize:
            self._entries.popitem(last=False)
        return net
