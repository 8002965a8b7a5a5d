"""The fitted Gaussian RBF network: evaluation, statistics and the ``.asrbf`` file.

``f(x) = a0 + sum_k a_k exp(-||x - u_k||^2 / sigma_k^2)`` (paper, eqs. 1-2), learned
in the unit square; :class:`Network` evaluates it in physical units through its
:class:`~asrbf_mesh._frame.Frame`.
"""

from __future__ import annotations

import io
import json
import os
import zipfile
from dataclasses import MISSING, dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np

from . import _network_kernels as _nk
from ._atomic import atomic_path, check_output_path
from ._config import FitConfig
from ._frame import Frame
from ._validate import check_float, check_int, one_line
from .errors import AsrbfError, ConfigError, NetworkFileError, ScanError

__all__ = ["Network", "FitInfo", "FitLog", "NeuronStats", "FORMAT_NAME", "FORMAT_VERSION"]

FORMAT_NAME = "asrbf-network"
FORMAT_VERSION = 1
_ZIP_DATE = (1980, 1, 1, 0, 0, 0)  # fixed member dates: same network, same bytes
# wall-clock figures stay in memory only: the same seed must give the same file
VOLATILE_INFO = ("fit_seconds", "learn_seconds", "polish_seconds", "us_per_step")


def eval_grid(centers: np.ndarray, widths: np.ndarray, weights: np.ndarray,
              support: float) -> tuple:
    """Build the static evaluation grid ``(support, lo, h, g, start, items, packed)``.

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
    start, items = _nk.build_grid(centers, widths, support, lo, h, g)
    packed = _nk.pack_cells(centers, widths, weights, items)
    return support, lo, h, g, start, items, packed


def eval_unit(grid: tuple, uv: np.ndarray, a0: float, centers: np.ndarray, widths: np.ndarray,
              weights: np.ndarray, want_grad: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Evaluate f (and optionally its gradient) at unit-square points through a grid."""
    s, lo, h, g, start, items, packed = grid
    uv = np.ascontiguousarray(uv, dtype=np.float64)
    if not want_grad:
        return _nk.evaluate_values(uv, a0, packed, s, lo, h, g, start), np.zeros((0, 2))
    return _nk.evaluate_with_gradient(uv, a0, centers, widths, weights, s, lo, h, g, start, items)


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
    version: str = ""
    streamed: bool = False
    chunk: int | None = None
    mix: int | None = None
    spacing_exact: bool | None = None
    outliers: int | None = None

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


@dataclass(frozen=True, eq=False)
class Network:
    """An immutable, picklable Gaussian RBF network fitted to a height field.

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
    """

    a0: float
    centers: np.ndarray
    widths: np.ndarray
    weights: np.ndarray
    frame: Frame
    config: FitConfig
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
        if np.any(w <= 0):
            raise ConfigError("widths must be positive")
        if not isinstance(self.frame, Frame):
            raise ConfigError(f"frame must be a Frame, got {type(self.frame).__name__}")
        if not isinstance(self.config, FitConfig):
            raise ConfigError(f"config must be a FitConfig, got {type(self.config).__name__}")
        if self.log is not None and not isinstance(self.log, FitLog):
            raise ConfigError(f"log must be a FitLog or None, got {type(self.log).__name__}")
        if not isinstance(self.info, dict):
            raise ConfigError(f"info must be a dict, got {type(self.info).__name__}")
        for name, arr in (("centers", c), ("widths", w), ("weights", a)):
            arr.flags.writeable = False
            object.__setattr__(self, name, arr)
        object.__setattr__(self, "a0", a0)

    # -- pickling: drop the evaluation grid cache ------------------------------------------
    def __getstate__(self) -> dict[str, Any]:
        state = dict(self.__dict__)
        state.pop("_grid", None)
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)

    # -- sizes ------------------------------------------------------------------------------
    @property
    def n_neurons(self) -> int:
        """K, the number of Gaussian neurons."""
        return int(len(self.widths))

    @property
    def fit_info(self) -> FitInfo | None:
        """The fit figures of ``info`` as a :class:`FitInfo`; None without fit figures."""
        try:
            return FitInfo.from_dict(self.info)
        except (ConfigError, TypeError):
            return None

    def compression_ratio(self, n_points: int | None = None) -> float:
        """N : K, points per neuron (paper, Table 2)."""
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
        """Width and |weight| statistics (the paper's Table 1 reports |a|)."""
        w = self.widths
        a = np.abs(self.weights)
        if self.n_neurons == 0:
            return NeuronStats(0, *[None] * 8)
        return NeuronStats(self.n_neurons, float(w.max()), float(w.min()), float(w.mean()),
                           float(w.std()), float(a.max()), float(a.min()), float(a.mean()),
                           float(a.std()))

    # -- evaluation -------------------------------------------------------------------------
    def _grid_arrays(self) -> tuple:
        cached = self.__dict__.get("_grid")
        if cached is None:
            cached = eval_grid(self.centers, self.widths, self.weights, self.config.support)
            object.__setattr__(self, "_grid", cached)
        return cached

    def _eval_unit(self, uv: np.ndarray, want_grad: bool) -> tuple[np.ndarray, np.ndarray]:
        return eval_unit(self._grid_arrays(), uv, self.a0, self.centers, self.widths,
                         self.weights, want_grad)

    @staticmethod
    def _points(xy: np.ndarray) -> np.ndarray:
        arr = np.ascontiguousarray(xy, dtype=np.float64)
        if arr.ndim != 2 or arr.shape[1] != 2:
            raise ScanError(f"xy must have shape (M, 2), got {arr.shape}")
        if not np.all(np.isfinite(arr)):
            raise ScanError("xy contains NaN or infinite values")
        return arr

    def evaluate(self, xy: np.ndarray, *, unit: bool = False) -> np.ndarray:
        """Depth of the surface at (M, 2) points.

        Parameters
        ----------
        xy : (M, 2) array
            Points in the frame's local physical (x, y) (for view axis ``"z"`` these
            are the world x and y), or in the unit square if ``unit``.
        unit : bool
            Work in the unit cube (inputs and output) instead of physical units.

        Returns
        -------
        (M,) float64 array
            Depth in physical units (or unit-cube depth).
        """
        pts = self._points(xy)
        uv = pts if unit else self.frame.xy_to_unit(pts)
        f, _ = self._eval_unit(np.ascontiguousarray(uv), False)
        if unit:
            return f
        return f * self.frame.scale[2] + self.frame.offset[2]

    def gradient(self, xy: np.ndarray, *, unit: bool = False) -> np.ndarray:
        """Analytic gradient d depth / d(x, y), (M, 2), in the units of :meth:`evaluate`."""
        pts = self._points(xy)
        uv = pts if unit else self.frame.xy_to_unit(pts)
        _, grad = self._eval_unit(np.ascontiguousarray(uv), True)
        if unit:
            return grad
        return grad * (self.frame.scale[2] / self.frame.scale[:2])

    def surface_points(self, xy: np.ndarray, *, unit: bool = False) -> np.ndarray:
        """World (M, 3) points of the surface above local (x, y) (or unit-square) points."""
        pts = self._points(xy)
        uv = pts if unit else self.frame.xy_to_unit(pts)
        f, _ = self._eval_unit(np.ascontiguousarray(uv), False)
        return self.frame.to_world(np.column_stack([uv, f]))

    def normals(self, xy: np.ndarray, *, unit: bool = False) -> np.ndarray:
        """Return unit surface normals in world coordinates, (M, 3), facing +depth.

        From the analytic gradient: ``n ~ (-dz/dx, -dz/dy, 1)`` in the local physical
        frame, rotated to world.
        """
        pts = self._points(xy)
        uv = pts if unit else self.frame.xy_to_unit(pts)
        _, grad = self._eval_unit(np.ascontiguousarray(uv), True)
        gp = grad * (self.frame.scale[2] / self.frame.scale[:2])
        n = np.column_stack([-gp[:, 0], -gp[:, 1], np.ones(len(gp))])
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        return n @ self.frame.rotation.T

    # -- file -------------------------------------------------------------------------------
    def save(self, path: str | os.PathLike, *, float32: bool = False,
             inputs: tuple[str | os.PathLike, ...] = ()) -> Path:
        """Write a versioned ``.asrbf`` file atomically.

        The file is a zip of ``.npy`` members (loadable with ``numpy.load``) with fixed
        member dates and without the timings of ``info`` (:data:`VOLATILE_INFO`), so the
        same network always gives the same bytes.

        Parameters
        ----------
        path : path-like
            Output file.
        float32 : bool
            Store the neuron parameters in single precision (half the size).
        inputs : paths
            Input files the output must not overwrite.
        """
        out = check_output_path(path, *inputs)
        dt = np.float32 if float32 else np.float64
        meta = {"format": FORMAT_NAME, "format_version": FORMAT_VERSION,
                "dtype": np.dtype(dt).name, "frame": self.frame.to_dict(),
                "config": self.config.to_dict(),
                "info": {k: v for k, v in self.info.items() if k not in VOLATILE_INFO},
                "log_counters": self.log.counters() if self.log else None}
        members: dict[str, np.ndarray] = {
            "meta": np.frombuffer(json.dumps(meta, sort_keys=True).encode(), dtype=np.uint8),
            "a0": np.array([self.a0], dtype=np.float64),
            "centers": self.centers.astype(dt),
            "widths": self.widths.astype(dt),
            "weights": self.weights.astype(dt),
        }
        if self.log is not None:
            for name in FitLog._ARRAYS:
                members[f"log_{name}"] = np.asarray(getattr(self.log, name))
        with atomic_path(out) as tmp, zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as zf:
            for name, arr in members.items():
                buf = io.BytesIO()
                np.lib.format.write_array(buf, np.ascontiguousarray(arr), allow_pickle=False)
                zi = zipfile.ZipInfo(f"{name}.npy", date_time=_ZIP_DATE)
                zi.compress_type = zipfile.ZIP_DEFLATED
                zi.external_attr = 0o644 << 16
                zf.writestr(zi, buf.getvalue())
        return out

    @classmethod
    def load(cls, path: str | os.PathLike) -> Network:
        """Read a ``.asrbf`` file written by :meth:`save`.

        Raises
        ------
        NetworkFileError
            Missing, unreadable, foreign, corrupt or version-mismatched file.
        """
        p = Path(path)
        if not p.exists():
            raise NetworkFileError(f"{p}: no such file")
        if p.is_dir():
            raise NetworkFileError(f"{p}: is a directory, not a network file")
        try:
            with open(p, "rb") as fh:
                magic = fh.read(4)
        except OSError as exc:
            raise NetworkFileError(f"{p}: cannot read ({exc.strerror})") from None
        if not magic:
            raise NetworkFileError(f"{p}: not an asrbf network file (empty file, 0 bytes)")
        try:
            with zipfile.ZipFile(p) as zf:
                names = set(zf.namelist())
                if "meta.npy" not in names:
                    raise NetworkFileError(f"{p}: not an asrbf network file (no metadata)")
                arrays = {}
                for name in names:
                    if name.endswith(".npy"):
                        with zf.open(name) as fh:
                            arrays[name[:-4]] = np.lib.format.read_array(
                                io.BytesIO(fh.read()), allow_pickle=False)
        except NetworkFileError:
            raise
        except zipfile.BadZipFile:
            if magic == b"PK\x03\x04":  # starts like a zip: damaged or cut short
                raise NetworkFileError(
                    f"{p}: corrupt or truncated network file (the zip archive is damaged)"
                ) from None
            raise NetworkFileError(f"{p}: not an asrbf network file (not a zip archive)") from None
        except OSError as exc:
            raise NetworkFileError(f"{p}: cannot read ({exc.strerror or one_line(exc)})") from None
        except Exception as exc:  # corrupt member, truncated data, ...
            raise NetworkFileError(f"{p}: corrupt network file ({one_line(exc)})") from None
        try:
            meta = json.loads(bytes(arrays["meta"]).decode())
        except Exception:
            raise NetworkFileError(f"{p}: corrupt network file (unreadable metadata)") from None
        if not isinstance(meta, dict) or meta.get("format") != FORMAT_NAME:
            raise NetworkFileError(f"{p}: not an asrbf network file")
        version = meta.get("format_version")
        if version != FORMAT_VERSION:
            raise NetworkFileError(
                f"{p}: network file format version {version!r} is not supported "
                f"(this asrbf-mesh reads version {FORMAT_VERSION})")
        try:
            log = None
            if "log_step" in arrays:
                counters = meta.get("log_counters") or {}
                log = FitLog(*(arrays[f"log_{n}"] for n in FitLog._ARRAYS),
                             **{k: int(v) for k, v in counters.items()})
            a0 = np.asarray(arrays["a0"], dtype=np.float64).reshape(-1)
            if a0.shape != (1,):
                raise ValueError("a0 must hold one value")
            return cls(float(a0[0]), arrays["centers"], arrays["widths"],
                       arrays["weights"], Frame.from_dict(meta["frame"]),
                       FitConfig.from_dict(meta["config"]), log, dict(meta.get("info") or {}))
        except (KeyError, ValueError, TypeError, AsrbfError) as exc:
            raise NetworkFileError(f"{p}: corrupt network file ({one_line(exc)})") from None
