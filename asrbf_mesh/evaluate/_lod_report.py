"""Write a level-of-detail set with its measurements: meshes, networks and ``manifest.json``.

The core (:func:`asrbf_mesh.lod_set`) makes the levels; this module, on the evaluation
side, writes them with Metro-style errors against the scan (pymeshlab) and, on request,
quadric-decimation (QEM) baselines at the same face counts.
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from .._atomic import atomic_path
from .._io import Scan, save_mesh
from .._lod import (
    LodLevel,
    _as_scan,
    _footprint_bytes,
    _save_network,
    ply_bytes,
)
from .._mesh import Mesh, compact
from .._validate import jsonable
from .._version import __version__
from ..errors import AsrbfError
from . import _meshlab
from ._meshlab import quadric_edge_collapse
from ._simplify import fast_decimate

__all__ = ["write_lod_set", "QEM_BASELINES", "MANIFEST_FORMAT", "MANIFEST_VERSION"]

#: Names of the quadric-decimation baselines in a manifest's ``qem`` list.
QEM_BASELINES: tuple[str, ...] = ("fast-simplification", "pymeshlab-quadric")

MANIFEST_FORMAT = "asrbf-lod"
MANIFEST_VERSION = 1
_REACHED_REL = 0.01  # a QEM result within 1 % (+2 faces) of its target "reached" it



def _boundary_vertices(faces: np.ndarray) -> np.ndarray:
    """Return the indices of the vertices on edges used by exactly one face."""
    e = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    uniq, count = np.unique(e, axis=0, return_counts=True)
    return np.unique(uniq[count == 1])


class _Border:
    """The scan's border vertices in the view plane, for border-offset checks."""

    def __init__(self, scan: Scan, rotation: np.ndarray) -> None:
        self.rotation = rotation
        self.tree = None
        if scan.faces is not None:
            b = _boundary_vertices(scan.faces)
            if len(b):
                self.tree = cKDTree((scan.points[b] @ rotation)[:, :2])

    def offset(self, mesh: Mesh) -> float | None:
        """Largest view-plane distance from a border vertex of ``mesh`` to the scan's border."""
        if self.tree is None or mesh.n_faces == 0:
            return None
        b = _boundary_vertices(mesh.faces)
        if len(b) == 0:
            return 0.0
        d, _ = self.tree.query((mesh.vertices[b] @ self.rotation)[:, :2])
        return float(d.max())


def _metro(mesh: Mesh, reference: Mesh | np.ndarray, enabled: bool) -> dict[str, Any]:
    keys = ("mean_pct", "rms_pct", "hausdorff_pct", "mean_abs", "rms_abs", "hausdorff_abs",
            "metro_seconds")
    if not enabled:
        return dict.fromkeys(keys)
    t = time.perf_counter()
    d = _meshlab.hausdorff(mesh, reference)
    return {"mean_pct": d["mean_pct"], "rms_pct": d["rms_pct"],
            "hausdorff_pct": d["hausdorff_pct"], "mean_abs": d["mean"], "rms_abs": d["rms"],
            "hausdorff_abs": d["hausdorff"], "metro_seconds": time.perf_counter() - t}


def _qem(name: str, mesh: Mesh, target: int) -> Mesh:
    if name == "fast-simplification":
        return fast_decimate(mesh, target_faces=target, preserve_border=True)
    return quadric_edge_collapse(mesh, target_faces=target, preserve_border=True)


def write_lod_set(scan: Scan | np.ndarray, levels: list[LodLevel], out_dir: str | os.PathLike,
                  *, compare_qem: bool = False, metro: bool = True) -> dict[str, Any]:
    """Write a LOD set: one mesh per level, its network(s) and ``manifest.json``.

    Files in ``out_dir`` (created if missing), each written atomically, the manifest
    last: ``level_<i>.ply`` (the meshes), ``network.asrbf`` (``resample``: the one
    network all levels share) or ``level_<i>.asrbf`` (``refit``), and with
    ``compare_qem`` the baselines ``qem_fast_<i>.ply`` and ``qem_meshlab_<i>.ply``.

    Parameters
    ----------
    scan : Scan or (N, 3) array
        The scan the levels approximate: the reference of the errors and the input
        of the QEM baselines. Its source file is never overwritten.
    levels : list of LodLevel
        From :func:`lod_set`.
    out_dir : path-like
        Output directory.
    compare_qem : bool
        Also decimate the scan mesh to each level's face count with
        fast-simplification and with pymeshlab's quadric edge collapse, both
        preserving the border, and measure them the same way. Needs a scan with faces.
    metro : bool
        Measure the errors (pymeshlab Hausdorff, both directions); False leaves them
        ``None``.

    Returns
    -------
    dict
        The manifest (also written as ``manifest.json``):

        - ``format`` ("asrbf-lod"), ``format_version``, ``asrbf_mesh_version``,
          ``method``, ``order`` and ``definitions`` (what every figure means);
        - ``scan``: ``source``, ``n_points``, ``n_faces``, ``diagonal``;
        - ``network``: the shared network of a ``resample`` set (``path``, ``bytes``,
          ``n_neurons``, ``d_min``, ``fit_seconds``, ``shared_by_levels``), else None;
        - ``metro``: ``reference`` ("scan mesh" or "scan points") and the sampling;
        - ``levels``: per level ``index``, ``path``, ``method``, ``vertices``,
          ``faces``, ``bytes``, ``network_path``, ``mesh_bytes``, ``footprint_bytes``,
          ``spacing_abs``, ``mean_pct``, ``rms_pct``, ``hausdorff_pct`` (and the
          ``*_abs`` values in scan units), ``metro_seconds``, ``seconds``,
          ``n_neurons``, ``d_min``, ``border_offset_abs``;
        - ``qem``: per level and baseline the same keys (``method`` is the baseline's
          name, ``bytes`` = ``mesh_bytes``, network fields None) plus
          ``target_faces``, ``reached`` and ``note``; empty without ``compare_qem``.

    Raises
    ------
    AsrbfError
        Empty or foreign ``levels``, an unusable ``out_dir``, ``compare_qem`` on a
        point cloud, or a failure of pymeshlab / fast-simplification.

    Notes
    -----
    ``bytes`` compares what each side must store. Ours: the network file (compact
    parameters: uint16 centres, float16 widths and weights; deflated, with ~2 KB of
    JSON metadata; see :func:`network_file_bytes`); a reader rebuilds the level from
    it, the grid spacing and the footprint bitmap (``footprint_bytes``, reported apart:
    without it the network meshes the whole square). QEM: the mesh as a float32 binary PLY
    (:func:`ply_bytes`; the ``.ply`` files written here keep float64 vertices).

    Errors are Metro-style (:func:`asrbf_mesh.evaluate._meshlab.hausdorff`): both directions
    between the level and the scan mesh (unreferenced scan points ignored), or, for a
    bare point cloud, from the points to the level only; percentages of the scan
    surface's bounding-box diagonal. ``border_offset_abs``: the largest distance, in
    the view plane, from a border vertex of the mesh to the nearest border vertex of
    the scan (holes' rims included); None for a point cloud.
    """
    if not isinstance(levels, (list, tuple)) or not levels:
        raise AsrbfError("levels must be a non-empty list of LodLevel")
    if not all(isinstance(lv, LodLevel) for lv in levels):
        raise AsrbfError("levels must hold LodLevel objects (from lod_set)")
    idx = [lv.index for lv in levels]
    if len(set(idx)) != len(idx):
        raise AsrbfError(f"level indices must be unique, got {idx}")
    sc = _as_scan(scan)
    if compare_qem and sc.faces is None:
        raise AsrbfError("compare_qem needs a scan with faces (QEM decimates the scan mesh); "
                         "this scan is a point cloud")
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise AsrbfError(f"{out}: output path exists and is not a directory")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise AsrbfError(f"{out}: cannot create the output directory ({exc.strerror})") from None
    inputs = tuple(p for p in (sc.source,) if p)

    if sc.faces is not None:
        reference: Mesh | np.ndarray = Mesh(*compact(sc.points, sc.faces))
        ref_kind = "scan mesh"
    else:
        reference, ref_kind = sc.points, "scan points"
    frame_net = next((lv.network for lv in levels if lv.network is not None), None)
    rotation = frame_net.frame.rotation if frame_net is not None else np.eye(3)
    border = _Border(sc, rotation)

    # networks: one file per distinct network object
    net_paths: dict[int, str] = {}
    shared = None
    nets = [lv.network for lv in levels if lv.network is not None]
    distinct = {id(n): n for n in nets}
    for lv in levels:
        if lv.network is None or id(lv.network) in net_paths:
            continue
        users = [x.index for x in levels if x.network is lv.network]
        name = "network.asrbf" if len(users) > 1 else f"level_{lv.index}.asrbf"
        _save_network(lv.network, out / name, inputs)
        net_paths[id(lv.network)] = name
        if len(users) > 1 and len(distinct) == 1:
            shared = {"path": name, "bytes": (out / name).stat().st_size,
                      "n_neurons": lv.network.n_neurons,
                      "d_min": lv.network.info.get("d_min"),
                      "fit_seconds": lv.network.info.get("fit_seconds"),
                      "shared_by_levels": users}

    rows = []
    for lv in levels:
        path = f"level_{lv.index}.ply"
        save_mesh(lv.mesh, out / path, overwrite_inputs=inputs)
        npath = net_paths.get(id(lv.network)) if lv.network is not None else None
        fbytes = None
        if lv.network is not None and lv.spacing_abs:
            fbytes = _footprint_bytes(lv.mesh, lv.network.frame, lv.spacing_abs)
        row = {"index": lv.index, "path": path, "method": lv.method,
               "vertices": lv.mesh.n_vertices, "faces": lv.mesh.n_faces,
               "bytes": (out / npath).stat().st_size if npath else lv.network_bytes,
               "network_path": npath, "mesh_bytes": ply_bytes(lv.mesh.n_vertices,
                                                              lv.mesh.n_faces),
               "footprint_bytes": fbytes, "spacing_abs": lv.spacing_abs}
        row.update(_metro(lv.mesh, reference, metro))
        row.update({"seconds": lv.seconds, "n_neurons": lv.n_neurons, "d_min": lv.d_min,
                    "border_offset_abs": border.offset(lv.mesh)})
        rows.append(row)

    qem_rows = []
    if compare_qem:
        assert isinstance(reference, Mesh)
        for lv in levels:
            target = lv.mesh.n_faces
            for name, tag in zip(QEM_BASELINES, ("fast", "meshlab"), strict=True):
                t = time.perf_counter()
                if target >= reference.n_faces:
                    mesh = reference
                    note = (f"target >= the scan's {reference.n_faces} faces: the scan mesh "
                            "itself, not decimated")
                else:
                    mesh = _qem(name, reference, target)
                    note = None
                seconds = time.perf_counter() - t
                reached = abs(mesh.n_faces - target) <= _REACHED_REL * target + 2
                if not reached and note is None:
                    note = (f"{mesh.n_faces} faces is as far as it goes with the border "
                            "preserved" if mesh.n_faces > target else "overshot the target")
                path = f"qem_{tag}_{lv.index}.ply"
                save_mesh(mesh, out / path, overwrite_inputs=inputs)
                mb = ply_bytes(mesh.n_vertices, mesh.n_faces)
                row = {"index": lv.index, "path": path, "method": name,
                       "vertices": mesh.n_vertices, "faces": mesh.n_faces, "bytes": mb,
                       "network_path": None, "mesh_bytes": mb, "footprint_bytes": None,
                       "spacing_abs": None}
                row.update(_metro(mesh, reference, metro))
                row.update({"seconds": seconds, "n_neurons": None, "d_min": None,
                            "border_offset_abs": border.offset(mesh),
                            "target_faces": target, "reached": bool(reached), "note": note})
                qem_rows.append(row)

    methods = sorted({lv.method for lv in levels})
    manifest: dict[str, Any] = {
        "format": MANIFEST_FORMAT,
        "format_version": MANIFEST_VERSION,
        "asrbf_mesh_version": __version__,
        "method": methods[0] if len(methods) == 1 else "mixed",
        "order": "level 0 is the finest; the index grows with coarseness",
        "scan": {"source": sc.source, "n_points": sc.n_points, "n_faces": sc.n_faces,
                 "diagonal": float(np.linalg.norm(np.ptp(
                     reference.vertices if isinstance(reference, Mesh) else reference,
                     axis=0)))},
        "network": shared,
        "metro": {"reference": ref_kind, "enabled": bool(metro),
                  "samples": "all vertices + max(4 max(V_level, V_scan), 10000) area samples per "
                             "direction (seeded)" if ref_kind == "scan mesh" else
                             "all scan points, scan -> level only"},
        "definitions": {
            "bytes": "levels: size of the .asrbf network file the level is sampled from "
                     "(compact parameters: uint16 centres, float16 widths and weights; "
                     "deflated, no learning log); a resample set "
                     "shares one network, so every level reports the same file. qem: "
                     "mesh_bytes",
            "mesh_bytes": "the mesh as a binary PLY of float32 vertices and int32 faces",
            "footprint_bytes": "deflated bitmap of the grid cells a level keeps (needed "
                               "with the network to rebuild the level; not in bytes)",
            "mean_pct": "Metro mean distance, average of both directions' area-weighted "
                        "means, % of the scan's bounding-box diagonal",
            "rms_pct": "Metro RMS distance of both directions, % of the diagonal",
            "hausdorff_pct": "Metro Hausdorff distance (max of both directions), % of "
                             "the diagonal",
            "border_offset_abs": "largest view-plane distance from a border vertex of the "
                                 "mesh to the scan's border vertices, scan units",
            "seconds": "levels: time to make the level (refit: fit + grid; resample: "
                       "grid only, the shared fit is network.fit_seconds); qem: decimation",
        },
        "levels": rows,
        "qem": qem_rows,
    }
    manifest = jsonable(manifest)
    with atomic_path(out / "manifest.json") as tmp:
        tmp.write_text(json.dumps(manifest, indent=2) + "\n")
    return manifest
