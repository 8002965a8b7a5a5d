"""The ``.asrbf`` network file: format 2 (pieces), and format 1 (one network) read back.

A zip of ``.npy`` members (each loadable with ``numpy.load``) with fixed member dates
and the wall-clock figures left out, so the same model always gives the same bytes.
Format 2 members (field by field in ``docs/design.md``):

- ``meta``: UTF-8 JSON: format name and version, dtype, frame, config, the model's
  ``info``, one ``{"info", "log_counters"}`` per piece and the piece map's corner and cell;
- ``a0`` (P,), ``piece_neurons`` (P,): each piece's bias and neuron count;
- ``centers`` (K, 2), ``widths`` (K,), ``weights`` (K,): all pieces' neurons, piece
  after piece;
- ``log_*`` and ``log_lengths`` (P,): the pieces' learning logs, one after another;
- ``piece_map`` (ny, nx): the piece of each map cell, when there are several pieces.

Format 1 (one network; ``a0`` of one value, no ``piece_*`` member) still loads.
"""

from __future__ import annotations

import io
import json
import os
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from ._atomic import atomic_path, check_output_path
from ._config import FitConfig
from ._frame import Frame
from ._piece import FitLog, Piece
from ._piece_map import PieceMap
from ._validate import one_line
from .errors import AsrbfError, NetworkFileError

__all__ = ["write_network", "read_network", "FORMAT_NAME", "FORMAT_VERSION",
           "READABLE_VERSIONS", "VOLATILE_INFO"]

FORMAT_NAME = "asrbf-network"
#: The version written.
FORMAT_VERSION = 2
# wall-clock figures stay in memory only: the same seed must give the same file
VOLATILE_INFO = ("fit_seconds", "learn_seconds", "polish_seconds", "us_per_step",
                 "compile_seconds")
#: Format versions :func:`read_network` reads.
READABLE_VERSIONS = (1, 2)
_ZIP_DATE = (1980, 1, 1, 0, 0, 0)  # fixed member dates: same network, same bytes


def _stable_info(info: dict[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in info.items() if k not in VOLATILE_INFO}


def _compact(centers: np.ndarray, widths: np.ndarray, weights: np.ndarray
             ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """Centres as uint16 over their bounding box, widths and weights as float16.

    A quarter of float64. Centres land within 1/65535 of their box (2.3e-5 of the unit
    square for a box of 1.5), widths and weights within a relative 4.9e-4; an array that
    float16 cannot hold (a width under its normal range, a weight over 60,000) stays
    float32.
    """
    lo = centers.min(axis=0) if len(centers) else np.zeros(2)
    hi = centers.max(axis=0) if len(centers) else np.ones(2)
    span = np.where(hi > lo, hi - lo, 1.0)
    q = np.rint((centers - lo) / span * 65535.0).astype(np.uint16)
    out = {"centers": q.reshape(-1, 2)}
    for name, arr in (("widths", widths), ("weights", weights)):
        small = np.abs(arr[arr != 0]).min(initial=1.0) < 6.2e-5
        out[name] = arr.astype(np.float32 if small or np.abs(arr).max(initial=0) > 6e4
                               else np.float16)
    return out, {"centers_lo": lo.tolist(), "centers_span": span.tolist()}


def write_network(path: str | os.PathLike, pieces: tuple[Piece, ...], frame: Frame,
                  config: FitConfig, info: dict[str, Any], pm: PieceMap | None, *,
                  float32: bool = False, compact: bool = False,
                  inputs: tuple[str | os.PathLike, ...] = ()) -> Path:
    """Write a model's parts as a format-2 ``.asrbf`` file atomically (``Network.save``)."""
    out = check_output_path(path, *inputs)
    dt = np.float32 if float32 or compact else np.float64
    has_log = any(p.log is not None for p in pieces)
    meta = {"format": FORMAT_NAME, "format_version": FORMAT_VERSION,
            "dtype": "compact" if compact else np.dtype(dt).name, "frame": frame.to_dict(),
            "config": config.to_dict(), "info": _stable_info(info),
            "pieces": [{"info": _stable_info(p.info),
                        "log_counters": p.log.counters() if p.log else None} for p in pieces],
            "piece_map": None if pm is None else {"lo": pm.lo.tolist(), "cell": pm.cell}}
    members: dict[str, np.ndarray] = {
        "meta": np.frombuffer(json.dumps(meta, sort_keys=True).encode(), dtype=np.uint8),
        "a0": np.array([p.a0 for p in pieces], dtype=np.float64),
        "piece_neurons": np.array([p.n_neurons for p in pieces], dtype=np.int64),
        "centers": np.concatenate([p.centers for p in pieces]).astype(dt),
        "widths": np.concatenate([p.widths for p in pieces]).astype(dt),
        "weights": np.concatenate([p.weights for p in pieces]).astype(dt),
    }
    if compact:
        packed, quant = _compact(np.concatenate([p.centers for p in pieces]),
                                 np.concatenate([p.widths for p in pieces]),
                                 np.concatenate([p.weights for p in pieces]))
        members.update(packed)
        meta["quantization"] = quant
        members["meta"] = np.frombuffer(json.dumps(meta, sort_keys=True).encode(),
                                        dtype=np.uint8)
    if has_log:
        logs = [p.log for p in pieces]
        members["log_lengths"] = np.array([0 if lg is None else len(lg.step) for lg in logs],
                                          dtype=np.int64)
        for name in FitLog._ARRAYS:
            members[f"log_{name}"] = np.concatenate(
                [np.asarray(getattr(lg, name)) for lg in logs if lg is not None])
    if pm is not None:
        members["piece_map"] = pm.labels
    with atomic_path(out) as tmp, zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as zf:
        for name, arr in members.items():
            buf = io.BytesIO()
            np.lib.format.write_array(buf, np.ascontiguousarray(arr), allow_pickle=False)
            zi = zipfile.ZipInfo(f"{name}.npy", date_time=_ZIP_DATE)
            zi.compress_type = zipfile.ZIP_DEFLATED
            zi.external_attr = 0o644 << 16
            zf.writestr(zi, buf.getvalue())
    return out


def _read_members(p: Path) -> dict[str, np.ndarray]:
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
    return arrays


_Parts = tuple[tuple[Piece, ...], Frame, FitConfig, dict[str, Any], PieceMap | None]


def read_network(path: str | os.PathLike) -> _Parts:
    """Read a ``.asrbf`` file of format 1 or 2: pieces, frame, config, info and map.

    Raises
    ------
    NetworkFileError
        Missing, unreadable, foreign, corrupt or version-mismatched file.
    """
    p = Path(path)
    arrays = _read_members(p)
    try:
        meta = json.loads(bytes(arrays["meta"]).decode())
    except Exception:
        raise NetworkFileError(f"{p}: corrupt network file (unreadable metadata)") from None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT_NAME:
        raise NetworkFileError(f"{p}: not an asrbf network file")
    version = meta.get("format_version")
    if version not in READABLE_VERSIONS:
        raise NetworkFileError(
            f"{p}: network file format version {version!r} is not supported "
            f"(this asrbf-mesh reads versions {', '.join(map(str, READABLE_VERSIONS))})")
    try:
        frame = Frame.from_dict(meta["frame"])
        config = FitConfig.from_dict(meta["config"])
        info = dict(meta.get("info") or {})
        if version == 1:
            return _load_v1(arrays, meta, frame, config, info)
        return _load_v2(arrays, meta, frame, config, info)
    except (KeyError, ValueError, TypeError, AsrbfError) as exc:
        raise NetworkFileError(f"{p}: corrupt network file ({one_line(exc)})") from None


def _log(arrays: dict[str, np.ndarray], lo: int, hi: int, counters: Any) -> FitLog:
    return FitLog(*(arrays[f"log_{n}"][lo:hi] for n in FitLog._ARRAYS),
                  **{k: int(v) for k, v in (counters or {}).items()})


def _load_v1(arrays: dict[str, np.ndarray], meta: dict[str, Any], frame: Frame,
             config: FitConfig, info: dict[str, Any]) -> _Parts:
    log = None
    if "log_step" in arrays:
        log = _log(arrays, 0, len(arrays["log_step"]), meta.get("log_counters"))
    a0 = np.asarray(arrays["a0"], dtype=np.float64).reshape(-1)
    if a0.shape != (1,):
        raise ValueError("a0 must hold one value")
    piece = Piece(float(a0[0]), arrays["centers"], arrays["widths"], arrays["weights"], log)
    return (piece,), frame, config, info, None


def _load_v2(arrays: dict[str, np.ndarray], meta: dict[str, Any], frame: Frame,
             config: FitConfig, info: dict[str, Any]) -> _Parts:
    a0 = np.asarray(arrays["a0"], dtype=np.float64).reshape(-1)
    counts = np.asarray(arrays["piece_neurons"]).reshape(-1)
    described = meta["pieces"]
    if (len(a0) == 0 or counts.shape != a0.shape or len(described) != len(a0)
            or counts.dtype.kind not in "iu" or counts.min() < 0
            or counts.sum() != len(arrays["widths"])):
        raise ValueError("the pieces' sizes disagree with the neuron arrays")
    ends = np.cumsum(counts)
    centers = arrays["centers"]
    if centers.dtype == np.uint16:  # compact: dequantize over the stored box
        q = meta["quantization"]
        centers = (np.asarray(q["centers_lo"], dtype=np.float64)
                   + centers.astype(np.float64) / 65535.0
                   * np.asarray(q["centers_span"], dtype=np.float64))
    log_ends = None
    if "log_lengths" in arrays:
        lengths = np.asarray(arrays["log_lengths"]).reshape(-1)
        if lengths.shape != a0.shape or lengths.sum() != len(arrays["log_step"]):
            raise ValueError("the pieces' log lengths disagree with the log arrays")
        log_ends = np.cumsum(lengths)
    pieces = []
    for i, d in enumerate(described):
        lo, hi = int(ends[i] - counts[i]), int(ends[i])
        log = None
        if log_ends is not None and (d.get("log_counters") is not None):
            log = _log(arrays, int(log_ends[i - 1]) if i else 0, int(log_ends[i]),
                       d["log_counters"])
        pieces.append(Piece(float(a0[i]), centers[lo:hi], arrays["widths"][lo:hi],
                            arrays["weights"][lo:hi], log, dict(d.get("info") or {})))
    pm = None
    if meta.get("piece_map") is not None:
        pm = PieceMap(np.asarray(meta["piece_map"]["lo"], dtype=np.float64),
                      float(meta["piece_map"]["cell"]), arrays["piece_map"])
    elif len(pieces) > 1:
        raise ValueError(f"{len(pieces)} pieces without a piece map")
    return tuple(pieces), frame, config, info, pm
