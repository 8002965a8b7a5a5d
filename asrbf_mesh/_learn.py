"""Adaptive sequential learning of a Gaussian RBF network (the paper's Algorithm 1).

Each observation ``(x_n, z_n)`` of a random replay of the scan goes through:

1. growth: a neuron ``u = x_n, a = r_n, sigma = psi ||x_n - u_near||`` is added when
   the input is novel: far from every centre (``> D``), badly fitted
   (``|r_n| > E``) and the windowed RMS error is still above ``E_omega``;
2. optimization: otherwise the nearest neuron (or a neighbourhood) and the bias
   are corrected by the NEKF (or GEKF / gradient descent);
3. pruning: neurons whose contribution ratio stays below ``P`` are removed.

The loop runs in compiled code (:mod:`asrbf_mesh._learn_kernels`); this module owns
the state, feeds it chunk by chunk, grows its arrays, shows progress and builds
the :class:`~asrbf_mesh.Network`.

References
----------
Meng, Q., Li, B., Holstein, H., Liu, Y. "Parameterization of point-cloud freeform
surfaces using adaptive sequential learning RBF networks", Pattern Recognition 46
(2013), sections 3 and 5.1.
"""

from __future__ import annotations

import hashlib
import math
import time
import warnings
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from . import _learn_kernels as _lk
from . import _validate
from ._config import FitConfig
from ._frame import HeightField, HeightFieldWarning
from ._network import FitInfo, FitLog, Network
from ._validate import check_seed
from ._version import __version__
from .errors import FitError, ScanError

__all__ = ["learn", "learn_from", "auto_d_min", "residuals", "fit_info", "MIN_POINTS",
           "LearnedState", "NeuronCapWarning", "learn_polished"]


class NeuronCapWarning(UserWarning):
    """The neuron cap (``FitConfig.max_neurons``) stopped the network's growth."""


MIN_POINTS = 10
_CENTRE_BOX = (-0.25, 1.25)
_SIGMA_RANGE = (1e-5, 2.0)
_CHUNK = 16_384
_LOG_POINTS = 2_000
_GEKF_MAX = 2_000  # neurons: the GEKF's full covariance is (1 + 4 K)^2 floats
_SLOTS = 1_024  # neuron slots allocated first (GEKF: 256), doubled when full
#: Fraction of points on folds (see :func:`~asrbf_mesh._frame.fold_fraction`) above which
#: the polish is skipped: most points fold over, the data is not a height field.
FOLD_NO_POLISH = 0.5


def auto_d_min(spacing: float, error_threshold: float = 0.01) -> float:
    """Automatic D_min: ``max(2 * spacing, E)``, at most 0.2 (unit square).

    Section 5.1 of the paper sets D_min to twice the uni-dimensional sampling
    spacing: 0.01 for its 200 x 200 scans, where it equals the default E = 0.01.
    On denser scans twice the spacing is finer than the detail an accuracy E asks
    for: on the face map (2 x spacing = 0.0043, E = 0.01) it added 37 % more neurons
    for the same E-bar, while at E = 0.003 the finer separation is what reaches
    E-bar = 0.0010 (BENCHMARKS.md, "D_min"). Tying the floor to E keeps both.

    Examples
    --------
    >>> auto_d_min(1 / 200)
    0.01
    >>> auto_d_min(1 / 50)
    0.04
    >>> auto_d_min(0.002, 0.003)
    0.004
    """
    return float(min(max(2.0 * spacing, error_threshold), 0.2))


def polish_kind(fold: float, polish: str, stacklevel: int = 3) -> str:
    """Return the polish to run: ``polish``, or ``"none"`` when most points fold over.

    On a surface that is not a height field (a closed mesh, a sphere: front and back at
    one x, y) the polish's least squares fit both sides at once: the normal equations
    are so ill-conditioned that conjugate gradients take minutes where a range scan
    takes a second, to no gain. Above :data:`FOLD_NO_POLISH` the polish is skipped, with
    a :class:`~asrbf_mesh._frame.HeightFieldWarning`.
    """
    if polish == "none" or fold <= FOLD_NO_POLISH:
        return polish
    warnings.warn(f"most points ({100 * fold:.0f}%) lie on folds, so the {polish!r} polish is "
                  "skipped (on a surface that is not a height field it barely converges); fit "
                  "a range scan, or choose the depth direction with --view-axis",
                  HeightFieldWarning, stacklevel=stacklevel)
    return "none"


def _pow2_at_most(v: float) -> int:
    return 1 << max(0, int(math.floor(math.log2(max(v, 1.0)))))


class _State:
    """All arrays of the learning kernel; grows its per-slot arrays on demand."""

    def __init__(self, cfg: FitConfig, d_min: float, n_points: int, total_steps: int,
                 window: int, prune_window: int) -> None:
        self.cf = np.zeros(_lk.CF_SIZE)
        self.ci = np.zeros(_lk.CI_SIZE, dtype=np.int64)
        cf, ci = self.cf, self.ci
        cf[_lk.CF_E] = cfg.error_threshold
        cf[_lk.CF_EW] = cfg.rms_threshold
        cf[_lk.CF_DMAX] = cfg.d_max
        cf[_lk.CF_DMIN] = d_min
        cf[_lk.CF_GAMMA] = cfg.gamma
        if cfg.decay == "pass":  # D_min after decay_fraction of the first pass
            steps = max(cfg.decay_fraction * n_points, 1.0)
            cf[_lk.CF_GAMMA] = min(d_min / cfg.d_max, 1.0) ** (1.0 / steps)
        cf[_lk.CF_PSI] = cfg.psi
        cf[_lk.CF_PRUNE] = cfg.prune_threshold
        cf[_lk.CF_R] = cfg.measurement_noise
        cf[_lk.CF_Q] = cfg.process_noise
        cf[_lk.CF_P0] = cfg.prior_variance
        cf[_lk.CF_SUPPORT] = cfg.support
        cf[_lk.CF_NBR] = cfg.neighbourhood_factor
        cf[_lk.CF_GD] = cfg.gd_rate
        cf[_lk.CF_SMIN], cf[_lk.CF_SMAX] = _SIGMA_RANGE
        cf[_lk.CF_BOXLO], cf[_lk.CF_BOXHI] = _CENTRE_BOX
        cf[_lk.CF_LOCAL] = cfg.local_width or 0.0  # None: off (the paper's step)
        ci[_lk.CI_WINDOW] = window
        ci[_lk.CI_PWIN] = prune_window
        ci[_lk.CI_PRUNE] = ("none", "literal", "support").index(cfg.pruning)
        ci[_lk.CI_UPDATE] = ("nekf", "nekf-neighbourhood", "gekf", "gd").index(cfg.update)
        ci[_lk.CI_DECAY] = _lk.DECAY_NEURONS if cfg.decay == "neurons" else _lk.DECAY_OBSERVATION
        ci[_lk.CI_MAXNB] = cfg.max_neighbours
        ci[_lk.CI_MAXK] = cfg.max_neurons if cfg.max_neurons is not None else 2**62
        ci[_lk.CI_LOGSTRIDE] = max(1, total_steps // _LOG_POINTS)
        box = _CENTRE_BOX[1] - _CENTRE_BOX[0]
        ci[_lk.CI_GC] = int(min(max(box / d_min, 8), 1024))
        g0 = _pow2_at_most(min(1.0 / (cfg.support * cfg.psi * d_min), 1024))
        ci[_lk.CI_G0] = g0
        ci[_lk.CI_NLEV] = int(math.log2(g0)) + 1

        self.fs = np.zeros(_lk.FS_SIZE)
        self.fs[_lk.FS_P00] = cfg.prior_variance
        self.st = np.zeros(_lk.ST_SIZE, dtype=np.int64)
        gc = int(ci[_lk.CI_GC])
        self.c_head = np.full(gc * gc, -1, dtype=np.int64)
        sizes = [(g0 >> lev) ** 2 for lev in range(int(ci[_lk.CI_NLEV]))]
        self.lev_off = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
        self.l_head = np.full(int(self.lev_off[-1]), -1, dtype=np.int64)
        self.lev_count = np.zeros(len(sizes), dtype=np.int64)
        self.wbuf = np.zeros(window)
        n_log = total_steps // int(ci[_lk.CI_LOGSTRIDE]) + 2
        self.log_t = np.zeros(n_log, dtype=np.int64)
        self.log_k = np.zeros(n_log, dtype=np.int64)
        self.log_rms = np.zeros(n_log)
        self.log_sig = np.zeros(n_log)
        self.log_amp = np.zeros(n_log)
        self.gekf = cfg.update == "gekf"
        self.cap = 0
        self._alloc(min(256, _GEKF_MAX) if self.gekf else _SLOTS)

    # per-slot arrays and their fill values
    _SLOT = {"W": (np.float64, (4,), 0.0), "P": (np.float64, (4, 4), 0.0),
             "alive": (np.int8, (), 0), "gen": (np.int64, (), 0), "free": (np.int64, (), 0),
             "last_active": (np.int64, (), 0), "miss": (np.int64, (), 0),
             "hk": (np.int64, (), 0), "hs": (np.int64, (), 0), "hg": (np.int64, (), 0),
             "c_nxt": (np.int64, (), -1), "c_prv": (np.int64, (), -1),
             "c_cell": (np.int64, (), -1), "l_nxt": (np.int64, (), -1),
             "l_prv": (np.int64, (), -1), "l_cell": (np.int64, (), -1),
             "l_lev": (np.int64, (), 0)}

    def _alloc(self, cap: int) -> None:
        old = self.cap
        for name, (dt, tail, fill) in self._SLOT.items():
            arr = np.full((cap, *tail), fill, dtype=dt)
            if old:
                arr[:old] = getattr(self, name)
            setattr(self, name, arr)
        if self.gekf:
            n = 1 + 4 * cap
            pg = np.zeros((n, n))
            if old:
                m = 1 + 4 * old
                pg[:m, :m] = self.Pg
            else:
                pg[0, 0] = self.cf[_lk.CF_P0]
            self.Pg = pg
        else:
            self.Pg = np.zeros((1, 1))
        self.cap = cap

    def run(self, X: np.ndarray, Z: np.ndarray, order: np.ndarray, t_end: int) -> None:
        pos = 0
        # the kernel compiled for this updater, pruning rule and decay only
        kernel = _lk.run_steps_for(self.ci[_lk.CI_UPDATE], self.ci[_lk.CI_PRUNE],
                                   self.ci[_lk.CI_DECAY])
        while True:
            status, pos = kernel(
                X, Z, order, t_end, self.cf, self.ci, self.fs, self.st, self.W, self.P,
                self.alive, self.gen, self.free, self.last_active, self.miss, self.hk, self.hs,
                self.hg, self.c_head, self.c_nxt, self.c_prv, self.c_cell, self.l_head,
                self.l_nxt, self.l_prv, self.l_cell, self.l_lev, self.lev_off, self.lev_count,
                self.wbuf, self.Pg, self.log_t, self.log_k, self.log_rms, self.log_sig,
                self.log_amp, pos)
            if status == _lk.DONE:
                return
            if status == _lk.NEED_SLOTS:
                if self.gekf and self.cap >= _GEKF_MAX:
                    raise FitError(
                        f"the GEKF updater holds a full covariance and is limited to "
                        f"{_GEKF_MAX} neurons; this fit needs more (use update='nekf' or a "
                        "subsample)")
                self._alloc(min(2 * self.cap, _GEKF_MAX) if self.gekf else 2 * self.cap)
            else:  # NEED_LOG: cannot happen with the precomputed size; be safe
                for name in ("log_t", "log_k", "log_rms", "log_sig", "log_amp"):
                    arr = getattr(self, name)
                    setattr(self, name, np.concatenate([arr, np.zeros_like(arr)]))


@dataclass(frozen=True)
class LearnedState:
    """Raw outcome of sequential learning, in the unit cube (before any polish)."""

    a0: float
    centers: np.ndarray
    widths: np.ndarray
    weights: np.ndarray
    log: FitLog
    d_min: float
    steps: int
    seconds: float


def learn(hf: HeightField, config: FitConfig | None = None, *, seed: int = 0,
          progress: bool | None = None,
          order: Callable[[np.random.Generator], np.ndarray] | None = None) -> LearnedState:
    """Run adaptive sequential learning (Algorithm 1) on a height field.

    Parameters
    ----------
    hf : HeightField
        Points in the unit cube.
    config : FitConfig, optional
        Learning parameters (paper defaults when omitted).
    seed : int
        Seeds the random replay order; the same seed gives the same network, bit
        for bit.
    progress : bool, optional
        Progress bar on stderr (default: when stderr is a terminal and the fit
        takes more than a second).
    order : callable, optional
        ``order(rng)`` returns the replay order of one pass (a permutation of the N
        points), drawn from the seeded generator; default ``rng.permutation(N)``.
        The streaming fit's block order (:func:`asrbf_mesh._stream.block_order`)
        given here reproduces a streaming fit in memory.

    Returns
    -------
    LearnedState

    Raises
    ------
    ScanError
        Fewer than :data:`MIN_POINTS` points.

    Notes
    -----
    A flat scan (every residual within E of the bias) gives a network with no
    neuron, only the bias a0: a valid result.
    """
    seed = check_seed(seed)
    cfg = config or FitConfig()
    n = hf.n_points
    if n < MIN_POINTS:
        raise ScanError(f"a fit needs at least {MIN_POINTS} points, got {n}")
    d_min = cfg.d_min if cfg.d_min is not None else auto_d_min(hf.spacing, cfg.error_threshold)
    X = np.ascontiguousarray(hf.xy, dtype=np.float64)
    Z = np.ascontiguousarray(hf.z, dtype=np.float64)
    rng = np.random.default_rng(seed)

    def passes() -> Iterator[tuple[np.ndarray, np.ndarray, np.ndarray]]:
        for _ in range(cfg.passes):
            perm = rng.permutation(n) if order is None else order(rng)
            yield X, Z, np.asarray(perm, dtype=np.int64)

    return learn_from(passes(), n, cfg, d_min, progress=progress)


_WARM: set[tuple[str, str, str]] = set()


def _warm_up(cfg: FitConfig, d_min: float) -> None:
    """Compile (or load from numba's cache) the learning kernel once per process.

    One observation is learned by a throw-away state, so that the learning time and the
    microseconds per step of a fit never include the compilation (the first fit after an
    install compiled for about 12 s).
    """
    # one kernel per updater, pruning rule and decay (run_steps_for): each is warmed once
    key = (cfg.update, cfg.pruning, cfg.decay)
    if key in _WARM:
        return
    state = _State(cfg, d_min, 1, 1, cfg.window, cfg.prune_window or cfg.window)
    state.run(np.full((1, 2), 0.5), np.zeros(1), np.zeros(1, dtype=np.int64), 1)
    _WARM.add(key)


def learn_from(batches: Iterable[tuple[np.ndarray, np.ndarray, np.ndarray]], n: int,
               config: FitConfig, d_min: float, *,
               progress: bool | None = None) -> LearnedState:
    """Run sequential learning on observations fed in batches (the core of :func:`learn`).

    Parameters
    ----------
    batches : iterable of (X, Z, order)
        Unit-square inputs (M, 2), unit depths (M,) and the indices of the points to
        learn from, in that order; ``n * config.passes`` indices over all batches.
        :func:`learn` feeds the whole height field once per pass; the streaming fit
        (:mod:`asrbf_mesh._stream`) feeds blocks read from disk.
    n : int
        Points in the scan (sizes the window of the growth criteria and the log).
    config : FitConfig
    d_min : float
        The neuron separation floor D_min, unit square.
    progress : bool, optional
        Progress bar on stderr.

    Returns
    -------
    LearnedState
    """
    cfg = config
    d_min = min(d_min, cfg.d_max)
    total = n * cfg.passes
    window = cfg.window
    prune_window = cfg.prune_window or cfg.window
    _warm_up(cfg, d_min)
    state = _State(cfg, d_min, n, total, window, prune_window)
    tick = _validate.progress(total, progress, "learning", unit="step")
    t0 = time.perf_counter()
    visit = np.arange(_CHUNK, dtype=np.int64)
    for X, Z, order in batches:
        for start in range(0, len(order), _CHUNK):
            chunk = order[start:start + _CHUNK]
            # the chunk's observations gathered in visiting order: the kernel reads them
            # one after another instead of at random (2-3 % faster on the face map); the
            # same steps bit for bit
            state.run(X[chunk], Z[chunk], visit[:len(chunk)],
                      int(state.st[_lk.ST_T]) + len(chunk))
            if tick:
                tick(len(chunk))
    seconds = time.perf_counter() - t0
    st = state.st
    alive = np.flatnonzero(state.alive[: st[_lk.ST_SLOTS]])  # may be empty: a flat scan
    nl = int(st[_lk.ST_NLOG])
    log = FitLog(state.log_t[:nl].copy(), state.log_k[:nl].copy(), state.log_rms[:nl].copy(),
                 state.log_sig[:nl].copy(), state.log_amp[:nl].copy(),
                 added=int(st[_lk.ST_ADDED]), pruned=int(st[_lk.ST_PRUNED]),
                 reset=int(st[_lk.ST_RESET]), diverged=int(st[_lk.ST_DIVERGED]),
                 capped=int(st[_lk.ST_CAPPED]))
    if log.capped:
        warnings.warn(
            f"the neuron cap stopped growth at K = {cfg.max_neurons}: {log.capped:,} "
            "insertions the novelty criteria asked for were refused, so the fit is coarser "
            "than the data allow (raise max_neurons / --max-neurons for more detail)",
            NeuronCapWarning, stacklevel=3)
    W = state.W[alive]
    return LearnedState(float(state.fs[_lk.FS_A0]), W[:, 2:4].copy(), W[:, 1].copy(),
                        W[:, 0].copy(), log, float(d_min), int(st[_lk.ST_T]), seconds)


def source_hash(points: np.ndarray) -> str:
    """SHA-256 of the point coordinates (provenance of a network)."""
    return hashlib.sha256(np.ascontiguousarray(points, dtype=np.float64).tobytes()).hexdigest()


def fit_info(n_points: int, net: Network, source: str | None, sha256: str, seed: int,
             spacing: float, learned: LearnedState, polished: Any, ebar: float,
             error_mean: float, error_std: float, polish_seconds: float, fit_seconds: float,
             **stream: Any) -> FitInfo:
    """Build the :class:`FitInfo` of a fit, in memory or streamed (``stream``: its fields).

    ``polished`` is the polish's result (its ``ebar_before`` is E-bar before the polish)
    or None.
    """
    return FitInfo(
        n_points=n_points, n_neurons=net.n_neurons, source=source, source_sha256=sha256,
        seed=seed, spacing=spacing, d_min=learned.d_min, steps=learned.steps, ebar=ebar,
        ebar_sequential=polished.ebar_before if polished is not None else ebar,
        error_mean=error_mean, error_std=error_std, learn_seconds=learned.seconds,
        polish_seconds=polish_seconds, fit_seconds=fit_seconds,
        us_per_step=1e6 * learned.seconds / max(learned.steps, 1), version=__version__,
        **stream)


def residuals(net: Network, hf: HeightField) -> np.ndarray:
    """Unit-cube residuals ``z_n - f(x_n)`` of a network on a height field, (N,)."""
    return hf.z - net.evaluate(hf.xy, unit=True)


def learn_polished(hf: HeightField, cfg: FitConfig, polish: str, *, seed: int,
                   progress: bool | None = None,
                   order: Callable[[np.random.Generator], np.ndarray] | None = None,
                   prune_below: float = 0.0, keep_residual: bool = False
                   ) -> tuple[LearnedState, Any, tuple, float]:
    """Learn a height field, then run ``polish`` (``"weights"``, ``"full"`` or ``"none"``).

    With a polish, ``prune_below`` > 0 first drops the learned neurons whose |weight| is
    under it (the default model's refinement, :mod:`asrbf_mesh._pieces`); the polish's
    ``ebar_before`` stays the learned network's E-bar. ``keep_residual``: the weight
    polish keeps its network's residual (the tail refinement starts from it).

    The learning and batch stage of :func:`fit`, shared with the piecewise fit
    (:mod:`asrbf_mesh._pieces`). Returns the learned state, the polish's result (None
    for ``"none"``), the final ``(a0, centers, widths, weights)`` in the unit cube and
    the polish's seconds.
    """
    from ._polish import polish_full, polish_weights

    learned = learn(hf, cfg, seed=seed, progress=progress, order=order)
    a0, centers, widths, weights = learned.a0, learned.centers, learned.widths, learned.weights
    tp = time.perf_counter()
    sequential = None  # E-bar of the learned network, when the polish starts from another
    if prune_below > 0 and polish != "none":
        strong = np.abs(weights) >= prune_below
        if strong.any() and not strong.all():
            from ._piece import Piece

            f = Piece(a0, centers, widths, weights).eval_unit(hf.xy, cfg.support)[0]
            sequential = float(np.abs(hf.z - f).mean())
            centers, widths, weights = centers[strong], widths[strong], weights[strong]
    if polish == "weights":  # (the tail refinement after it starts from its residual)
        pr = polish_weights(hf.xy, hf.z, a0, centers, widths, weights, cfg.support,
                            cfg.polish_ridge, keep_residual=keep_residual)
    elif polish == "full":
        pr = polish_full(hf.xy, hf.z, a0, centers, widths, weights, cfg.support,
                         iterations=cfg.polish_iterations, ridge=cfg.polish_ridge)
    else:
        pr = None
    if pr is not None:
        a0, centers, widths, weights = pr.a0, pr.centers, pr.widths, pr.weights
        if sequential is not None:  # before the polish: the learned network, all of it
            pr = replace(pr, ebar_before=sequential)
    return learned, pr, (a0, centers, widths, weights), time.perf_counter() - tp
