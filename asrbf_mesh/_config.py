"""Learning parameters of the ASRBF network (:class:`FitConfig`).

Defaults follow section 5.1 of the paper (Meng et al., "Parameterization of
point-cloud freeform surfaces using adaptive sequential learning RBF networks"),
expressed in the unit cube; the places where the paper is silent or where its
rule does not work as written are documented per field and in docs/design.md.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
from dataclasses import dataclass
from typing import Any, Literal

from .errors import ConfigError

__all__ = ["FitConfig", "LOCAL_WIDTH", "UPDATES", "PRUNINGS", "DECAYS", "POLISHES"]

UPDATES = ("nekf", "nekf-neighbourhood", "gekf", "gd")
PRUNINGS = ("none", "literal", "support")
DECAYS = ("observation", "neurons", "pass")
POLISHES = ("none", "weights", "full")
#: Depth directions of a height field (``to_height_field``'s ``view_axis``).
VIEW_AXES = ("z", "x", "y", "pca")
#: How a hole fill carries the scan's residual across the hole.
BLENDS = ("thin-plate", "harmonic")
#: Footprint modes of ``reconstruct``.
FOOTPRINT_MODES = ("scan", "surface", "hull", "full")
#: ``pieces`` of a fit: "auto" (one network per smooth piece) or "1" (one network).
PIECES = ("auto", "1")
#: LOD methods of ``lod_set``.
LOD_METHODS = ("resample", "refit")

Update = Literal["nekf", "nekf-neighbourhood", "gekf", "gd"]
Pruning = Literal["none", "literal", "support"]
Decay = Literal["observation", "neurons", "pass"]
Polish = Literal["none", "weights", "full"]


#: ``FitConfig.local_width`` of the default model. The face map's seed 8 without it: one
#: step of a neuron 0.37 wide (the unit square's), the nearest to a point at the rim with
#: an error of 0.17, moved its centre by 0.15; the windowed RMS error rose from 0.008 to
#: 0.024 and growth added about 800 neurons (the main piece learned 1,379). With 8 it
#: learns 641 there, 444-641 over seeds 0-9 (the largest of ``fit(face, seed=s).pieces``,
#: its ``log.counters()["added"]``); the face map's K over seeds 0-9 715 (worst 1,074) ->
#: 713 (767) (``scripts/bench_pieces.py``; BENCHMARKS, "Piecewise model").
LOCAL_WIDTH = 8.0


@dataclass(frozen=True)
class FitConfig:
    """Parameters of adaptive sequential learning, in the unit cube.

    Parameters
    ----------
    error_threshold : float
        E, criterion 2: a neuron may be added where ``|z - f(x)| > E``.
    rms_threshold : float
        E_omega, criterion 3: growth goes on while the RMS error over the last
        ``window`` observations exceeds it.
    d_max : float
        D_max, the initial neuron separation distance (criterion 1).
    d_min : float or None
        D_min, the final separation ("neuron separation level"). ``None``: twice
        the scan's sampling spacing measured from the data (section 5.1), but not
        below E (see :func:`asrbf_mesh._learn.auto_d_min`).
    gamma : float
        Decay factor of the separation distance, eq. (4).
    decay : {"observation", "neurons", "pass"}
        What eq. (4) is indexed by. ``"neurons"`` is the paper's text
        (``D_K = max(D_max gamma^K, D_min)``); it stalls at about a dozen neurons,
        because a dozen spread neurons cover the unit square closer than ``D_K``.
        ``"observation"`` (default) decays with the observation index as in the
        RAN/MRAN networks the method builds on, which gives the paper's results.
        ``"pass"`` also decays with the observation index, but reaches D_min after
        ``decay_fraction`` of the first pass over the N points, whatever N (gamma is
        then ``(D_min / D_max) ** (1 / (decay_fraction N))``, ``gamma`` unused): the
        wide-to-narrow phase lasts that share of the data, where ``gamma = 0.99``
        reaches D_min after a few hundred observations on any scan.
    decay_fraction : float
        Share of the first pass after which ``decay="pass"`` reaches D_min; in (0, 1].
    psi : float
        Overlap factor: a new neuron's width is ``psi`` times the distance to the
        nearest neuron, eq. (7). 0.7 for detailed scans, 0.8 for smooth objects.
    window : int
        omega, the RMS window of criterion 3.
    prune_threshold : float
        P, the contribution-ratio threshold of pruning, eqs. (11)-(13).
    pruning : {"literal", "support", "none"}
        ``"literal"``: the paper's rule, a neuron whose ratio stays below P for
        ``prune_window`` consecutive observations is removed. ``"support"``: only
        observations inside the neuron's truncated support count. ``"none"``.
    prune_window : int or None
        Observations counted by pruning; ``None`` means ``window`` (the paper).
    passes : int
        How many times the data is replayed, each time in a new random order.
    update : {"nekf", "nekf-neighbourhood", "gekf", "gd"}
        Parameter updater. ``"nekf"``: the nearest neuron (K' = 1) and a0, the
        paper's experiments. ``"nekf-neighbourhood"``: every neuron within
        ``neighbourhood_factor * D`` of the input. ``"gekf"``: one covariance over
        all parameters, O((4K)^2) per step, for small problems. ``"gd"``: gradient
        descent with rate ``gd_rate``.
    neighbourhood_factor, max_neighbours
        Radius (in units of the current separation D) and cap of the NEKF
        neighbourhood.
    measurement_noise : float
        R, the EKF measurement noise variance.
    process_noise : float
        q, the EKF process noise, relative to the prior (P0 and Q are
        ``diag(1, 1, sigma^2, sigma^2)`` per neuron, for ``(a, log sigma, u)``).
    prior_variance : float
        Scale of P0.
    gd_rate : float
        Step size of the ``"gd"`` updater.
    support : float
        Gaussians are truncated at ``support * sigma`` (exp(-12.25) = 5e-6 of
        their peak at the default 3.5), in learning and in evaluation alike.
    max_neurons : int or None
        Hard cap on K (growth stops, learning goes on).
    polish : {"none", "weights", "full"}
        Batch stage after learning: sparse least squares of the weights with
        centres and widths fixed, or Levenberg-Marquardt over all parameters.
        ``"none"`` is the paper's method.
    polish_iterations : int
        Levenberg-Marquardt iterations of ``polish="full"``.
    polish_ridge : float
        Tikhonov weight pulling polished parameters toward the learned ones,
        relative to the mean diagonal of the normal equations; keeps neurons
        with little data under them (holes, borders) where learning left them.
    local_width : float or None
        Keeps an NEKF step local. One observation speaks for its neighbourhood, about
        the current separation D across, but its nearest neuron may be far wider (an
        early wide neuron at the rim, beside later narrow ones), and a full step there
        reshapes the surface over its whole width. A neuron wider than
        ``local_width * D`` takes the step scaled by ``local_width * D / sigma``.
        ``None`` (default): :data:`LOCAL_WIDTH` for the pieces of the default model
        (``fit(pieces="auto")`` on a scan cut in several), off wherever one network
        learns (``pieces=1``, a scan of one piece, :func:`~asrbf_mesh.learn`, the
        streaming fit); 0: off. See
        docs/design.md, "A local NEKF step".
    """

    error_threshold: float = 0.01
    rms_threshold: float = 0.01
    d_max: float = 0.4
    d_min: float | None = None
    gamma: float = 0.99
    decay: Decay = "observation"
    decay_fraction: float = 0.1
    psi: float = 0.7
    window: int = 1000
    prune_threshold: float = 0.001
    pruning: Pruning = "support"
    prune_window: int | None = None
    passes: int = 2
    update: Update = "nekf"
    neighbourhood_factor: float = 1.5
    max_neighbours: int = 8
    measurement_noise: float = 0.01
    process_noise: float = 3e-5
    prior_variance: float = 1.0
    gd_rate: float = 0.05
    support: float = 3.5
    max_neurons: int | None = None
    polish: Polish = "weights"
    polish_iterations: int = 4
    polish_ridge: float = 1e-4
    local_width: float | None = None

    def __post_init__(self) -> None:
        def check(name: str, test: Any, want: str, optional: bool) -> None:
            v = getattr(self, name)
            if v is None and optional:
                return
            ok, v = test(v)
            if not ok:
                raise ConfigError(f"{name} must be {want}, got {v!r}")
            object.__setattr__(self, name, v)

        def real(name: str, *, lo: float = 0.0, lo_open: bool = True, hi: float = math.inf,
                 hi_open: bool = True, optional: bool = False) -> None:
            if math.isinf(hi):
                want = "a positive finite number" if lo_open else f"a finite number >= {lo:g}"
            else:
                want = (f"a number in {'(' if lo_open else '['}{lo:g}, {hi:g}"
                        f"{')' if hi_open else ']'}")

            def test(v: Any) -> tuple[bool, Any]:
                ok = isinstance(v, numbers.Real) and not isinstance(v, bool) and math.isfinite(v)
                if ok:
                    v = float(v)
                    ok = (v > lo if lo_open else v >= lo) and (v < hi if hi_open else v <= hi)
                return ok, v

            check(name, test, want, optional)

        def integer(name: str, *, lo: int, optional: bool = False) -> None:
            def test(v: Any) -> tuple[bool, Any]:
                ok = isinstance(v, numbers.Integral) and not isinstance(v, bool) and v >= lo
                return ok, int(v) if ok else v

            check(name, test, f"an integer >= {lo}{' or None' if optional else ''}", optional)

        for name in ("error_threshold", "rms_threshold", "d_max", "measurement_noise",
                     "prior_variance", "gd_rate", "support", "neighbourhood_factor"):
            real(name)
        real("d_min", optional=True)
        real("gamma", hi=1.0)
        real("decay_fraction", hi=1.0, hi_open=False)
        real("psi", hi=1.0, hi_open=False)
        real("prune_threshold", lo_open=False, hi=1.0)
        real("process_noise", lo_open=False)
        real("polish_ridge", lo_open=False)
        real("local_width", lo_open=False, optional=True)
        if self.d_min is not None and self.d_min > self.d_max:
            raise ConfigError(f"d_min ({self.d_min}) must not exceed d_max ({self.d_max})")
        for name in ("window", "passes", "max_neighbours"):
            integer(name, lo=1)
        for name in ("prune_window", "max_neurons"):
            integer(name, lo=1, optional=True)
        integer("polish_iterations", lo=0)
        for name, allowed in (("update", UPDATES), ("pruning", PRUNINGS), ("decay", DECAYS),
                              ("polish", POLISHES)):
            v = getattr(self, name)
            if v not in allowed:
                raise ConfigError(f"{name} must be one of {', '.join(allowed)}; got {v!r}")

    def replace(self, **changes: Any) -> FitConfig:
        """Return a copy with some fields changed (validated)."""
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict[str, Any]:
        """Plain-JSON form (stored in ``.asrbf`` files)."""
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> FitConfig:
        """Inverse of :meth:`to_dict`; unknown keys raise :class:`ConfigError`."""
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(data) - names)
        if unknown:
            raise ConfigError(f"unknown FitConfig field(s): {', '.join(unknown)}")
        return cls(**data)
