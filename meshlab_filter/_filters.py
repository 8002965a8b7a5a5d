"""The five asrbf filters, :func:`apply_filter`, discovery and ``MeshSet`` binding."""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable
from typing import Any

import numpy as np
import pymeshlab

from asrbf_mesh._holes import FillResult, fill_holes
from asrbf_mesh._io import Scan
from asrbf_mesh._lod import lod_set
from asrbf_mesh._mesh import Mesh
from asrbf_mesh._network import Network
from asrbf_mesh._surface import reconstruct
from asrbf_mesh.errors import AsrbfError
from asrbf_mesh.evaluate._metro import metro

from ._bridge import (
    NetworkCache,
    add_layer,
    layer_mesh,
    layer_scan,
    mesh_of,
    set_vertex_quality,
)
from ._params import FILTERS, MeshlabFilterError

__all__ = [
    "apply_filter",
    "cache",
    "filter_list",
    "filter_parameter_values",
    "print_filter_list",
    "print_filter_parameter_list",
    "register",
    "unregister",
]

#: The fitted networks of the layers, shared by all filters (see :class:`NetworkCache`).
cache = NetworkCache(maxsize=8)

_MODES = {"surface": "surface", "footprint": "scan", "hull": "hull", "full": "full"}


def _label(m: pymeshlab.Mesh, mesh_id: int) -> str:
    return m.label() or f"mesh {mesh_id}"


def _fitted(ms: pymeshlab.MeshSet, name: str, p: dict[str, Any]
            ) -> tuple[pymeshlab.Mesh, int, Scan, Network]:
    """Return the current layer, its id, its Scan and its (cached) network."""
    m = mesh_of(ms, None, name)
    mesh_id = int(ms.current_mesh_id())
    scan = layer_scan(m)
    net = cache.network(ms, mesh_id, scan, seed=p["seed"], view_axis=p["viewaxis"],
                        pieces=p["pieces"])
    return m, mesh_id, scan, net


# --------------------------------------------------------------------------- filters


def _reconstruction(ms: pymeshlab.MeshSet, p: dict[str, Any]) -> dict[str, Any]:
    m, mesh_id, scan, net = _fitted(ms, "generate_surface_reconstruction_asrbf", p)
    mode = _MODES[p["mode"]]
    mesh = reconstruct(net, resolution=p["resolution"] or None,
                       footprint=None if mode == "full" else scan, mode=mode,
                       margin_rel=p["margin"] if mode == "full" else 0.0)
    new_id = add_layer(ms, mesh, f"{_label(m, mesh_id)} (asrbf surface)")
    return {"mesh_id": new_id, "n_neurons": net.n_neurons, "vertices": mesh.n_vertices,
            "faces": mesh.n_faces}


def _edge_codes(faces: np.ndarray, n: int) -> np.ndarray:
    """Undirected edges of ``faces`` whose ends are both below ``n``, as ``a * n + b``."""
    e = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    e = e[(e < n).all(axis=1)]
    return e[:, 0] * np.int64(n) + e[:, 1]


def _keep_selected(res: FillResult, scan: Scan, selected: np.ndarray
                   ) -> tuple[Mesh, list[bool], list[dict[str, Any]]]:
    """Drop the fills of holes without a selected face on their rim.

    The fill of each hole is a block of vertices and faces appended in hole order
    (``HoleInfo.vertices_added`` / ``faces_added``); its rim edges are its edges between
    two scan vertices, and a rim face is a selected face holding such an edge.
    """
    mesh = res.mesh
    n_v, n_f = scan.n_points, scan.n_faces
    sel_codes = _edge_codes(np.asarray(scan.faces)[selected], n_v)
    keep_v = np.ones(mesh.n_vertices, dtype=bool)
    keep_f = np.ones(mesh.n_faces, dtype=bool)
    kept: list[bool] = []
    skipped: list[dict[str, Any]] = []
    vo, fo = n_v, n_f
    for h in res.holes:
        vs, fs = slice(vo, vo + h.vertices_added), slice(fo, fo + h.faces_added)
        vo, fo = vo + h.vertices_added, fo + h.faces_added
        on = h.faces_added > 0 and bool(np.isin(_edge_codes(mesh.faces[fs], n_v),
                                                sel_codes).any())
        kept.append(on)
        if h.faces_added and not on:
            keep_v[vs] = keep_f[fs] = False
            skipped.append({"index": h.index, "size_abs": h.size_abs, "size_pct": h.size_pct,
                            "reason": "no selected face on its rim (selected=True)"})
    remap = np.cumsum(keep_v) - 1
    q = None if mesh.vertex_quality is None else mesh.vertex_quality[keep_v]
    return Mesh(mesh.vertices[keep_v], remap[mesh.faces[keep_f]], vertex_quality=q), kept, skipped


def _close_holes(ms: pymeshlab.MeshSet, p: dict[str, Any]) -> dict[str, Any]:
    name = "meshing_close_holes_asrbf"
    m = mesh_of(ms, None, name)
    if m.face_number() == 0:
        raise MeshlabFilterError(f"Failed to apply filter: {name}: the current mesh has no "
                                 "faces (a point set has no holes to close)")
    m, mesh_id, scan, net = _fitted(ms, name, p)
    limit = p["maxholesize"].absolute(scan.bbox_diagonal)
    res = fill_holes(scan, net, max_hole_size=limit, progress=False)
    mesh = res.mesh
    kept = [h.faces_added > 0 for h in res.holes]
    skipped = res.holes_skipped
    if p["selected"]:
        selected = np.asarray(m.face_selection_array(), dtype=bool)
        mesh, kept, more = _keep_selected(res, scan, selected)
        skipped = [s for s in skipped if s["index"] not in {x["index"] for x in more}] + more
    new_faces = mesh.n_faces - scan.n_faces
    face_quality = np.r_[np.zeros(scan.n_faces), np.ones(new_faces)]
    new_id = add_layer(ms, mesh, f"{_label(m, mesh_id)} (asrbf filled)",
                       face_quality=face_quality)
    if p["newfaceselected"] and new_faces:
        ms.compute_selection_by_condition_per_face(condselect="fq > 0.5")
    closed = sum(h.filled and k for h, k in zip(res.holes, kept, strict=True))
    return {"closed_holes": int(closed), "new_faces": int(new_faces),
            "new_vertices": int(mesh.n_vertices - scan.n_points),
            "holes_found": res.holes_found,
            "holes_skipped": sorted(skipped, key=lambda s: s["index"]), "mesh_id": new_id}


def _base_resolution(net: Network, scan: Scan, target: int, footprint: bool,
                     fill_holes: bool) -> int:
    """Grid resolution whose footprint mesh has about ``target`` faces (two probes)."""
    kw: dict[str, Any] = ({"footprint": scan, "mode": "scan" if fill_holes else "surface"}
                          if footprint else {})
    r = 64
    for _ in range(2):
        faces = reconstruct(net, resolution=r, **kw).n_faces
        r = max(2, int(round(1 + (r - 1) * math.sqrt(target / max(faces, 1)))))
    return r


def _lod(ms: pymeshlab.MeshSet, p: dict[str, Any]) -> dict[str, Any]:
    m, mesh_id, scan, net = _fitted(ms, "generate_lod_set_asrbf", p)
    base = None
    if p["targetfacenum"]:
        base = _base_resolution(net, scan, p["targetfacenum"], p["footprint"],
                                p["fillholes"])
    levels = lod_set(scan, levels=p["levels"], method=p["method"], net=net, seed=p["seed"],
                     footprint=p["footprint"], base_resolution=base, pieces=p["pieces"],
                     fill_holes=p["fillholes"] and p["footprint"])
    label = _label(m, mesh_id)
    ids = [add_layer(ms, lv.mesh, f"{label} (asrbf LOD {lv.index})") for lv in levels]
    return {"mesh_ids": ids, "faces": [lv.mesh.n_faces for lv in levels],
            "vertices": [lv.mesh.n_vertices for lv in levels],
            "n_neurons": [lv.n_neurons for lv in levels]}


def _residual(ms: pymeshlab.MeshSet, p: dict[str, Any]) -> dict[str, Any]:
    m, mesh_id, scan, net = _fitted(ms, "compute_scalar_by_asrbf_residual_per_vertex", p)
    local = scan.points @ net.frame.rotation
    r = local[:, 2] - net.evaluate(np.ascontiguousarray(local[:, :2]))
    set_vertex_quality(ms, mesh_id, r, "asrbf_residual",
                       None if p["signed"] else "abs(asrbf_residual)")
    a = np.abs(r)
    return {"max": float(a.max()), "mean": float(a.mean()),
            "RMS": float(np.sqrt(np.mean(a**2)))}


def _diagonal(v: np.ndarray) -> float:
    return float(np.linalg.norm(np.ptp(v, axis=0))) if len(v) else 0.0


def _metro(ms: pymeshlab.MeshSet, p: dict[str, Any]) -> dict[str, Any]:
    name = "get_metro_distance"
    a_id = int(ms.current_mesh_id()) if p["sampledmesh"] == -1 else p["sampledmesh"]
    a = layer_mesh(mesh_of(ms, a_id, name))
    b = layer_mesh(mesh_of(ms, p["targetmesh"], name))
    if a.n_faces == 0:
        raise MeshlabFilterError(f"Failed to apply filter: {name}: the sampled mesh "
                                 f"{a_id} has no faces (it must be a mesh; the target may "
                                 "be a point set)")
    res = metro(a, b if b.n_faces else b.vertices, samples=p["samplenum"] or None,
                seed=p["seed"], per_sample=p["savequality"])
    if p["savequality"] and res.a_to_b is not None:
        set_vertex_quality(ms, a_id, res.vertex_error, "asrbf_metro_distance")
    dirs = [d for d in (res.a_to_b, res.b_to_a) if d is not None]
    return {"RMS": res.rms, "diag_mesh_0": _diagonal(a.vertices),
            "diag_mesh_1": _diagonal(b.vertices), "max": res.hausdorff, "mean": res.mean,
            "min": min(d.min for d in dirs), "n_samples": res.n_samples}


_IMPLEMENTATIONS: dict[str, Callable[[pymeshlab.MeshSet, dict[str, Any]], dict[str, Any]]] = {
    "generate_surface_reconstruction_asrbf": _reconstruction,
    "meshing_close_holes_asrbf": _close_holes,
    "generate_lod_set_asrbf": _lod,
    "compute_scalar_by_asrbf_residual_per_vertex": _residual,
    "get_metro_distance": _metro,
}
assert set(_IMPLEMENTATIONS) == set(FILTERS)


# --------------------------------------------------------------------------- apply


def apply_filter(ms: pymeshlab.MeshSet, filter_name: str, /, **params: Any) -> dict[str, Any]:
    """Apply a filter to ``ms``: one of ours, or any pymeshlab filter.

    Parameters
    ----------
    ms : pymeshlab.MeshSet
        The mesh set; our filters act on its current mesh (``get_metro_distance`` on
        the meshes its parameters name).
    filter_name : str
        A name from :func:`filter_list`, or a pymeshlab filter (passed on to
        ``ms.apply_filter``, whose errors are pymeshlab's own).
    **params
        The filter's parameters, by keyword (see :func:`print_filter_parameter_list`);
        the ones left out take their default. Ours never remember values between calls.

    Returns
    -------
    dict
        What the filter reports (possibly empty).

    Raises
    ------
    MeshlabFilterError
        (a ``pymeshlab.PyMeshLabException`` and an ``AsrbfError``) An empty MeshSet, an
        unknown parameter or a value of the wrong type (pymeshlab's wording), or a
        failure of the filter (one line, ``Failed to apply filter: <name>: <reason>``).
    InvalidEnumError
        A choice outside the parameter's choices (also a ``pymeshlab.InvalidEnumException``).

    Examples
    --------
    >>> import pymeshlab, meshlab_filter as mf                       # doctest: +SKIP
    >>> ms = pymeshlab.MeshSet(); ms.load_new_mesh("scan.ply")      # doctest: +SKIP
    >>> mf.apply_filter(ms, "meshing_close_holes_asrbf",
    ...                 maxholesize=pymeshlab.PercentageValue(5))    # doctest: +SKIP
    {'closed_holes': 17, 'new_faces': 5210, ...}
    """
    spec = FILTERS.get(filter_name)
    if spec is None:
        return ms.apply_filter(filter_name, **params)
    mesh_of(ms, None, filter_name)  # an empty MeshSet first, as pymeshlab checks it
    values = spec.check(params)
    try:
        return _IMPLEMENTATIONS[filter_name](ms, values)
    except MeshlabFilterError:
        raise
    except AsrbfError as exc:
        text = " ".join(str(exc).split())
        raise MeshlabFilterError(f"Failed to apply filter: {filter_name}: {text}") from exc


# --------------------------------------------------------------------------- discovery


def filter_list() -> list[str]:
    """Return the names of the asrbf filters, sorted (like ``pymeshlab.filter_list``)."""
    return sorted(FILTERS)


def print_filter_list() -> None:
    """Print every asrbf filter with its one-line summary."""
    for name in filter_list():
        print(f"{name} : {FILTERS[name].summary}")


def print_filter_parameter_list(filter_name: str) -> None:
    """Print a filter's parameters: name, type, default and description.

    A pymeshlab filter's list is printed by ``pymeshlab.print_filter_parameter_list``
    (which raises ``PyMeshLabException`` for an unknown name).

    Lengths (``PercentageValue``) take a ``pymeshlab.PercentageValue`` (% of the
    bounding-box diagonal of the mesh the filter works on) or a ``pymeshlab.PureValue``
    (mesh units).
    """
    spec = FILTERS.get(filter_name)
    if spec is None:
        pymeshlab.print_filter_parameter_list(filter_name)
        return
    print(spec.parameter_text())


def filter_parameter_values(ms: pymeshlab.MeshSet, filter_name: str) -> dict[str, Any]:
    """Return a filter's default parameter values computed on ``ms``, as pymeshlab does.

    Like ``MeshSet.filter_parameter_values``: lengths are resolved to mesh units on the
    current mesh, choices to their index, ``-1`` (the current mesh) to its id.
    Any other name goes to ``ms.filter_parameter_values``.

    Raises
    ------
    MeshlabFilterError
        An empty MeshSet (pymeshlab's wording).
    """
    spec = FILTERS.get(filter_name)
    if spec is None:
        return ms.filter_parameter_values(filter_name)
    m = mesh_of(ms, None, filter_name)
    out: dict[str, Any] = {}
    for p in spec.params:
        if p.kind == "length":
            out[p.name] = p.default / 100.0 * _diagonal(layer_mesh(m).vertices)
        elif p.kind == "enum":
            out[p.name] = p.choices.index(p.default)
        elif p.kind == "mesh" and p.default == -1:
            out[p.name] = int(ms.current_mesh_id())
        else:
            out[p.name] = p.default
    return out


# --------------------------------------------------------------------------- binding

_MARK = "_asrbf_filter"


def _method(name: str) -> Callable[..., dict[str, Any] | None]:
    def method(self: pymeshlab.MeshSet, **kwargs: Any) -> dict[str, Any] | None:
        res = apply_filter(self, name, **kwargs)
        return res if res else None  # as pymeshlab's bound filters do

    method.__name__ = name
    method.__qualname__ = f"MeshSet.{name}"
    method.__doc__ = FILTERS[name].docstring()
    setattr(method, _MARK, True)
    return method


def register() -> list[str]:
    """Bind the asrbf filters as ``pymeshlab.MeshSet`` methods (``ms.<filter>(...)``).

    Explicit by design: importing :mod:`meshlab_filter` changes nothing in pymeshlab. A
    name pymeshlab already has is never shadowed: it is skipped with a
    ``RuntimeWarning``. Calling it again is harmless.

    Returns
    -------
    list of str
        The names bound.
    """
    bound = []
    for name in filter_list():
        existing = getattr(pymeshlab.MeshSet, name, None)
        if existing is not None and not getattr(existing, _MARK, False):
            warnings.warn(f"pymeshlab.MeshSet already has {name!r}; meshlab_filter does not "
                          f"shadow it (use meshlab_filter.apply_filter(ms, {name!r}, ...))",
                          RuntimeWarning, stacklevel=2)
            continue
        setattr(pymeshlab.MeshSet, name, _method(name))
        bound.append(name)
    return bound


def unregister() -> list[str]:
    """Remove the methods :func:`register` bound; returns their names."""
    removed = []
    for name in filter_list():
        if getattr(getattr(pymeshlab.MeshSet, name, None), _MARK, False):
            delattr(pymeshlab.MeshSet, name)
            removed.append(name)
    return removed
