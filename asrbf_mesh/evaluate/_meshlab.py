"""Adapter for :mod:`pymeshlab`: the only module of the package that imports it.

Small typed functions that take and return numpy arrays or
:class:`~asrbf_mesh.Mesh`. Each call builds a fresh ``pymeshlab.MeshSet`` and passes
*every* parameter of every filter explicitly: pymeshlab remembers a filter's parameter
values between calls in one process, even on a new MeshSet (docs/design.md), so a default
left implicit is whatever the previous caller set. Errors of pymeshlab surface as a
one-line :class:`~asrbf_mesh.errors.AsrbfError`.

Written against pymeshlab 2025.7 (filter and parameter names of the 2022.2+ API).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pymeshlab

from .._io import Scan
from .._mesh import Mesh, compact
from .._validate import check_int, check_points, check_seed, one_line
from ..errors import AsrbfError, ConfigError, ScanError

__all__ = [
    "hausdorff",
    "repair_non_manifold",
    "close_holes",
    "screened_poisson",
    "quadric_edge_collapse",
    "ball_pivoting",
    "topological_measures",
]

_MIN_SAMPLES = 10_000
#: Area samples per referenced vertex of the denser mesh, by default. One per vertex left
#: the RMS of a LOD level against a noisy scan uncertain by about 0.5 % of itself (bun045
#: seed 5, four sampling seeds: level 0 0.0868-0.0871 %, level 1 0.0871-0.0876 %, so
#: the order of the two flipped with the seed); four per vertex (stratified, see
#: :func:`_surface_samples`): 0.0868-0.0869 % and 0.0873-0.0874 %, at 1.2 s instead of
#: 0.65 s per measurement.
_SAMPLES_PER_VERTEX = 4


# --------------------------------------------------------------------------- plumbing


def _apply(ms: pymeshlab.MeshSet, name: str, **params: Any) -> dict:
    """Run filter ``name`` on ``ms`` with explicit ``params``; errors become AsrbfError."""
    try:
        out = getattr(ms, name)(**params)
    except Exception as exc:  # pymeshlab raises PyMeshLabException and friends
        raise AsrbfError(f"pymeshlab {name} failed: {one_line(exc, 200)}") from None
    return out if isinstance(out, dict) else {}


def _check_mesh(mesh: Mesh, what: str) -> None:
    if not isinstance(mesh, Mesh):
        raise ScanError(f"{what} must be an asrbf_mesh.Mesh, got {type(mesh).__name__}")
    if mesh.n_faces == 0:
        raise ScanError(f"{what} has no faces")


def _to_ml(vertices: np.ndarray, faces: np.ndarray | None = None) -> pymeshlab.Mesh:
    v = np.ascontiguousarray(vertices, dtype=np.float64)
    if faces is None or len(faces) == 0:
        return pymeshlab.Mesh(vertex_matrix=v)
    return pymeshlab.Mesh(vertex_matrix=v, face_matrix=np.ascontiguousarray(faces, np.int32))


def _from_ml(m: pymeshlab.Mesh, *, normals: bool = False, quality: bool = False) -> Mesh:
    if not m.is_compact():
        m.compact()
    v = np.array(m.vertex_matrix(), dtype=np.float64)
    f = np.array(m.face_matrix(), dtype=np.int64).reshape(-1, 3)
    vn = np.array(m.vertex_normal_matrix(), dtype=np.float64) if normals else None
    if vn is not None:
        norm = np.linalg.norm(vn, axis=1, keepdims=True)
        vn = np.divide(vn, norm, out=np.zeros_like(vn), where=norm > 0)
    vq = None
    if quality and m.has_vertex_scalar():
        vq = np.array(m.vertex_scalar_array(), dtype=np.float64)
    return Mesh(v, f, vertex_normals=vn, vertex_quality=vq)


# --------------------------------------------------------------------------- Hausdorff


def _surface_samples(v: np.ndarray, f: np.ndarray, n: int,
                     rng: np.random.Generator) -> np.ndarray:
    """``n`` points uniformly distributed over the triangles' area (Monte Carlo)."""
    p0, p1, p2 = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    area = 0.5 * np.linalg.norm(np.cross(p1 - p0, p2 - p0), axis=1)
    total = float(area.sum())
    if not (total > 0 and np.isfinite(total)):
        return np.empty((0, 3))
    cdf = np.cumsum(area)
    # stratified along the cumulative area (one sample in each of n equal slices of it,
    # jittered): each triangle gets its share of the samples up to one, so the estimate's
    # variance is what varies within triangles, not which triangles the draw happened to hit
    u = (np.arange(n) + rng.random(n)) / n
    idx = np.minimum(np.searchsorted(cdf, u * cdf[-1], side="right"), len(f) - 1)
    r1 = np.sqrt(rng.random(n))
    r2 = rng.random(n)
    return ((1 - r1)[:, None] * p0[idx] + (r1 * (1 - r2))[:, None] * p1[idx]
            + (r1 * r2)[:, None] * p2[idx])


def _distances(samples: np.ndarray, target: tuple[np.ndarray, np.ndarray | None],
               maxdist: float) -> np.ndarray:
    """Distance of every sample point to the target surface (or point set), via MeshLab."""
    ms = pymeshlab.MeshSet()
    ms.add_mesh(_to_ml(samples))
    ms.add_mesh(_to_ml(*target))
    res = _apply(ms, "get_hausdorff_distance", sampledmesh=0, targetmesh=1, savesample=False,
                 samplevert=True, sampleedge=False, samplefauxedge=False, sampleface=False,
                 samplenum=int(len(samples)), maxdist=pymeshlab.PureValue(maxdist))
    d = np.array(ms.mesh(0).vertex_scalar_array(), dtype=np.float64)
    if int(res.get("n_samples", -1)) != len(samples) or d.shape != (len(samples),):
        raise AsrbfError(
            f"pymeshlab get_hausdorff_distance measured {res.get('n_samples')} of "
            f"{len(samples)} samples")
    return d


def _direction(vertex_d: np.ndarray, area_d: np.ndarray | None) -> dict[str, Any]:
    """Statistics of one direction: max over all samples, mean / RMS over area samples."""
    body = area_d if area_d is not None and len(area_d) else vertex_d
    all_d = vertex_d if area_d is None else np.concatenate([vertex_d, area_d])
    return {"max": float(all_d.max()), "min": float(all_d.min()),
            "mean": float(body.mean()), "rms": float(np.sqrt(np.mean(body**2))),
            "n_samples": int(len(all_d)), "n_vertex_samples": int(len(vertex_d)),
            "n_area_samples": 0 if area_d is None else int(len(area_d))}


def hausdorff(a: Mesh | Scan, b: Mesh | Scan | np.ndarray, *, samples: int | None = None,
              seed: int = 0, keep_samples: bool = False) -> dict[str, Any]:
    """Metro-style distances between a mesh and a reference, both ways (pymeshlab).

    ``b`` is the reference ("the scan"): percentages are of its bounding-box diagonal.
    Each direction ``x -> y`` samples surface ``x`` and measures, with pymeshlab's
    ``get_hausdorff_distance`` filter, each sample's distance to the closest point of
    ``y``. The samples of a mesh are all its (referenced) vertices plus ``samples``
    points drawn uniformly over its area by a seeded, stratified Monte Carlo (the MeshLab filter's
    own face sampling draws from a process-wide generator, so its figures change from
    call to call; ours do not).

    Parameters
    ----------
    a : Mesh or Scan
        The mesh under test (e.g. a level of detail), scan units.
    b : Mesh, Scan or (N, 3) array
        The reference surface, or the reference as a bare point set (a scan without
        faces counts as one).
    samples : int, optional
        Area samples per direction. Default ``max(4 max(V_a, V_b), 10000)`` (``V``:
        referenced vertices), i.e. four area samples per vertex of the denser mesh,
        stratified over the area.
        Ignored for a point-set reference, whose points are all used.
    seed : int
        Seed of the area sampling.
    keep_samples : bool
        Also return every sample: each direction dict then has ``points`` (S, 3) and
        ``distances`` (S,) (vertex samples first, then area samples), and ``a_to_b``
        has ``vertex_index``: the index in ``a`` of each vertex sample.

    Returns
    -------
    dict
        ``hausdorff``, ``mean``, ``rms`` (scan units), the same as ``hausdorff_pct``,
        ``mean_pct``, ``rms_pct`` (100 x value / ``diagonal``), ``diagonal`` (of the
        reference's bounding box), ``n_samples`` (both directions), and the
        per-direction dicts ``a_to_b`` and ``b_to_a`` (``max``, ``min``, ``mean``,
        ``rms``, ``n_samples``, ``n_vertex_samples``, ``n_area_samples``).

    Raises
    ------
    AsrbfError
        A mesh without faces, bad points, or a pymeshlab failure.

    Notes
    -----
    Definitions (Cignoni, Rocchini, Scopigno, "Metro: measuring error on simplified
    surfaces", 1998):

    - ``hausdorff`` = max of both directions' maxima, over vertex and area samples;
    - per direction, ``mean`` and ``rms`` come from the area samples only, so they
      estimate the area-weighted mean (vertex samples would over-weight the regions
      where a mesh is dense, e.g. the curved parts of a QEM mesh);
    - symmetric ``mean`` = average of the two directions' means; ``rms`` = square
      root of the average of their mean squares (each surface counts once; with equal
      area-sample counts this is the pooled mean over all area samples).

    A point-set reference gives only ``b -> a`` (``a_to_b`` is ``None``): the distance
    from a surface to a discrete point set grows with the gaps between the points, not
    with the surface error. Its mean and RMS are over all the points (a range scan
    samples its surface about uniformly). Unreferenced vertices of a mesh are not part
    of its surface and are ignored. Coordinates are centred on the reference before
    they go to MeshLab, which computes in single precision.

    Examples
    --------
    >>> v = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]])
    >>> f = np.array([[0, 1, 3], [0, 3, 2]])
    >>> d = hausdorff(Mesh(v + [0, 0, 0.5], f), Mesh(v, f), samples=100)
    >>> round(d["hausdorff"], 6), round(d["mean"], 6), round(d["hausdorff_pct"], 3)
    (0.5, 0.5, 35.355)
    """
    if isinstance(a, Scan):
        a = a.to_mesh()
    if isinstance(b, Scan):
        b = b.to_mesh() if b.faces is not None else b.points
    _check_mesh(a, "a")
    if samples is not None:
        samples = check_int(samples, "samples", 1)
    seed = check_seed(seed)
    va, fa = compact(a.vertices, a.faces)
    if isinstance(b, Mesh):
        _check_mesh(b, "b")
        vb, fb = compact(b.vertices, b.faces)
    else:
        vb, fb = check_points(b, "b"), None
    if not (np.all(np.isfinite(va)) and np.all(np.isfinite(vb))):
        raise ScanError("hausdorff: meshes must have finite vertex coordinates")
    lo, hi = vb.min(axis=0), vb.max(axis=0)
    centre = 0.5 * (lo + hi)
    diagonal = float(np.linalg.norm(hi - lo))
    va, vb = va - centre, vb - centre
    both = np.vstack([va, vb])
    reach = float(np.linalg.norm(both.max(axis=0) - both.min(axis=0)))
    maxdist = 2.0 * reach + 1.0  # larger than any distance: MeshLab drops farther samples
    rng = np.random.default_rng(seed)

    b_vertex = _distances(vb, (va, fa), maxdist)
    if fb is None:
        a_to_b = None
        b_to_a = _direction(b_vertex, None)
        if keep_samples:
            b_to_a |= {"points": vb + centre, "distances": b_vertex}
    else:
        n = int(samples) if samples is not None else max(
            _SAMPLES_PER_VERTEX * max(len(va), len(vb)), _MIN_SAMPLES)
        sa = _surface_samples(va, fa, n, rng)
        sb = _surface_samples(vb, fb, n, rng)
        a_all = _distances(np.vstack([va, sa]), (vb, fb), maxdist)
        a_to_b = _direction(a_all[: len(va)], a_all[len(va):])
        b_area = _distances(sb, (va, fa), maxdist) if len(sb) else np.empty(0)
        b_to_a = _direction(b_vertex, b_area)
        if keep_samples:
            a_to_b |= {"points": np.vstack([va, sa]) + centre, "distances": a_all,
                       "vertex_index": np.unique(np.asarray(a.faces, dtype=np.int64))}
            b_to_a |= {"points": np.vstack([vb, sb]) + centre,
                       "distances": np.concatenate([b_vertex, b_area])}

    dirs = [d for d in (a_to_b, b_to_a) if d is not None]
    out: dict[str, Any] = {
        "hausdorff": max(d["max"] for d in dirs),
        "mean": float(np.mean([d["mean"] for d in dirs])),
        "rms": float(np.sqrt(np.mean([d["rms"] ** 2 for d in dirs]))),
        "diagonal": diagonal,
        "n_samples": sum(d["n_samples"] for d in dirs),
        "a_to_b": a_to_b,
        "b_to_a": b_to_a,
    }
    scale = 100.0 / diagonal if diagonal > 0 else float("nan")
    for key in ("hausdorff", "mean", "rms"):
        out[f"{key}_pct"] = out[key] * scale
    return out


# --------------------------------------------------------------------------- cleaning


def _repair(ms: pymeshlab.MeshSet) -> None:
    """Duplicate faces, non-manifold edges, then non-manifold vertices (split)."""
    _apply(ms, "meshing_remove_duplicate_faces")
    _apply(ms, "meshing_repair_non_manifold_edges", method="Remove Faces")
    _apply(ms, "meshing_repair_non_manifold_vertices", vertdispratio=0.0)


def repair_non_manifold(vertices: np.ndarray, faces: np.ndarray, *,
                        drop_unreferenced: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Make a triangle mesh two-manifold (pymeshlab).

    Removes duplicate faces, removes the faces that make an edge non-manifold
    (``meshing_repair_non_manifold_edges``, method "Remove Faces"), then splits every
    non-manifold vertex into one copy per fan (``meshing_repair_non_manifold_vertices``,
    no displacement). Raw range scans all have such vertices where two triangles touch
    at a corner (docs/design.md); topology tools disagree on them until they are split.

    Parameters
    ----------
    vertices : (V, 3) array
    faces : (F, 3) int array
    drop_unreferenced : bool
        Also remove the vertices no face references (isolated scan samples).

    Returns
    -------
    vertices : (V', 3) float64 array
        The kept input vertices in their input order (if ``drop_unreferenced`` is
        False, all of them), then the split copies.
    faces : (F', 3) int64 array

    Raises
    ------
    AsrbfError
        Bad arrays or a pymeshlab failure.
    """
    v = check_points(vertices, "vertices")
    f = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    if len(f) == 0 or f.min() < 0 or f.max() >= len(v):
        raise ScanError(f"faces must be a non-empty (F, 3) array of indices into {len(v)} "
                         "vertices")
    ms = pymeshlab.MeshSet()
    ms.add_mesh(_to_ml(v, f))
    _repair(ms)
    if drop_unreferenced:
        _apply(ms, "meshing_remove_unreferenced_vertices")
    m = _from_ml(ms.current_mesh())
    return np.array(m.vertices), np.array(m.faces)


def topological_measures(mesh: Mesh) -> dict[str, Any]:
    """Topology figures of MeshLab's ``get_topological_measures`` (on a fresh MeshSet).

    Keys include ``number_holes`` (-1 when MeshLab cannot count them: non-manifold
    mesh), ``boundary_edges``, ``connected_components_number``,
    ``non_two_manifold_edges``, ``non_two_manifold_vertices``, ``is_mesh_two_manifold``.
    """
    _check_mesh(mesh, "mesh")
    ms = pymeshlab.MeshSet()
    ms.add_mesh(_to_ml(mesh.vertices, mesh.faces))
    return _apply(ms, "get_topological_measures")


def close_holes(mesh: Mesh, *, max_hole_edges: int) -> Mesh:
    """Close the holes bounded by at most ``max_hole_edges`` edges (pymeshlab).

    Repairs non-manifold edges and vertices first (see :func:`repair_non_manifold`;
    unreferenced vertices are kept), then runs ``meshing_close_holes`` with
    ``selfintersection=False``: its default (True) rejects fills that would
    self-intersect and silently left gaps in 4 of 45 holes of the face map
    (docs/design.md). ``get_topological_measures`` is never called on that MeshSet: run
    before it, it made the filter close almost nothing.

    Parameters
    ----------
    mesh : Mesh
        Scan units; normals and quality are not carried over.
    max_hole_edges : int
        MeshLab's ``maxholesize``: boundary edges of the largest hole to close
        (the outer border of a range scan is a "hole" too; keep this below its length).

    Returns
    -------
    Mesh
        The input vertices first, in their order (then the copies made by splitting
        non-manifold vertices); faces: the repaired input faces, then the new ones.
        ``vertex_quality`` is 1 on vertices of new faces, else 0.

    Raises
    ------
    AsrbfError
        Bad arguments or a pymeshlab failure.
    """
    _check_mesh(mesh, "mesh")
    check_int(max_hole_edges, "max_hole_edges", 3)
    ms = pymeshlab.MeshSet()
    ms.add_mesh(_to_ml(mesh.vertices, mesh.faces))
    _repair(ms)
    n_before = ms.current_mesh().face_number()
    _apply(ms, "meshing_close_holes", maxholesize=int(max_hole_edges), selected=False,
           newfaceselected=True, selfintersection=False, refinehole=False,
           refineholeedgelen=pymeshlab.PercentageValue(3.0))
    m = ms.current_mesh()
    if not m.is_compact():
        m.compact()
    out = _from_ml(m)
    filled = np.zeros(out.n_vertices)
    new = np.array(m.face_selection_array(), dtype=bool)
    if new.shape != (out.n_faces,):  # fall back on the face order
        new = np.arange(out.n_faces) >= n_before
    filled[np.unique(out.faces[new])] = 1.0
    return Mesh(out.vertices, out.faces, vertex_quality=filled)


# --------------------------------------------------------------------------- reconstruction


def screened_poisson(points: np.ndarray, *, depth: int = 8, k_normals: int = 10,
                     point_weight: float = 4.0, threads: int = 1) -> Mesh:
    """Screened Poisson surface of a range scan's points (pymeshlab).

    Normals are estimated from the ``k_normals`` nearest points
    (``compute_normal_for_point_clouds``) and oriented toward a viewpoint far along +z
    (``flipflag=True``, ``viewpos`` = centre + 10 diagonals in z): the scanner side of a
    height field seen along -z. Then ``generate_surface_reconstruction_screened_poisson``
    (Kazhdan & Hoppe 2013) runs with every parameter explicit.

    Parameters
    ----------
    points : (N, 3) array
        Scan units, view axis z.
    depth : int
        Octree depth (resolution 2^depth over the bounding cube).
    k_normals : int
        Neighbours used for the normals.
    point_weight : float
        Screening weight (MeshLab's default 4).
    threads : int
        Worker threads of the solver.

    Returns
    -------
    Mesh
        The (closed) Poisson surface with vertex normals; ``vertex_quality`` holds
        MeshLab's per-vertex sample density, used to trim the parts far from data.

    Raises
    ------
    AsrbfError
        Fewer than ``k_normals + 1`` points, bad parameters, or a pymeshlab failure.
    """
    p = check_points(points, "points")
    for name, val, lo in (("depth", depth, 1), ("k_normals", k_normals, 3),
                          ("threads", threads, 1)):
        check_int(val, name, lo)
    if len(p) <= k_normals:
        raise ScanError(f"screened Poisson needs more than k_normals={k_normals} points, "
                         f"got {len(p)}")
    ms = pymeshlab.MeshSet()
    ms.add_mesh(_to_ml(p))
    lo, hi = p.min(axis=0), p.max(axis=0)
    view = 0.5 * (lo + hi) + np.array([0.0, 0.0, 10.0 * max(float(np.linalg.norm(hi - lo)), 1.0)])
    _apply(ms, "compute_normal_for_point_clouds", k=int(k_normals), smoothiter=0,
           flipflag=True, viewpos=view)
    _apply(ms, "generate_surface_reconstruction_screened_poisson", visiblelayer=False,
           depth=int(depth), fulldepth=5, cgdepth=0, scale=1.1, samplespernode=1.5,
           pointweight=float(point_weight), iters=8, confidence=False, preclean=False,
           threads=int(threads))
    return _from_ml(ms.current_mesh(), normals=True, quality=True)


def ball_pivoting(points: np.ndarray, *, radius_rel: float | None = None) -> Mesh:
    """Ball-pivoting triangulation of a point set (pymeshlab).

    Parameters
    ----------
    points : (N, 3) array
        Scan units.
    radius_rel : float, optional
        Ball radius as a fraction of the bounding-box diagonal; ``None``: MeshLab
        guesses it from the point density (``ballradius`` = 0 %).

    Returns
    -------
    Mesh
        The input points as vertices (same order; unreached points stay unreferenced).

    Raises
    ------
    AsrbfError
        Bad arguments or a pymeshlab failure.

    Notes
    -----
    Bernardini et al., "The ball-pivoting algorithm for surface reconstruction",
    IEEE TVCG 5(4), 1999. Fixed: ``clustering`` 20 % of the radius, ``creasethr`` 90°,
    ``deletefaces`` False.
    """
    p = check_points(points, "points")
    if radius_rel is not None and not (np.isfinite(radius_rel) and 0 < radius_rel <= 1):
        raise ConfigError(f"radius_rel must be a fraction of the diagonal in (0, 1], "
                         f"got {radius_rel!r}")
    ms = pymeshlab.MeshSet()
    ms.add_mesh(_to_ml(p))
    pct = 0.0 if radius_rel is None else 100.0 * float(radius_rel)
    _apply(ms, "generate_surface_reconstruction_ball_pivoting",
           ballradius=pymeshlab.PercentageValue(pct), clustering=20.0, creasethr=90.0,
           deletefaces=False)
    return _from_ml(ms.current_mesh())


# --------------------------------------------------------------------------- decimation


def quadric_edge_collapse(mesh: Mesh, *, target_faces: int, preserve_border: bool = True,
                          boundary_weight: float = 1.0, quality_threshold: float = 0.3,
                          optimal_placement: bool = True, preserve_normal: bool = False,
                          preserve_topology: bool = False,
                          planar_quadric: bool = False) -> Mesh:
    """Quadric edge-collapse decimation (Garland & Heckbert 1997; pymeshlab).

    ``meshing_decimation_quadric_edge_collapse`` with every parameter explicit; the
    ones not exposed here are fixed: ``targetperc`` 0 (use the face count),
    ``planarweight`` 0.001, ``qualityweight`` False, ``autoclean`` True (removes
    unreferenced and duplicate vertices), ``selected`` False.

    Parameters
    ----------
    mesh : Mesh
        Scan units.
    target_faces : int
        Requested face count. With ``preserve_border`` the border edges cannot be
        collapsed, so a ragged range-scan border puts a floor under the reachable
        count (≈ 4,100 faces on the face map); the result then has more faces.
    preserve_border : bool
        MeshLab's ``preserveboundary``.
    boundary_weight : float
        ``boundaryweight``: weight of the border-preserving quadrics.
    quality_threshold : float
        ``qualitythr``: penalize collapses creating triangles of quality below it.
    optimal_placement : bool
        ``optimalplacement``: place the new vertex at the quadric's minimum.
    preserve_normal, preserve_topology, planar_quadric : bool
        ``preservenormal``, ``preservetopology``, ``planarquadric``.

    Returns
    -------
    Mesh
        Compact (no unreferenced vertices).

    Raises
    ------
    AsrbfError
        Bad arguments or a pymeshlab failure.
    """
    _check_mesh(mesh, "mesh")
    check_int(target_faces, "target_faces", 1)
    v, f = compact(mesh.vertices, mesh.faces)
    ms = pymeshlab.MeshSet()
    ms.add_mesh(_to_ml(v, f))
    _apply(ms, "meshing_decimation_quadric_edge_collapse", targetfacenum=int(target_faces),
           targetperc=0.0, qualitythr=float(quality_threshold),
           preserveboundary=bool(preserve_border), boundaryweight=float(boundary_weight),
           preservenormal=bool(preserve_normal), preservetopology=bool(preserve_topology),
           optimalplacement=bool(optimal_placement), planarquadric=bool(planar_quadric),
           planarweight=0.001, qualityweight=False, autoclean=True, selected=False)
    out = _from_ml(ms.current_mesh())
    return Mesh(*compact(out.vertices, out.faces))
