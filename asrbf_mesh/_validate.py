"""One validation layer: arguments, points, lengths, progress bars and strict JSON.

Every public function and every front end checks its inputs through these helpers, so
that one rule holds everywhere: a bad *parameter* raises :class:`ConfigError`, bad *data*
(points, meshes, scans) raises :class:`ScanError`, and every message names the argument,
what was expected and what arrived, on one line.
"""

from __future__ import annotations

import contextlib
import logging
import math
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from typing import Any

import numpy as np

from .errors import ConfigError, ScanError

__all__ = [
    "one_line",
    "plural",
    "check_int",
    "check_seed",
    "check_float",
    "check_bool",
    "check_choice",
    "check_points",
    "parse_length",
    "progress",
    "jsonable",
    "strict_json",
]

#: Longest message :func:`one_line` keeps.
MAX_MESSAGE = 300


def one_line(exc: BaseException | str, limit: int = MAX_MESSAGE) -> str:
    """Return an exception (or a text) as one short line.

    Examples
    --------
    >>> one_line(ValueError("bad   value"))
    'bad value'
    >>> one_line(KeyError())
    'KeyError'
    """
    text = exc if isinstance(exc, str) else " ".join(str(exc).split())
    text = " ".join(text.split())
    if not text and not isinstance(exc, str):
        text = type(exc).__name__
    return text if len(text) <= limit else text[: limit - 3] + "..."


def plural(n: int, word: str) -> str:
    """``'1 point'`` / ``'3 points'``.

    Examples
    --------
    >>> plural(1, "hole"), plural(2, "hole")
    ('1 hole', '2 holes')
    """
    return f"{n:,} {word}{'' if n == 1 else 's'}"


def _is_int(value: Any) -> bool:
    return not isinstance(value, (bool, np.bool_)) and isinstance(value, (int, np.integer))


def check_int(value: Any, name: str, low: int | None = None, high: int | None = None) -> int:
    """Return ``value`` as an ``int`` in ``[low, high]``; else raise :class:`ConfigError`.

    Booleans and floats (even ``3.0``) are refused: a count is an integer.

    Examples
    --------
    >>> check_int(3, "levels", 1, 12)
    3
    >>> check_int(0, "levels", 1)
    Traceback (most recent call last):
    ...
    asrbf_mesh.errors.ConfigError: levels must be an integer >= 1, got 0
    """
    bounds = (f" >= {low}" if high is None else f" in [{low}, {high}]") if low is not None \
        else (f" <= {high}" if high is not None else "")
    if not _is_int(value) or (low is not None and value < low) or (
            high is not None and value > high):
        raise ConfigError(f"{name} must be an integer{bounds}, got {value!r}")
    return int(value)


def check_seed(seed: Any, name: str = "seed") -> int:
    """Return a valid random seed (an integer ``>= 0``) or raise :class:`ConfigError`."""
    return check_int(seed, name, 0)


def check_float(value: Any, name: str, *, low: float | None = None, high: float | None = None,
                low_open: bool = False, high_open: bool = False) -> float:
    """Return ``value`` as a finite ``float`` within the given bounds, else :class:`ConfigError`.

    Examples
    --------
    >>> check_float(0.5, "margin", low=0.0)
    0.5
    >>> check_float(float("nan"), "margin", low=0.0)
    Traceback (most recent call last):
    ...
    asrbf_mesh.errors.ConfigError: margin must be a finite number >= 0.0, got nan
    """
    lo = "" if low is None else f" {'>' if low_open else '>='} {low}"
    hi = "" if high is None else f" {'<' if high_open else '<='} {high}"
    want = f"a finite number{lo}{' and' if lo and hi else ''}{hi}"
    if isinstance(value, (bool, np.bool_)):
        raise ConfigError(f"{name} must be {want}, got {value!r}")
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ConfigError(f"{name} must be {want}, got {value!r}") from None
    bad = not math.isfinite(v)
    if low is not None:
        bad = bad or (v <= low if low_open else v < low)
    if high is not None:
        bad = bad or (v >= high if high_open else v > high)
    if bad:
        raise ConfigError(f"{name} must be {want}, got {value!r}")
    return v


def check_bool(value: Any, name: str, *, allow_none: bool = False) -> bool | None:
    """Return ``value`` if it is True or False (or None when ``allow_none``), else ConfigError.

    Examples
    --------
    >>> check_bool(True, "metro")
    True
    """
    if (value is None and allow_none) or isinstance(value, bool):
        return value
    raise ConfigError(f"{name} must be True or False{' or None' if allow_none else ''}, "
                      f"got {value!r}")


def check_instance(value: Any, name: str, kind: type, *, allow_none: bool = False) -> Any:
    """Return ``value`` if it is a ``kind`` (or None when ``allow_none``), else ConfigError.

    Examples
    --------
    >>> check_instance(None, "config", dict, allow_none=True) is None
    True
    >>> check_instance("x", "config", dict)
    Traceback (most recent call last):
    ...
    asrbf_mesh.errors.ConfigError: config must be a dict, got str
    """
    if (value is None and allow_none) or isinstance(value, kind):
        return value
    raise ConfigError(f"{name} must be a {kind.__name__}{' or None' if allow_none else ''}, "
                      f"got {type(value).__name__}")


def check_choice(value: Any, name: str, choices: Sequence[str]) -> str:
    """Return ``value`` if it is one of ``choices``, else raise :class:`ConfigError`.

    Examples
    --------
    >>> check_choice("nekf", "update", ("nekf", "gd"))
    'nekf'
    """
    if not isinstance(value, str) or value not in choices:
        raise ConfigError(f"{name} must be one of {', '.join(map(repr, choices))}, "
                          f"got {value!r}")
    return value


def float_array(value: Any, name: str, what: str = "an array of numbers") -> np.ndarray:
    """Return ``value`` as a C-contiguous float64 array, or raise :class:`ScanError`."""
    try:
        return np.ascontiguousarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ScanError(f"{name} must be {what}, got {type(value).__name__}") from None


def readonly(arr: np.ndarray, source: object = None) -> np.ndarray:
    """Return ``arr`` made read-only, copied first if it may alias a writeable ``source``."""
    if isinstance(source, np.ndarray) and source.flags.writeable and \
            np.may_share_memory(arr, source):
        arr = arr.copy()
    arr.flags.writeable = False
    return arr


def check_points(points: Any, name: str = "points", *, min_points: int = 1,
                 columns: int = 3) -> np.ndarray:
    """Return ``points`` as a C-contiguous float64 ``(N, columns)`` array of finite values.

    A :class:`~asrbf_mesh.Scan` or :class:`~asrbf_mesh.Mesh` is accepted for its points
    (vertices). Anything else that is not such an array raises :class:`ScanError` naming
    ``name``.

    Examples
    --------
    >>> check_points([[0, 0, 1]]).shape
    (1, 3)
    >>> check_points([[0, 0]])
    Traceback (most recent call last):
    ...
    asrbf_mesh.errors.ScanError: points must be an (N, 3) array, got shape (1, 2)
    """
    for attr in ("points", "vertices"):
        if not isinstance(points, np.ndarray) and hasattr(points, attr):
            points = getattr(points, attr)
            break
    p = float_array(points, name, f"an (N, {columns}) array of numbers")
    if p.ndim != 2 or p.shape[1] != columns:
        raise ScanError(f"{name} must be an (N, {columns}) array, got shape {p.shape}")
    if len(p) < min_points:
        raise ScanError(f"{name} must hold at least {plural(min_points, 'point')}, "
                        f"got {len(p):,}")
    if not np.all(np.isfinite(p)):
        raise ScanError(f"{name} contain NaN or infinite coordinates")
    return p


def parse_length(value: Any, diagonal: float, name: str) -> float | None:
    """Parse a length: scan units (``12.5``) or a percentage of the diagonal (``"5%"``).

    ``None`` stays ``None`` (no limit). Zero, negative, infinite or malformed values raise
    :class:`ConfigError`; a percentage must lie in (0, 100].

    Examples
    --------
    >>> parse_length("5%", 200.0, "max hole size")
    10.0
    >>> parse_length(3, 200.0, "max hole size")
    3.0
    >>> parse_length("inf", 200.0, "max hole size")
    Traceback (most recent call last):
    ...
    asrbf_mesh.errors.ConfigError: max hole size must be a finite length > 0 or a percentage \
like '5%' (omit it for no limit), got 'inf'
    """
    if value is None:
        return None
    want = (f"{name} must be a finite length > 0 or a percentage like '5%' "
            "(omit it for no limit)")
    pct = isinstance(value, str) and value.strip().endswith("%")
    try:
        if isinstance(value, (bool, np.bool_)):
            raise ValueError
        v = float(value.strip()[:-1]) if pct else float(value)
    except (TypeError, ValueError):
        raise ConfigError(f"{want}, got {value!r}") from None
    if not (math.isfinite(v) and v > 0) or (pct and v > 100):
        if pct and math.isfinite(v) and v > 100:
            raise ConfigError(f"{name} must be a percentage in (0, 100], got {value!r}")
        raise ConfigError(f"{want}, got {value!r}")
    return v * diagonal / 100.0 if pct else v


class _Bar:
    """A tick function over a tqdm bar that appears only after ``delay`` seconds of work."""

    def __init__(self, total: int, desc: str, unit: str, delay: float, initial: int) -> None:
        self.total, self.desc, self.unit, self.delay = total, desc, unit, delay
        self.done, self.bar, self.t0 = initial, None, time.perf_counter()
        self.initial = initial
        if delay <= 0:
            self._open()

    def _open(self) -> None:
        from tqdm import tqdm

        self.bar = tqdm(total=self.total, initial=self.done, unit=self.unit, unit_scale=True,
                        desc=self.desc, leave=False, file=sys.stderr)

    def __call__(self, n: int = 1) -> None:
        self.done += n
        if self.bar is None:
            if self.done < self.total and time.perf_counter() - self.t0 > self.delay:
                self._open()
        else:
            self.bar.update(n)
        if self.done >= self.total:
            self.close()

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None


def progress(total: int, enabled: bool | None, desc: str, *, unit: str = "step",
             delay: float = 1.0, initial: int = 0) -> Callable[[int], None] | None:
    """Return a tick function ``tick(n)`` driving a progress bar on stderr, or ``None``.

    One contract for every long loop: ``enabled=False`` never shows a bar, ``True``
    always does, ``None`` (the default of the public functions) shows one on a
    terminal only. The bar appears after ``delay`` seconds of work (short runs stay
    quiet) and closes itself when ``total`` is reached; call ``tick.close()`` on an
    early exit.
    """
    if enabled is False or (enabled is None and not sys.stderr.isatty()):
        return None
    return _Bar(int(total), desc, unit, 0.0 if enabled is True else delay, initial)


def jsonable(obj: Any) -> Any:
    """Return ``obj`` with numpy scalars/arrays as Python values and non-finite floats as None.

    Dataclass-like objects with a ``to_dict`` method are expanded; paths become strings.
    The result always serializes as strict JSON (no ``NaN`` / ``Infinity`` tokens).

    Examples
    --------
    >>> jsonable({"a": np.float64("nan"), "b": [np.int64(2), float("inf")]})
    {'a': None, 'b': [2, None]}
    """
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return jsonable(obj.tolist())
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if hasattr(obj, "to_dict") and callable(obj.to_dict):
        return jsonable(obj.to_dict())
    if isinstance(obj, (str, int, float, bool)) or obj is None:
        return obj
    if hasattr(obj, "__fspath__"):
        return str(obj)
    return str(obj)


def strict_json(obj: Any, **kwargs: Any) -> str:
    """Serialize ``obj`` as strict JSON (see :func:`jsonable`); ``kwargs`` go to json.dumps."""
    import json

    return json.dumps(jsonable(obj), allow_nan=False, **kwargs)


@contextlib.contextmanager
def quiet_logger(name: str) -> Iterator[None]:
    """Silence a library's logger for a while.

    laspy and tifffile log what they then raise or skip; their failures become one
    ScanError line.
    """
    log = logging.getLogger(name)
    level = log.level
    log.setLevel(logging.CRITICAL + 1)
    try:
        yield
    finally:
        log.setLevel(level)
