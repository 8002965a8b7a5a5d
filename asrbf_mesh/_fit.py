"""Fitting a scan: outliers out, the scan cut into smooth pieces, one network per piece.

:func:`fit` is the entry point of every command that learns: it leaves isolated points
out (:mod:`asrbf_mesh._outliers`), builds the whole scan's frame, cuts the scan into
pieces that are each a smooth height field (:func:`~asrbf_mesh.segment`, ``pieces="auto"``)
and learns them (:mod:`asrbf_mesh._pieces`), or learns the paper's single network
(``pieces=1``); either way it returns a :class:`~asrbf_mesh.Network`.
"""

from __future__ import annotations

import threading
import time
import warnings
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import numpy as np

from . import _config
from ._blas import one_blas_thread
from ._config import LOCAL_WIDTH, FitConfig
from ._frame import HeightField, to_height_field
from ._io import Scan
from ._jit_cache import compile_seconds
from ._learn import MIN_POINTS, fit_info, learn_polished, polish_kind, residuals, source_hash
from ._mesh import Mesh
from ._network import FitInfo, Network
from ._outliers import OutlierWarning, describe_isolated, isolated_points
from ._pieces import learn_pieces, parallel_pieces, refine_tails
from ._segment import Segmentation, depth_quanta, segment
from ._tail_shapes import DataShapes
from ._validate import check_choice, check_points, check_seed
from ._version import __version__
from .errors import ConfigError, ScanError

__all__ = ["fit", "check_pieces"]


def check_pieces(pieces: Any) -> str | Segmentation:
    """Return ``"auto"``, ``"1"`` or the :class:`Segmentation` given; else ConfigError."""
    if isinstance(pieces, Segmentation):
        return pieces
    if isinstance(pieces, int) and not isinstance(pieces, bool):
        pieces = str(pieces)
    return check_choice(pieces, "pieces", _config.PIECES)


def fit(scan: Scan | np.ndarray, config: FitConfig | None = None, *, seed: int = 0,
        view_axis: str = "z", pieces: str | int | Segmentation = "auto",
        progress: bool | None = None,
        order: Callable[[np.random.Generator], np.ndarray] | None = None,
        **overrides: Any) -> Network:
    """Fit a range scan: one ASRBF network per smooth piece (learning, then the polish).

    Parameters
    ----------
    scan : Scan or (N, 3) array
        The scan points in world units (a Scan's triangles guide the segmentation).
    config : FitConfig, optional
        Learning parameters, the same for every piece; paper defaults (section 5.1)
        with D_min from the data.
    seed : int
        Random replay order; the same seed gives the same network bit for bit. Piece
        ``i`` of several learns with :func:`~asrbf_mesh._pieces.piece_seed` ``(seed, i)``.
    view_axis : {"z", "x", "y", "pca"}
        Depth direction of the height field.
    pieces : "auto", 1 or Segmentation
        ``"auto"``: cut the scan into smooth pieces (:func:`~asrbf_mesh.segment` with its
        defaults) and learn one network per piece, all in the whole scan's frame with
        the same thresholds; a scan of one piece gives exactly the single network.
        ``1``: the paper's single network over the whole scan. A :class:`Segmentation`
        of the scan's points: those pieces.
    progress : bool, optional
        Progress bar on stderr (default: on a terminal, for fits over a second).
    order : callable, optional
        The replay order of each pass, see :func:`~asrbf_mesh.learn` (default: a uniform
        random permutation per pass); a single network only (``pieces=1``).
    **overrides
        FitConfig fields to change, e.g. ``passes=3``.

    Returns
    -------
    Network
        With ``info`` holding ``n_points``, ``n_pieces``, ``ebar`` (mean |f - z| in the
        unit cube over all points, each by its own piece), ``error_mean`` /
        ``error_std`` (|depth error| in scan units), ``steps``, timings and provenance
        (typed: ``net.fit_info``, a :class:`FitInfo`). When most points fold over along
        the view axis (a closed mesh: no height field), the polish is skipped with a
        :class:`HeightFieldWarning` (see :func:`~asrbf_mesh._learn.polish_kind`).

    Raises
    ------
    ConfigError
        A bad argument (``pieces``, ``order`` with several pieces, ...).
    ScanError
        Unusable points (too few, NaN, zero x or y extent).
    FitError
        The GEKF updater would need more than 2,000 neurons.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> xy = rng.random((3000, 2))
    >>> pts = np.c_[xy, np.sin(3 * xy[:, 0]) * np.cos(2 * xy[:, 1])]
    >>> net = fit(pts, seed=0, progress=False)
    >>> bool(net.info["ebar"] < 0.01), net.n_pieces
    (True, 1)
    """
    seed = check_seed(seed)
    pieces = check_pieces(pieces)
    cfg = (config or FitConfig()).replace(**overrides) if overrides else (config or FitConfig())
    if isinstance(scan, Scan):
        points, source, faces = scan.points, scan.source, scan.faces
    else:
        points, source, faces = check_points(scan, "points"), None, None
    named = f"{source}: " if source else ""
    if len(points) < MIN_POINTS:
        raise ScanError(f"{named}a fit needs at least {MIN_POINTS} points, got {len(points)}")
    if isinstance(pieces, Segmentation) and pieces.n_points != len(points):
        raise ConfigError(f"pieces: the segmentation has {pieces.n_points:,} points, the scan "
                          f"{len(points):,}")
    # BLAS on one thread for the whole fit: its threads spin after each call, on the
    # cores the numba kernels want (:mod:`._blas`)
    with one_blas_thread():
        return _fit_checked(points, source, faces, named, cfg, seed, view_axis, pieces,
                            progress, order)


def _fit_checked(points: np.ndarray, source: str | None, faces: np.ndarray | None,
                 named: str, cfg: FitConfig, seed: int, view_axis: str,
                 pieces: str | Segmentation, progress: bool | None,
                 order: Callable[[np.random.Generator], np.ndarray] | None) -> Network:
    """Fit checked arguments (the body of :func:`fit`)."""
    t0 = (time.perf_counter(), compile_seconds())
    # the cut into pieces runs beside the search for isolated points, the frame and the
    # sampling measures (mostly KD-tree queries and compiled kernels that release the
    # GIL): on two cores it hides the segmentation's time. It is cut again without the
    # isolated points when there are some (rare: real scans have none)
    with ThreadPoolExecutor(max_workers=1) as pool:
        none = np.zeros(len(points), dtype=bool)
        cut = pool.submit(_segmentation, pieces, points, faces, none, view_axis)
        stray = isolated_points(points)
        n_stray = int(stray.sum())
        fitted = points
        if n_stray:  # stray returns would set the frame and pull the surface: leave them out
            warnings.warn(describe_isolated(points, stray, named), OutlierWarning,
                          stacklevel=3)
            fitted = points[~stray]
            if len(fitted) < MIN_POINTS:
                raise ScanError(f"{named}a fit needs at least {MIN_POINTS} points that are "
                                f"not isolated, got {len(fitted)}")
            cut.cancel()
            cut = pool.submit(_segmentation, pieces, fitted, faces, stray, view_axis)
        try:
            hf = to_height_field(fitted, view_axis=view_axis)  # type: ignore[arg-type]
        except ScanError as exc:  # (leaving the block waits for the cut: no stray thread)
            if not named or str(exc).startswith(named):
                raise
            raise ScanError(f"{named}{exc}") from None  # name the file, like load_scan
        seg = cut.result()
    if seg is not None and order is not None:
        raise ConfigError("order applies to a single network: pass pieces=1")
    polish = polish_kind(hf.fold, cfg.polish, stacklevel=4)
    common = (source, source_hash(points), int(seed), n_stray or None)
    loose = None  # the points in no scan triangle, as the fit holds them
    if faces is not None and len(faces):
        loose = np.ones(len(points), dtype=bool)
        loose[np.asarray(faces).ravel()] = False
        loose = loose[~stray]
    if seg is None or seg.n_pieces == 1 or (pieces == "auto" and _scattered(seg)):
        # the paper's single network (pieces=1) is learned and polished as it was; the
        # default model, one piece or scattered, learns as it and gets its tails refined
        if cfg.local_width is None:
            cfg = cfg.replace(local_width=0.0)
        return _fit_single(hf, cfg, polish, seed, progress, order, t0, *common,
                           refine=pieces != "1", loose=loose)
    if cfg.local_width is None:  # the pieces keep their steps local
        cfg = cfg.replace(local_width=LOCAL_WIDTH)
    return _fit_pieces(hf, seg, cfg, polish, seed, progress, t0, *common, loose=loose)


#: Pieces that learn (not small) must hold at least this share of the points.
MIN_LEARNED_SHARE = 0.5


def _scattered(seg: Segmentation) -> bool:
    """Whether the cut scattered the scan into small pieces (a sparse, uneven cloud).

    Then most points would get a constant: one network over the whole scan fits better,
    and :func:`fit` falls back to it.
    """
    return float(seg.sizes[~seg.small].sum()) < MIN_LEARNED_SHARE * seg.n_points


def _segmentation(pieces: str | Segmentation, points: np.ndarray, faces: np.ndarray | None,
                  stray: np.ndarray, view_axis: str) -> Segmentation | None:
    """Return the pieces of the points kept (None for a single network)."""
    if isinstance(pieces, Segmentation):
        if stray.any():
            raise ConfigError("pieces: a segmentation cannot be given for a scan with "
                              "isolated points (they are left out of the fit)")
        if pieces.view_axis != view_axis:
            raise ConfigError(f"pieces: the segmentation was made along view axis "
                              f"{pieces.view_axis!r}, not {view_axis!r}")
        return pieces
    if pieces == "1":
        return None
    if faces is not None and len(faces) and stray.any():  # drop the strays' triangles
        new = np.cumsum(~stray) - 1
        faces = new[faces[~stray[faces].any(axis=1)]]
    mesh = Mesh(points, faces if faces is not None else np.zeros((0, 3), np.int64))
    return segment(mesh, view_axis=view_axis)


def _elapsed(t0: tuple[float, float]) -> tuple[float, float]:
    """Wall seconds since ``t0`` (time, compile seconds), and the compiling among them."""
    return time.perf_counter() - t0[0], compile_seconds() - t0[1]


def _fit_single(hf: HeightField, cfg: FitConfig, polish: str, seed: int,
                progress: bool | None, order: Any, t0: tuple[float, float],
                source: str | None, sha: str, seed_out: int, outliers: int | None, *,
                refine: bool = False, loose: np.ndarray | None = None) -> Network:
    refine = refine and polish != "none"
    # the tails' data shapes, measured beside the learning (which runs on one core)
    shapes = DataShapes(hf) if refine and parallel_pieces() else None
    beside = threading.Thread(target=shapes.run, daemon=True) if shapes else None
    if beside is not None:
        beside.start()
    try:
        learned, pr, params, polish_seconds = learn_polished(
            hf, cfg, polish, seed=seed, progress=progress, order=order,
            keep_residual=refine)  # one piece: no weak neuron dropped (see TAIL_PRUNE)
        added = 0
        if refine:
            tr = time.perf_counter()
            quanta = depth_quanta(hf.z)
            params, added = refine_tails(hf, cfg, *params, learned.d_min, pr,
                                         None if quanta is None else quanta.at(hf.z),
                                         no_more=True, loose=loose, shapes=shapes)
            polish_seconds += time.perf_counter() - tr
    finally:
        if beside is not None:
            shapes.take()  # stops it after the chunk in hand
            beside.join()
    a0, centers, widths, weights = params
    net = Network(a0, centers, widths, weights, hf.frame, cfg, learned.log)
    res = residuals(net, hf)
    abs_mm = np.abs(res) * hf.frame.scale[2]
    fit_s, compile_s = _elapsed(t0)
    info = fit_info(hf.n_points, net, source, sha, seed_out, hf.spacing, learned, pr,
                    float(np.mean(np.abs(res))), float(abs_mm.mean()), float(abs_mm.std()),
                    polish_seconds, fit_s, compile_seconds=compile_s, outliers=outliers,
                    weak_pruned=len(learned.widths) - len(widths) + added,
                    tail_neurons=added)
    return Network(a0, centers, widths, weights, hf.frame, cfg, learned.log, info.to_dict())


def _fit_pieces(hf: HeightField, seg: Segmentation, cfg: FitConfig, polish: str, seed: int,
                progress: bool | None, t0: tuple[float, float], source: str | None, sha: str,
                seed_out: int, outliers: int | None, *,
                loose: np.ndarray | None = None) -> Network:
    got = learn_pieces(hf, seg, cfg, polish, seed=seed, progress=progress, loose=loose)
    abs_mm = got.absres * hf.frame.scale[2]
    fit_s, compile_s = _elapsed(t0)
    k = sum(p.n_neurons for p in got.pieces)
    info = FitInfo(
        n_points=hf.n_points, n_neurons=k, source=source, source_sha256=sha, seed=seed_out,
        spacing=hf.spacing, d_min=got.d_min, steps=got.steps, ebar=float(got.absres.mean()),
        ebar_sequential=got.ebar_sequential, error_mean=float(abs_mm.mean()),
        error_std=float(abs_mm.std()), learn_seconds=got.learn_seconds,
        polish_seconds=got.polish_seconds, fit_seconds=fit_s, compile_seconds=compile_s,
        us_per_step=1e6 * got.learn_seconds / max(got.steps, 1), version=__version__,
        outliers=outliers, n_pieces=len(got.pieces),
        weak_pruned=sum(p.info.get("weak_pruned", 0) for p in got.pieces),
        tail_neurons=sum(p.info.get("tail_neurons", 0) for p in got.pieces))
    return Network.from_pieces(got.pieces, hf.frame, cfg, info.to_dict(), got.piece_map)
