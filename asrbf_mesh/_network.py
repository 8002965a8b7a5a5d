"""The fitted model of a scan: one Gaussian RBF network per smooth piece, in one frame.

Each piece is ``f(x) = a0 + sum_k a_k exp(-||x - u_k||^2 / sigma_k^2)`` (paper, eqs. 1-2),
learned in the unit square (:class:`~asrbf_mesh._piece.Piece`); :class:`Network` finds
the piece owning a point (:class:`~asrbf_mesh._piece_map.PieceMap`) and evaluates it in
physical units through its :class:`~asrbf_mesh._frame.Frame`. A single network is a
one-piece model.
"""

from __future__ import annotations

import dataclasses
import os
from dataclasses import MISSING, dataclass, fields
from pathlib import Path
from typing import Any

import numpy as np

from ._config import FitConfig
from ._frame import Frame
from ._network_file import FORMAT_NAME, FORMAT_VERSION, VOLATILE_INFO, read_network, write_network
from ._piece import FitLog, Piece, eval_grid, eval_unit
from ._piece_map import PieceMap
from ._validate import check_float, check_int, plural, readonly
from .errors import ConfigError, NetworkFileError, ScanError

__all__ = ["Network", "Piece", "FitInfo", "FitLog", "NeuronStats", "FORMAT_NAME",
           "FORMAT_VERSION", "eval_grid", "eval_unit"]


@dataclass(frozen=True)
class FitInfo:
    """The figures of a fit (:func:`asrbf_mesh.fit`, :func:`asrbf_mesh.fit_stream`), typed.

    ``Network.info`` keeps them as the plain dict the ``.asrbf`` file stores
    (:meth:`to_dict`); ``Network.fit_info`` gives them back as this record.

    Parameters
    ----------
    n_points, n_neurons : int
        N points learned from and K neurons of the network.
    source : str or None
        The scan file (None for points given in memory).
    source_sha256 : str
        SHA-256 of the point coordinates (float64).
    seed : int
        Seed of the replay order.
    spacing : float
        Sampling spacing, unit square.
    d_min : float
        D_min used, unit square.
    steps : int
        Learning steps (observations replayed).
    ebar : float
        Mean |f - z| in the unit cube after the polish.
    ebar_sequential : float
        The same before the polish (equal to ``ebar`` without a polish).
    error_mean, error_std : float
        Mean and standard deviation of |depth error|, scan units.
    learn_seconds, polish_seconds, fit_seconds, us_per_step : float or None
        Wall-clock figures; None for a network read from a file (they are not stored,
        so that the same seed gives the same file).
    compile_seconds : float or None
        Of ``fit_seconds``, the time spent compiling kernels (the first fit on a machine;
        0 once they are cached); None where not measured.
    version : str
        asrbf-mesh version that fitted the network.
    streamed : bool
        Fitted by :func:`asrbf_mesh.fit_stream`.
    chunk, mix : int or None
        The streaming fit's block size and group size.
    spacing_exact : bool or None
        Streaming fit: False when the spacing came from a sample of tiles.
    outliers : int or None
        Isolated points left out of the frame and the fit (``n_points`` counts the others);
        None (and absent from ``info``) when there were none.
    n_pieces : int
        Pieces of the model (1: a single network; a streamed fit is always one piece).
    """

    n_points: int
    n_neurons: int
    source: str | None
    source_sha256: str
    seed: int
    spacing: float
    d_min: float
    steps: int
    ebar: float
    ebar_sequential: float
    error_mean: float
    error_std: float
    learn_seconds: float | None = None
    polish_seconds: float | None = None
    fit_seconds: float | None = None
    us_per_step: float | None = None
    compile_seconds: float | None = None
    version: str = ""
    streamed: bool = False
    chunk: int | None = None
    mix: int | None = None
    spacing_exact: bool | None = None
    outliers: int | None = None
    n_pieces: int = 1
    weak_pruned: int = 0
    tail_neurons: int = 0

    _STREAM = ("streamed", "chunk", "mix", "spacing_exact")

    def to_dict(self) -> dict[str, Any]:
        """Return the ``Network.info`` dict: timings when known, stream fields if streamed."""
        out = {}
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name in self._STREAM and not self.streamed:
                continue
            if (f.name in VOLATILE_INFO or f.name == "outliers") and v is None:
                continue
            out[f.name] = v
        return out

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> FitInfo:
        """Inverse of :meth:`to_dict` (other keys are ignored).

        Raises
        ------
        ConfigError
            A fit figure is missing.
        """
        names = [f.name for f in fields(cls)]
        required = [f.name for f in fields(cls) if f.default is MISSING]
        missing = [n for n in required if n not in data]
        if missing:
            raise ConfigError(f"fit info lacks {', '.join(missing)}")
        return cls(**{n: data[n] for n in names if n in data})


@dataclass(frozen=True)
class NeuronStats:
    """Width and |weight| statistics of a network (the paper's Table 1), unit cube.

    A network without neurons (K = 0, a flat scan: only the bias a0) has no widths and
    no weights: every statistic is None (``null`` in JSON), never NaN.
    """

    n_neurons: int
    width_max: float | None
    width_min: float | None
    width_mean: float | None
    width_std: float | None
    weight_max: float | None
    weight_min: float | None
    weight_mean: float | None
    weight_std: float | None

    def to_dict(self) -> dict[str, Any]:
        """Return the statistics as a plain dict (JSON-ready: no NaN)."""
        return {f.name: getattr(self, f.name) for f in fields(self)}

    def __post_init__(self) -> None:
        check_int(self.n_neurons, "n_neurons", 0)
        for f in fields(self)[1:]:
            if self.n_neurons == 0 and getattr(self, f.name) is None:
                continue
            object.__setattr__(self, f.name, check_float(getattr(self, f.name), f.name,
                                                         low=0.0 if f.name.startswith("width")
                                                         else None))


@dataclass(frozen=True, eq=False, init=False)
class Network:
    """An immutable, picklable Gaussian RBF model of a scan: one network per smooth piece.

    A range scan is piecewise smooth (occlusion cliffs, walls seen edge-on, fragments),
    so a model holds one :class:`Piece` per smooth piece, all in one frame (the whole
    scan's unit cube), and a :class:`~asrbf_mesh._piece_map.PieceMap` telling which piece
    owns each point of the view plane. A single network (the paper's model, ``--pieces
    1``) is a one-piece model without a map: ``Network(a0, centers, widths, weights,
    frame, config)`` builds one; :meth:`from_pieces` builds a piecewise one.

    Evaluation (:meth:`evaluate`, :meth:`gradient`, :meth:`normals`,
    :meth:`surface_points`) takes the piece to use, or finds it from the map.

    Parameters
    ----------
    a0 : float
        Bias, unit cube.
    centers : (K, 2) float64 array
        Neuron centres u_k in the unit square.
    widths : (K,) float64 array
        Widths sigma_k (> 0), unit square.
    weights : (K,) float64 array
        Weights a_k, unit depth.
    frame : Frame
        Map between the unit cube and world units.
    config : FitConfig
        Parameters the network was learned with.
    log : FitLog, optional
        Learning history.
    info : dict
        Provenance and fit figures (JSON-serializable): ``n_points``,
        ``source_sha256``, ``d_min``, ``fit_seconds``, ...

    Examples
    --------
    >>> import numpy as np
    >>> from asrbf_mesh._frame import Frame
    >>> net = Network(0.5, np.array([[0.5, 0.5]]), np.array([0.2]), np.array([0.25]),
    ...               Frame(np.eye(3), np.zeros(3), np.ones(3)), FitConfig())
    >>> float(net.evaluate(np.array([[0.5, 0.5]]))[0])
    0.75
    >>> net.n_pieces
    1
    """

    pieces: tuple[Piece, ...]
    frame: Frame
    config: FitConfig
    info: dict[str, Any]
    piece_map: PieceMap | None

    def __init__(self, a0: float, centers: np.ndarray, widths: np.ndarray, weights: np.ndarray,
                 frame: Frame, config: FitConfig, log: FitLog | None = None,
                 info: dict[str, Any] | None = None) -> None:
        self._assign((Piece(a0, centers, widths, weights, log),), frame, config,
                     {} if info is None else info, None)

    @classmethod
    def from_pieces(cls, pieces: Any, frame: Frame, config: FitConfig,
                    info: dict[str, Any] | None = None,
                    piece_map: PieceMap | None = None) -> Network:
        """Build a model of several pieces (a map is needed to tell them apart).

        Raises
        ------
        ConfigError
            No piece, a piece that is not a :class:`Piece`, or a map missing or naming
            pieces the model lacks.
        """
        pieces = tuple(pieces)
        if not pieces or not all(isinstance(p, Piece) for p in pieces):
            raise ConfigError("pieces must be a non-empty sequence of Piece")
        if len(pieces) > 1 and not isinstance(piece_map, PieceMap):
            raise ConfigError(f"a model of {len(pieces)} pieces needs a PieceMap")
        if piece_map is not None and piece_map.n_pieces > len(pieces):
            raise ConfigError(f"the piece map names piece {piece_map.n_pieces - 1}, the "
                              f"model has {plural(len(pieces), 'piece')}")
        obj = cls.__new__(cls)
        obj._assign(pieces, frame, config, {} if info is None else info,
                    piece_map if len(pieces) > 1 else None)
        return obj

    def _assign(self, pieces: tuple[Piece, ...], frame: Frame, config: FitConfig,
                info: dict[str, Any], piece_map: PieceMap | None) -> None:
        if not isinstance(frame, Frame):
            raise ConfigError(f"frame must be a Frame, got {type(frame).__name__}")
        if not isinstance(config, FitConfig):
            raise ConfigError(f"config must be a FitConfig, got {type(config).__name__}")
        if not isinstance(info, dict):
            raise ConfigError(f"info must be a dict, got {type(info).__name__}")
        for name, value in (("pieces", pieces), ("frame", frame), ("config", config),
                            ("info", info), ("piece_map", piece_map)):
            object.__setattr__(self, name, value)

    # -- pickling: drop cached arrays ------------------------------------------------------
    def __getstate__(self) -> dict[str, Any]:
        return {k: v for k, v in self.__dict__.items() if not k.startswith("_")}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)

    # -- parameters -------------------------------------------------------------------------
    @property
    def n_pieces(self) -> int:
        """Number of pieces (1 for the paper's single network)."""
        return len(self.pieces)

    @property
    def n_neurons(self) -> int:
        """K, the Gaussian neurons of all pieces."""
        return sum(p.n_neurons for p in self.pieces)

    @property
    def a0(self) -> float:
        """The bias of a one-piece network (each piece has its own: ``pieces[i].a0``)."""
        if self.n_pieces > 1:
            raise ConfigError(f"a model of {self.n_pieces} pieces has one a0 per piece: "
                              "use pieces[i].a0")
        return self.pieces[0].a0

    def _joined(self, name: str) -> np.ndarray:
        if self.n_pieces == 1:
            return getattr(self.pieces[0], name)
        key = f"_{name}"
        arr = self.__dict__.get(key)
        if arr is None:
            arr = readonly(np.concatenate([getattr(p, name) for p in self.pieces]))
            object.__setattr__(self, key, arr)
        return arr

    @property
    def centers(self) -> np.ndarray:
        """(K, 2) neuron centres of all pieces, piece after piece (read-only)."""
        return self._joined("centers")

    @property
    def widths(self) -> np.ndarray:
        """(K,) widths of all pieces, piece after piece (read-only)."""
        return self._joined("widths")

    @property
    def weights(self) -> np.ndarray:
        """(K,) weights of all pieces, piece after piece (read-only)."""
        return self._joined("weights")

    @property
    def log(self) -> FitLog | None:
        """The learning history of a one-piece network (pieces: ``pieces[i].log``)."""
        return self.pieces[0].log if self.n_pieces == 1 else None

    def without_logs(self) -> Network:
        """Return the model without the pieces' learning logs (as a LOD set ships it)."""
        pieces = tuple(dataclasses.replace(p, log=None) for p in self.pieces)
        return Network.from_pieces(pieces, self.frame, self.config, self.info, self.piece_map)

    def log_counters(self) -> dict[str, int] | None:
        """Neurons added, pruned, ... summed over the pieces; None without any log."""
        logs = [p.log for p in self.pieces if p.log is not None]
        if not logs:
            return None
        total: dict[str, int] = {}
        for lg in logs:
            for k, v in lg.counters().items():
                total[k] = total.get(k, 0) + v
        return total

    # -- sizes ------------------------------------------------------------------------------
    @property
    def fit_info(self) -> FitInfo | None:
        """The fit figures of ``info`` as a :class:`FitInfo`; None without fit figures."""
        try:
            return FitInfo.from_dict(self.info)
        except (ConfigError, TypeError):
            return None

    def compression_ratio(self, n_points: int | None = None) -> float:
        """N : K, points per neuron over all pieces (paper, Table 2)."""
        n = self._n_points(n_points)
        return n / max(self.n_neurons, 1)

    def storage_ratio(self, n_points: int | None = None) -> float:
        """3N : 4K, storage of N 3D points over K four-parameter neurons (Table 2)."""
        n = self._n_points(n_points)
        return 3.0 * n / (4.0 * max(self.n_neurons, 1))

    def _n_points(self, n_points: int | None) -> int:
        if n_points is not None:
            return int(n_points)
        if "n_points" not in self.info:
            raise ConfigError("n_points is unknown for this network; pass it explicitly")
        return int(self.info["n_points"])

    def stats(self) -> NeuronStats:
        """Width and |weight| statistics over all pieces (the paper's Table 1 reports |a|)."""
        w = self.widths
        a = np.abs(self.weights)
        if self.n_neurons == 0:
            return NeuronStats(0, *[None] * 8)
        return NeuronStats(self.n_neurons, float(w.max()), float(w.min()), float(w.mean()),
                           float(w.std()), float(a.max()), float(a.min()), float(a.mean()),
                           float(a.std()))

    # -- evaluation -------------------------------------------------------------------------
    def piece_at(self, xy: np.ndarray, *, unit: bool = False) -> np.ndarray:
        """Piece owning each (M, 2) point of the view plane, (M,) int64 (see :meth:`evaluate`)."""
        pts = self._points(xy)
        uv = pts if unit else self.frame.xy_to_unit(pts)
        return self._piece_of(uv, None)

    def _piece_of(self, uv: np.ndarray, piece: Any) -> np.ndarray:
        if piece is None:
            if self.piece_map is None:
                return np.zeros(len(uv), dtype=np.int64)
            return self.piece_map.piece_at(uv)
        arr = np.asarray(piece)
        if arr.ndim == 0:
            arr = np.full(len(uv), check_int(piece, "piece", 0, self.n_pieces - 1))
        elif arr.shape != (len(uv),) or arr.dtype.kind not in "iu":
            raise ConfigError(f"piece must be an int or one int per point ({len(uv)}), got "
                              f"an array of shape {arr.shape} and type {arr.dtype}")
        elif len(arr) and (arr.min() < 0 or arr.max() >= self.n_pieces):
            raise ConfigError(f"piece must be in [0, {self.n_pieces - 1}]")
        return arr.astype(np.int64)

    def _eval_unit(self, uv: np.ndarray, want_grad: bool,
                   piece: Any = None) -> tuple[np.ndarray, np.ndarray]:
        uv = np.ascontiguousarray(uv, dtype=np.float64)
        support = self.config.support
        if self.n_pieces == 1 and piece is None:
            return self.pieces[0].eval_unit(uv, support, want_grad)
        owner = self._piece_of(uv, piece)
        f = np.empty(len(uv))
        grad = np.zeros((len(uv) if want_grad else 0, 2))
        order = np.argsort(owner, kind="stable")
        bounds = np.searchsorted(owner[order], np.arange(self.n_pieces + 1))
        for i, p in enumerate(self.pieces):
            idx = order[bounds[i]:bounds[i + 1]]
            if idx.size:
                fi, gi = p.eval_unit(np.ascontiguousarray(uv[idx]), support, want_grad)
                f[idx] = fi
                if want_grad:
                    grad[idx] = gi
        return f, grad

    @staticmethod
    def _points(xy: np.ndarray) -> np.ndarray:
        arr = np.ascontiguousarray(xy, dtype=np.float64)
        if arr.ndim != 2 or arr.shape[1] != 2:
            raise ScanError(f"xy must have shape (M, 2), got {arr.shape}")
        if not np.all(np.isfinite(arr)):
            raise ScanError("xy contains NaN or infinite values")
        return arr

    def evaluate(self, xy: np.ndarray, *, unit: bool = False, piece: Any = None) -> np.ndarray:
        """Depth of the surface at (M, 2) points.

        Parameters
        ----------
        xy : (M, 2) array
            Points in the frame's local physical (x, y) (for view axis ``"z"`` these
            are the world x and y), or in the unit square if ``unit``.
        unit : bool
            Work in the unit cube (inputs and output) instead of physical units.
        piece : int or (M,) int array, optional
            The piece to evaluate (one for all points, or one per point); default the
            piece owning each point (:meth:`piece_at`).

        Returns
        -------
        (M,) float64 array
            Depth in physical units (or unit-cube depth).
        """
        pts = self._points(xy)
        uv = pts if unit else self.frame.xy_to_unit(pts)
        f, _ = self._eval_unit(uv, False, piece)
        if unit:
            return f
        return f * self.frame.scale[2] + self.frame.offset[2]

    def gradient(self, xy: np.ndarray, *, unit: bool = False, piece: Any = None) -> np.ndarray:
        """Analytic gradient d depth / d(x, y), (M, 2), in the units of :meth:`evaluate`."""
        pts = self._points(xy)
        uv = pts if unit else self.frame.xy_to_unit(pts)
        _, grad = self._eval_unit(uv, True, piece)
        if unit:
            return grad
        return grad * (self.frame.scale[2] / self.frame.scale[:2])

    def surface_points(self, xy: np.ndarray, *, unit: bool = False,
                       piece: Any = None) -> np.ndarray:
        """World (M, 3) points of the surface above local (x, y) (or unit-square) points."""
        pts = self._points(xy)
        uv = pts if unit else self.frame.xy_to_unit(pts)
        f, _ = self._eval_unit(uv, False, piece)
        return self.frame.to_world(np.column_stack([uv, f]))

    def normals(self, xy: np.ndarray, *, unit: bool = False, piece: Any = None) -> np.ndarray:
        """Return unit surface normals in world coordinates, (M, 3), facing +depth.

        From the analytic gradient: ``n ~ (-dz/dx, -dz/dy, 1)`` in the local physical
        frame, rotated to world.
        """
        pts = self._points(xy)
        uv = pts if unit else self.frame.xy_to_unit(pts)
        _, grad = self._eval_unit(uv, True, piece)
        gp = grad * (self.frame.scale[2] / self.frame.scale[:2])
        n = np.column_stack([-gp[:, 0], -gp[:, 1], np.ones(len(gp))])
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        return n @ self.frame.rotation.T

    # -- file -------------------------------------------------------------------------------
    def save(self, path: str | os.PathLike, *, float32: bool = False, compact: bool = False,
             inputs: tuple[str | os.PathLike, ...] = ()) -> Path:
        """Write a versioned ``.asrbf`` file (format 2) atomically.

        The file is a zip of ``.npy`` members (loadable with ``numpy.load``) with fixed
        member dates and without the timings of ``info`` (:data:`VOLATILE_INFO`), so the
        same network always gives the same bytes (format: ``docs/design.md``).

        Parameters
        ----------
        path : path-like
            Output file.
        float32 : bool
            Store the neuron parameters in single precision (half the size).
        compact : bool
            Centres as uint16 over their bounding box, widths and weights as float16 (a
            quarter of the size; what a LOD set ships): centres within 2.3e-5 of the unit
            square, widths and weights within a relative 4.9e-4.
        inputs : paths
            Input files the output must not overwrite.
        """
        return write_network(path, self.pieces, self.frame, self.config, self.info,
                             self.piece_map, float32=float32, compact=compact, inputs=inputs)

    @classmethod
    def load(cls, path: str | os.PathLike) -> Network:
        """Read a ``.asrbf`` file (format 1 or 2).

        Raises
        ------
        NetworkFileError
            Missing, unreadable, foreign, corrupt or version-mismatched file.
        """
        pieces, frame, config, info, piece_map = read_network(path)
        try:
            return cls.from_pieces(pieces, frame, config, info, piece_map)
        except ConfigError as exc:
            raise NetworkFileError(f"{path}: corrupt network file ({exc})") from None

    def __repr__(self) -> str:
        return (f"Network({plural(self.n_neurons, 'neuron')} in "
                f"{plural(self.n_pieces, 'piece')}, N = {self.info.get('n_points', '?')})")
