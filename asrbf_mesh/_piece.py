"""One piece's Gaussian RBF network: parameters, learning log and fast evaluation.

``f(u) = a0 + sum_k a_k exp(-||u - c_k||^2 / sigma_k^2)`` (paper, eqs. 1-2), in the unit
cube; :class:`~asrbf_mesh.Network` holds one :class:`Piece` per smooth piece of a scan.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from . import _network_kernels as _nk
from .errors import ConfigError

__all__ = ["Piece", "FitLog", "eval_grid", "eval_unit"]


def eval_grid(centers: np.ndarray, widths: np.ndarray, weights: np.ndarray,
              support: float) -> tuple:
    """Build the static evaluation grid ``(support, lo, h, g, start, items, pstart, packed)``.

    Cells are about the size of a median truncated support (at most 512 per axis)
    over the unit square extended to every centre.
    """
    if len(widths):
        lo = np.minimum(centers.min(axis=0), 0.0)
        hi = np.maximum(centers.max(axis=0), 1.0)
        cell = max(float(np.median(widths)) * support, float((hi - lo).max()) / 512)
    else:
        lo, hi, cell = np.zeros(2), np.ones(2), 1.0
    g = max(1, int(np.ceil(float((hi - lo).max()) / cell)))
    h = float((hi - lo).max()) / g
    lo = np.ascontiguousarray(lo, dtype=np.float64)
    # read-only views whatever the caller holds: one compiled version of each kernel
    centers, widths, weights = _read_only(centers), _read_only(widths), _read_only(weights)
    start, items = _nk.build_grid(centers, widths, support, lo, h, g)
    pstart, packed = _nk.pack_cells(centers, widths, weights, start, items)
    return support, lo, h, g, start, items, pstart, packed


def eval_unit(grid: tuple, uv: np.ndarray, a0: float, centers: np.ndarray, widths: np.ndarray,
              weights: np.ndarray, want_grad: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Evaluate f (and optionally its gradient) at unit-square points through a grid."""
    s, lo, h, g, start, items, pstart, packed = grid
    uv = np.ascontiguousarray(uv, dtype=np.float64)
    if not want_grad:
        return _nk.evaluate_values(uv, a0, packed, pstart, s, lo, h, g), np.zeros((0, 2))
    return _nk.evaluate_with_gradient(uv, a0, _read_only(centers), _read_only(widths),
                                      _read_only(weights), s, lo, h, g, start, items)


def _read_only(a: np.ndarray) -> np.ndarray:
    """Return a read-only view of float64 array ``a`` (numba compiles per writeability)."""
    v = np.ascontiguousarray(a, dtype=np.float64).view()
    v.flags.writeable = False
    return v


#: The square of a width must exceed this (1e-300): evaluation divides by it.
_WIDTH2_MIN = 1e-300


@dataclass(frozen=True, eq=False)
class FitLog:
    """Learning history sampled at a fixed stride (paper, Figs. 6 and 9).

    Parameters
    ----------
    step : (L,) int64 array
        Observation index n of each record.
    n_neurons : (L,) int64 array
        K at that step.
    rms : (L,) float64 array
        Windowed RMS error e_n^omega (eq. 6), unit cube.
    mean_width, mean_weight : (L,) float64 arrays
        Mean sigma and mean |a| over the alive neurons (0 while there is none).
    added, pruned, reset, diverged : int
        Neurons added, pruned, covariance blocks reset and neurons removed by the
        numerical guard over the whole run.
    capped : int
        Insertions the neuron cap (``FitConfig.max_neurons``) refused: the three novelty
        criteria held but K was at the cap.
    """

    step: np.ndarray
    n_neurons: np.ndarray
    rms: np.ndarray
    mean_width: np.ndarray
    mean_weight: np.ndarray
    added: int = 0
    pruned: int = 0
    reset: int = 0
    diverged: int = 0
    capped: int = 0

    _ARRAYS = ("step", "n_neurons", "rms", "mean_width", "mean_weight")

    def counters(self) -> dict[str, int]:
        """Return the scalar counters as a dict."""
        return {"added": self.added, "pruned": self.pruned, "reset": self.reset,
                "diverged": self.diverged, "capped": self.capped}


@dataclass(frozen=True, eq=False)
class Piece:
    """The Gaussian RBF network of one smooth piece of a scan, in the unit cube.

    ``f(u) = a0 + sum_k a_k exp(-||u - c_k||^2 / sigma_k^2)``. A piece without neurons
    (K = 0: a small fragment, a flat scan) is the constant ``a0``.

    Parameters
    ----------
    a0 : float
        Bias, unit depth.
    centers : (K, 2) float64 array
        Neuron centres in the unit square.
    widths : (K,) float64 array
        Widths sigma_k (> 0), unit square.
    weights : (K,) float64 array
        Weights a_k, unit depth.
    log : FitLog, optional
        The piece's learning history.
    info : dict
        The piece's own figures (JSON-serializable): ``n_points``, ``seed``, ``ebar``,
        ``constant`` (no learning: too few points).
    """

    a0: float
    centers: np.ndarray
    widths: np.ndarray
    weights: np.ndarray
    log: FitLog | None = None
    info: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        try:
            c = np.array(self.centers, dtype=np.float64)
            w = np.array(self.widths, dtype=np.float64).reshape(-1)
            a = np.array(self.weights, dtype=np.float64).reshape(-1)
            a0 = float(self.a0)
        except (TypeError, ValueError):
            raise ConfigError("a0, centers, widths and weights must be numbers") from None
        if c.size == 0:
            c = c.reshape(0, 2)
        if c.ndim != 2 or c.shape[1] != 2:
            raise ConfigError(f"centers must have shape (K, 2), got {c.shape}")
        k = len(c)
        if len(w) != k or len(a) != k:
            raise ConfigError(f"centers ({k}), widths ({len(w)}) and weights ({len(a)}) differ")
        if not (np.all(np.isfinite(c)) and np.all(np.isfinite(w)) and np.all(np.isfinite(a))
                and np.isfinite(a0)):
            raise ConfigError("network parameters must be finite")
        if np.any(w <= 0) or np.any(w * w <= _WIDTH2_MIN):
            # a width whose square underflows would divide by zero in evaluation
            raise ConfigError("widths must be positive (and above 1e-150)")
        if self.log is not None and not isinstance(self.log, FitLog):
            raise ConfigError(f"log must be a FitLog or None, got {type(self.log).__name__}")
        if not isinstance(self.info, dict):
            raise ConfigError(f"info must be a dict, got {type(self.info).__name__}")
        for name, arr in (("centers", c), ("widths", w), ("weights", a)):
            arr.flags.writeable = False
            object.__setattr__(self, name, arr)
        object.__setattr__(self, "a0", a0)

    def __getstate__(self) -> dict[str, Any]:
        state = dict(self.__dict__)
        state.pop("_grid", None)  # the evaluation grid is rebuilt on demand
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)

    @property
    def n_neurons(self) -> int:
        """K, the piece's Gaussian neurons."""
        return int(len(self.widths))

    def eval_unit(self, uv: np.ndarray, support: float,
                  want_grad: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """Evaluate f (and its gradient if ``want_grad``) at (M, 2) unit-square points."""
        grid = self.__dict__.get("_grid")
        if grid is None or grid[0] != support:
            grid = eval_grid(self.centers, self.widths, self.weights, support)
            object.__setattr__(self, "_grid", grid)
        return eval_unit(grid, uv, self.a0, self.centers, self.widths, self.weights, want_grad)
