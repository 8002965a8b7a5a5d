"""Levels of detail (LOD) of a range scan from ASRBF networks.

The paper (Meng et al. 2013) gives two ways to get a multi-resolution set of meshes
from the learned representation:

- ``resample``: one network, sampled on successively coarser grids (level 0 about the
  scan's own spacing, level 1 twice as coarse, the coarsest at ``s0 * 2**i``:
  :func:`resample_spacings`);
- ``refit``: one network per level, learned with a coarser separation level
  ``D_min = d0 * 2**i``, each sampled at a grid that matches its own detail, so every
  level's network is itself compact.

Level 0 is the finest; the index grows with coarseness (the usual LOD convention, and
the one of the ``2**i`` formulas above). :func:`lod_set` returns the levels in that
order, finest first. Every level is meshed on the scan's own triangles, so its border
and its holes stay where the scan's are (within about a grid cell's diagonal of that
level); ``fill_holes=True`` meshes the holes the scan encloses too.

:func:`write_lod_set` writes the meshes, the networks and a ``manifest.json`` with
sizes and Metro-style errors against the scan, optionally beside quadric-decimation
(QEM) baselines at the same face counts.
"""

from __future__ import annotations

import math
import tempfile
import time
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np

from . import _config
from ._config import FitConfig
from ._fit import fit
from ._frame import Frame, sampling_spacing, to_height_field
from ._io import Scan
from ._learn import auto_d_min
from ._mesh import Mesh
from ._network import Network
from ._outliers import isolated_points
from ._surface import reconstruct
from ._validate import check_bool, check_int, check_seed
from .errors import ConfigError, ScanError

__all__ = [
    "LodLevel",
    "lod_set",
    "network_file_bytes",
    "ply_bytes",
    "METHODS",
    "REFIT_GRID_PER_D_MIN",
    "MIN_LEVEL_SAMPLES",
]

Method = Literal["resample", "refit"]

#: LOD methods of :func:`lod_set`.
METHODS: tuple[str, ...] = _config.LOD_METHODS

#: ``refit`` samples the network of separation ``D_min`` at a grid of ``D_min / 4``.
REFIT_GRID_PER_D_MIN = 4.0

#: Fewest grid samples along the shorter side of the coarsest level's grid.
MIN_LEVEL_SAMPLES = 4
#: A level leaves out the walls between pieces taller than this many of its grid
#: spacings where the scan is open (an occlusion gap: no scan edge joins the two pieces
#: there and the wall's middle is far from the scan's triangles): a wall there is surface
#: the scan does not have, which Metro samples
#: (:func:`~asrbf_mesh._surface.reconstruct`, ``max_wall``).
LOD_MAX_WALL = 3.0
#: ``resample``: levels past level 1 grow by at least this factor each, and level 0
#: takes the scan's own spacing where ``s0`` is finer than this share of it (see
#: :func:`resample_spacings`).
MIN_LEVEL_STEP = 1.25
FINER_THAN_SCAN = 0.9


def resample_spacings(s0: float, own: float, levels: int) -> list[float]:
    """Grid spacings of a ``resample`` set's levels, finest first (scan units).

    ``s0``: the unit square's sampling spacing times the geometric mean of the scan's
    two extents; ``own``: the scan's own spacing in the view plane (median nearest
    neighbour, scan units). The two agree on a scan about as wide as long; on an
    elongated one ``s0`` is finer (the unit square's spacing is measured along its long
    axis): 0.63 of ``own`` on a view of a bone 2.5 times as long as wide, 0.42 on an
    airplane's. Level 0 is ``s0``, or the scan's own spacing where ``s0`` is finer than
    :data:`FINER_THAN_SCAN` of it: never much finer than the scan's own sampling (a
    finer grid adds vertices and follows the network between the samples: on the bone
    view 2.5 times as many vertices as the scan has points, and a Metro RMS above level
    1's); level 1 is twice level 0; the coarsest level stays at
    ``s0 * 2**(levels - 1)`` (the old rule's, whose 99.9th percentiles keep within 1 % of
    the diagonal), or :data:`MIN_LEVEL_STEP` per level past level 1 if that is coarser;
    the levels between are spaced geometrically.

    Examples
    --------
    >>> [round(s, 3) for s in resample_spacings(0.95, 1.0, 4)]
    [0.95, 1.9, 3.8, 7.6]
    >>> [round(s, 3) for s in resample_spacings(0.5, 1.0, 4)]
    [1.0, 2.0, 2.828, 4.0]
    """
    first = own if s0 < FINER_THAN_SCAN * own else s0
    if levels == 1:
        return [first]
    last = max(s0 * 2.0 ** (levels - 1), 2.0 * first * MIN_LEVEL_STEP ** (levels - 2))
    steps = np.arange(levels - 1) / max(levels - 2, 1)
    return [first, *(float(s) for s in 2.0 * first * (last / (2.0 * first)) ** steps)]


@dataclass(frozen=True, eq=False)
class LodLevel:
    """One level of detail.

    Parameters
    ----------
    index : int
        Level number; 0 is the finest.
    method : {"resample", "refit"}
        How the level was made.
    mesh : Mesh
        The level's mesh, scan units.
    network_bytes : int or None
        Size of the level's network as a ``.asrbf`` file (float32 parameters, no
        learning log; see :func:`network_file_bytes`). With ``resample`` every level
        shares one network and reports its size.
    d_min : float or None
        D_min (unit square) of the level's network.
    n_neurons : int or None
        K of the level's network.
    seconds : float
        Wall time to make the level: grid evaluation (``resample``; the shared fit is
        in ``network.info["fit_seconds"]``) or fit plus grid evaluation (``refit``).
    spacing_abs : float or None
        Grid spacing of the mesh, scan units.
    network : Network or None
        The network the mesh was sampled from, as the set ships it (compact parameters,
        read back from its file; the same object for every level of a ``resample`` set).
    """

    index: int
    method: str
    mesh: Mesh
    network_bytes: int | None
    d_min: float | None
    n_neurons: int | None
    seconds: float
    spacing_abs: float | None = None
    network: Network | None = None


# --------------------------------------------------------------------------- sizes


def _save_network(net: Network, path: Path, inputs: tuple[str, ...] = ()) -> Path:
    """Write ``net`` as a LOD set ships it: compact parameters, no learning log."""
    return net.without_logs().save(path, compact=True, inputs=inputs)


def shipped(net: Network) -> tuple[Network, int]:
    """Return the network as a LOD set ships it (written, read back) and its file size.

    The levels are meshed from this network, so a reader who rebuilds a level from the
    file gets the same mesh.
    """
    with tempfile.TemporaryDirectory() as tmp:
        path = _save_network(net, Path(tmp) / "n.asrbf")
        return Network.load(path), path.stat().st_size


def network_file_bytes(net: Network) -> int:
    """Size in bytes of ``net`` written as a ``.asrbf`` file for a LOD set.

    The file is what :func:`write_lod_set` writes: compact neuron parameters (uint16
    centres, float16 widths and weights), frame, configuration, piece map and provenance
    (JSON), deflated; without the learning log (a history for plots, not part of the
    surface).

    Examples
    --------
    >>> from asrbf_mesh._frame import Frame
    >>> net = Network(0.0, np.zeros((3, 2)), np.ones(3), np.ones(3),
    ...               Frame(np.eye(3), np.zeros(3), np.ones(3)), FitConfig())
    >>> 1000 < network_file_bytes(net) < 4000
    True
    """
    return shipped(net)[1]


def ply_bytes(n_vertices: int, n_faces: int) -> int:
    """Size of a triangle mesh as a binary PLY of float32 vertices and int32 faces.

    The header below, ``12`` bytes per vertex (x, y, z float32) and ``13`` per face (a
    uchar count and three int32 indices). This is how the QEM baselines' size is
    counted: the smallest usual file that stores a mesh as it is.

    Examples
    --------
    >>> ply_bytes(3, 1)
    218
    """
    header = ("ply\nformat binary_little_endian 1.0\n"
              f"element vertex {int(n_vertices)}\n"
              "property float x\nproperty float y\nproperty float z\n"
              f"element face {int(n_faces)}\n"
              "property list uchar int vertex_indices\nend_header\n")
    return len(header.encode()) + 12 * int(n_vertices) + 13 * int(n_faces)


def _grid_cells(mesh: Mesh, frame: Frame, spacing_abs: float) -> tuple[np.ndarray, int, int]:
    """Grid cells (j, i) of a mesh made by :func:`~asrbf_mesh._surface.reconstruct`."""
    span = frame.scale[:2]
    nx = max(int(round(span[0] / spacing_abs)) + 1, 2)
    ny = max(int(round(span[1] / spacing_abs)) + 1, 2)
    step = span / np.array([nx - 1, ny - 1])
    local = (mesh.vertices @ frame.rotation)[:, :2]
    ij = np.rint((local - frame.offset[:2]) / step).astype(np.int64)
    cell = ij[mesh.faces].min(axis=1)
    return cell, nx, ny


def _footprint_bytes(mesh: Mesh, frame: Frame, spacing_abs: float) -> int:
    """Deflated size of the bitmap of grid cells a level keeps (one bit per cell)."""
    cell, nx, ny = _grid_cells(mesh, frame, spacing_abs)
    mask = np.zeros((ny - 1, nx - 1), dtype=bool)
    ok = (cell[:, 0] >= 0) & (cell[:, 0] < nx - 1) & (cell[:, 1] >= 0) & (cell[:, 1] < ny - 1)
    mask[cell[ok, 1], cell[ok, 0]] = True
    return len(zlib.compress(np.packbits(mask).tobytes(), 9))


# --------------------------------------------------------------------------- checks


def _as_scan(scan: Scan | np.ndarray) -> Scan:
    if isinstance(scan, Scan):
        return scan
    if isinstance(scan, Mesh):
        return Scan(scan.vertices, scan.faces)
    try:
        return Scan(np.asarray(scan))
    except (TypeError, ValueError) as exc:
        raise ScanError(f"scan must be a Scan or an (N, 3) array of points ({exc})") from None


def _check_d_mins(d_mins: Any, levels: int) -> list[float]:
    try:
        out = [float(d) for d in d_mins]
    except (TypeError, ValueError):
        raise ConfigError(
            f"d_mins must be a sequence of {levels} numbers, got {d_mins!r}") from None
    if len(out) != levels:
        raise ConfigError(f"d_mins must hold one D_min per level ({levels}), got {len(out)}")
    if not all(math.isfinite(d) and d > 0 for d in out):
        raise ConfigError(f"d_mins must be positive finite numbers (unit square), got {out}")
    if any(b < a for a, b in zip(out[:-1], out[1:], strict=True)):
        raise ConfigError(f"d_mins must not decrease with the level (level 0 is the finest), "
                          f"got {out}")
    return out



def _check_coarsest(levels: int, span: np.ndarray, spacings: Any) -> None:
    """Refuse levels whose grid would have fewer than MIN_LEVEL_SAMPLES along the short side.

    ``spacings(i)`` is level i's grid spacing (scan units); the grid of a spacing ``s``
    has ``round(short / s) + 1`` samples along the shorter side ``short`` (as in
    :func:`~asrbf_mesh._surface.reconstruct`).
    """
    short = float(np.min(span))

    def ok(i: int) -> bool:
        return int(round(short / spacings(i))) + 1 >= MIN_LEVEL_SAMPLES

    if ok(levels - 1):
        return
    best = 0
    while best < levels and ok(best):
        best += 1
    if best == 0:
        raise ConfigError(f"the finest level's grid would have fewer than {MIN_LEVEL_SAMPLES} "
                          "samples along the shorter side of the scan: raise base_resolution")
    raise ConfigError(f"levels must be at most {best} for this scan: a coarser level's grid "
                      f"would have fewer than {MIN_LEVEL_SAMPLES} samples along the shorter "
                      f"side, got levels={levels}")


# --------------------------------------------------------------------------- lod_set


def lod_set(scan: Scan | np.ndarray, *, levels: int = 4, method: Method = "resample",
            net: Network | None = None, seed: int = 0, d_mins: list[float] | None = None,
            footprint: bool = True, base_resolution: int | None = None,
            pieces: str | int = "auto", fill_holes: bool = False) -> list[LodLevel]:
    """Build a set of levels of detail of a range scan.

    Parameters
    ----------
    scan : Scan or (N, 3) array
        The range scan, scan units (view axis z unless ``net`` says otherwise).
    levels : int
        Number of levels (>= 1). Every level's grid must have at least
        :data:`MIN_LEVEL_SAMPLES` (4) samples along the shorter side of the scan's
        extent; more levels are refused with :class:`ConfigError` (the message gives
        the most this scan allows), as are ``refit`` levels whose D_min would exceed
        D_max.
    method : {"resample", "refit"}
        ``resample``: one network sampled on grids from ``s0`` (level 0) to
        ``s0 * 2**(levels - 1)``, where ``s0`` is the scan's sampling spacing in the unit
        square times the geometric mean of the scan's two extents (the scan's own
        spacing for a scan about as wide as long, finer for an elongated one, whose
        level 0 takes the scan's own spacing in the view plane instead); level 1 twice as
        coarse as level 0, the levels between spaced geometrically
        (:func:`resample_spacings`). ``refit``: one
        fit per level with ``D_min = d0 * 2**i`` (``d0``: the automatic D_min of the
        scan, 0.01 for the paper's defaults and the scans shipped here), sampled at
        spacing ``D_min / 4`` in scan units (level 0 not finer than ``s0``, the others
        scaled with D_min from it).
    net : Network, optional
        ``resample``: the network to sample (default: ``fit(scan, seed=seed)``).
        ``refit``: its configuration (and view axis) is the base of every level's fit,
        only D_min changes.
    seed : int
        Seed of the fits.
    d_mins : sequence of float, optional
        ``refit``: the D_min of each level (unit square), non-decreasing.
    footprint : bool
        Mesh only the scan's footprint (its triangles: :func:`~asrbf_mesh.reconstruct`
        mode ``surface``), so the border and the holes stay the scan's. False: the whole
        normalized square.
    fill_holes : bool
        With ``footprint``: also mesh the holes the scan's triangles enclose (mode
        ``scan``), the network's surface over them. Off by default: a level then stays on
        the scan, which gave the level sets of BENCHMARKS "LOD sets of the piecewise
        model" an RMS that never falls with the level (on 15 of 15 scans and seeds,
        against 13 of 15 with the holes filled, where the fill's distance to the scan,
        not the level's error, decided the order) and a mesh-to-scan 99.9th percentile of
        0.43-0.81 % of the diagonal (medians over seeds 0-2; face 2.19 % with its 23
        natural holes filled).
    base_resolution : int, optional
        Samples along the longer side of the level-0 grid, instead of the default
        spacings above; coarser levels scale it by ``2**i`` (``resample``) or by
        ``D_min_i / D_min_0`` (``refit``).
    pieces : "auto" or 1
        The fits made here: one network per smooth piece (``"auto"``), each level's mesh
        made piece by piece and stitched (:func:`~asrbf_mesh.reconstruct`), or the
        paper's single network (see :func:`~asrbf_mesh.fit`).

    Returns
    -------
    list of LodLevel
        Finest first: ``levels[i].index == i`` and face counts decrease with ``i``.

    Raises
    ------
    ConfigError
        Bad ``levels`` (too many for the scan, see above), ``method``, ``seed``,
        ``d_mins`` or ``base_resolution``, or a grid too large.
    ScanError
        Unusable scan points, or a footprint that selects no cell.

    Notes
    -----
    Why ``D_min / 4`` for ``refit``: a network of separation D_min has Gaussians as
    narrow as ``psi * D_min = 0.7 D_min``; a grid of a quarter of D_min puts about
    three samples across the narrowest one. On the face map (BENCHMARKS.md, "LOD"),
    that came within 0-20 % of each network's own RMS error (its mesh at the scan's
    spacing) at D_min = 0.01 ... 0.08, where ``D_min / 2`` was 2-75 % above it and
    ``D_min`` 7-195 %.

    ``resample`` samples without prefiltering: the narrow Gaussians of a fine network
    alias on coarse grids. On the face map the coarsest resampled level (RMS 0.52 % of
    the diagonal, 4,040 faces) lost to the coarsest refit level (0.38 %, 2,958 faces);
    on bun000 it did not (0.27 % against 0.36 %, both 1,754 faces).

    References
    ----------
    Meng, Q., Li, B., Holstein, H., Liu, Y. "Parameterization of point-cloud freeform
    surfaces using adaptive sequential learning RBF networks", Pattern Recognition 46
    (2013): multi-resolution representation from one network or from networks of
    several separation levels.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> xy = rng.random((2000, 2))
    >>> pts = np.c_[xy, 0.2 * np.sin(4 * xy[:, 0])]
    >>> lods = lod_set(pts, levels=3)
    >>> [lv.index for lv in lods], lods[0].n_neurons == lods[2].n_neurons
    ([0, 1, 2], True)
    >>> lods[0].mesh.n_faces > lods[1].mesh.n_faces > lods[2].mesh.n_faces
    True
    """
    levels = check_int(levels, "levels", 1)
    if method not in METHODS:
        raise ConfigError(f"method must be one of {', '.join(METHODS)}; got {method!r}")
    if base_resolution is not None:
        base_resolution = check_int(base_resolution, "base_resolution", 2)
    seed = check_seed(seed)
    if net is not None and not isinstance(net, Network):
        raise ConfigError(f"net must be a Network, got {type(net).__name__}")
    check_bool(footprint, "footprint")
    check_bool(fill_holes, "fill_holes")
    if fill_holes and not footprint:
        raise ConfigError("fill_holes applies with footprint=True only (the whole square "
                          "has no holes)")
    if d_mins is not None and method != "refit":
        raise ConfigError("d_mins applies to method 'refit' only")
    sc = _as_scan(scan)
    # every cell touching the footprint: a fragment or strip narrower than a coarse cell
    # keeps its surface (the mesh's outer nodes end on the scan, see reconstruct)
    fp_kw: dict[str, Any] = ({"footprint": sc, "mode": "scan" if fill_holes else "surface",
                              "coverage": "any"}
                             if footprint else {})

    if method == "resample":
        # the grid spacings come from the scan alone: refuse too many levels before the fit
        frame = net.frame if net is not None else None
        spacing = net.info.get("spacing") if net is not None else None
        if frame is None or not spacing:
            inliers = sc.points[~isolated_points(sc.points)]  # as the fit will see them
            hf = to_height_field(inliers, view_axis=frame.view_axis if frame else "z",
                                 warn_fraction=1.0)  # the fit warns, once
            frame, spacing = frame or hf.frame, spacing or hf.spacing
        gmean = float(np.sqrt(frame.scale[0] * frame.scale[1]))
        if base_resolution is not None:
            s0 = float(frame.scale[:2].max()) / (base_resolution - 1)
            _check_coarsest(levels, frame.scale[:2], lambda i: s0 * 2.0 ** min(i, 200))
            spacings = [s0 * 2.0**i for i in range(levels)]
        else:
            s0 = float(spacing) * gmean
            own = sampling_spacing((sc.points @ frame.rotation)[:, :2])
            _check_coarsest(levels, frame.scale[:2],
                            lambda i: resample_spacings(s0, own, min(i, 200) + 1)[-1])
            spacings = resample_spacings(s0, own, levels)
        if net is None:
            net = fit(sc, seed=seed, pieces=pieces, progress=False)
        net, nbytes = shipped(net)
        out = []
        for i in range(levels):
            t = time.perf_counter()
            mesh = reconstruct(net, spacing_abs=spacings[i], max_wall=LOD_MAX_WALL, **fp_kw)
            d_min = net.info.get("d_min")
            out.append(LodLevel(i, "resample", mesh, nbytes,
                                None if d_min is None else float(d_min), net.n_neurons,
                                time.perf_counter() - t, spacings[i], net))
        return out

    # refit
    base_cfg = net.config if net is not None else FitConfig()
    view_axis = net.frame.view_axis if net is not None else "z"
    hf = to_height_field(sc.points, view_axis=view_axis)  # type: ignore[arg-type]
    if d_mins is None:
        d0 = base_cfg.d_min if base_cfg.d_min is not None else auto_d_min(
            hf.spacing, base_cfg.error_threshold)
        if levels > 1 and d0 * 2.0 ** min(levels - 1, 200) > base_cfg.d_max:
            most = 1 + int(math.floor(math.log2(base_cfg.d_max / d0) + 1e-12))
            raise ConfigError(f"levels must be at most {most} for this scan: the coarsest "
                              f"D_min ({d0:g} * 2**{levels - 1}) would exceed D_max "
                              f"({base_cfg.d_max:g}); use fewer levels or a larger d_max")
        dm = [d0 * 2**i for i in range(levels)]
    else:
        dm = _check_d_mins(d_mins, levels)
    if dm[-1] > base_cfg.d_max:
        raise ConfigError(f"the coarsest D_min ({dm[-1]:g}) exceeds D_max ({base_cfg.d_max:g}): "
                          "use fewer levels or a larger d_max")
    gmean = float(np.sqrt(hf.frame.scale[0] * hf.frame.scale[1]))
    floor = hf.spacing * gmean
    if base_resolution is not None:
        s0 = float(hf.frame.scale[:2].max()) / (base_resolution - 1)
    else:
        s0 = max(dm[0] / REFIT_GRID_PER_D_MIN * gmean, floor)
    spacings = [s0 * d / dm[0] for d in dm]
    _check_coarsest(levels, hf.frame.scale[:2], spacings.__getitem__)
    out = []
    for i, (d, s) in enumerate(zip(dm, spacings, strict=True)):
        t = time.perf_counter()
        ni = fit(sc, base_cfg.replace(d_min=d), seed=seed, view_axis=view_axis,
                 pieces=pieces, progress=False)
        ni, nbytes = shipped(ni)
        mesh = reconstruct(ni, spacing_abs=s, max_wall=LOD_MAX_WALL, **fp_kw)
        seconds = time.perf_counter() - t
        out.append(LodLevel(i, "refit", mesh, nbytes, d, ni.n_neurons, seconds, s, ni))
    return out
