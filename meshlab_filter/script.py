"""Filter scripts: a JSON list of steps, pymeshlab's filters and ours mixed, run on a MeshSet.

A script is a JSON list; each step is an object with the key ``"filter"`` (a name from
:func:`meshlab_filter.filter_list` or any pymeshlab filter), optionally ``"params"`` (an
object of keyword arguments) and ``"comment"`` (ignored)::

    [
      {"filter": "meshing_remove_duplicate_faces"},
      {"filter": "meshing_close_holes_asrbf", "params": {"maxholesize": "5%"}},
      {"filter": "generate_lod_set_asrbf", "params": {"levels": 3}},
      {"filter": "meshing_decimation_quadric_edge_collapse",
       "params": {"targetfacenum": 2000, "preserveboundary": true}}
    ]

Values are JSON values, except:

- ``{"percentage": 5}`` is ``pymeshlab.PercentageValue(5)`` and ``{"abs": 2.0}`` is
  ``pymeshlab.PureValue(2.0)``, for any filter;
- the string ``"5%"`` is ``PercentageValue(5)`` for the length parameters of our filters
  only (a pymeshlab filter's string parameter, e.g. a muparser expression, is passed as
  written); a bare number for one of our lengths is refused as ambiguous;
- a list of numbers is a float64 numpy array (pymeshlab's point and matrix parameters).

Every step is checked before the first runs (JSON shape, filter names; parameter names,
types and values of our filters), so a typo does not leave a half-run script. Parameters
a step leaves out take their defaults; pymeshlab may remember a filter's values between
calls in one process (docs/design.md), so name every parameter of a pymeshlab filter
whose value matters.
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path
from typing import Any

import numpy as np
import pymeshlab

from asrbf_mesh._atomic import atomic_path, check_output_path
from asrbf_mesh._io import SUPPORTED_SCAN_FORMATS, load_scan
from asrbf_mesh._validate import jsonable as _jsonable
from asrbf_mesh._validate import one_line, parse_length
from asrbf_mesh.errors import AsrbfError, ConfigError

from ._filters import apply_filter, filter_list
from ._params import FILTERS, MeshlabFilterError

__all__ = ["ScriptError", "check_script", "load_script", "run_script", "run_script_file"]

_STEP_KEYS = {"filter", "params", "comment"}


class ScriptError(MeshlabFilterError):
    """A filter script is malformed or one of its steps failed (one line, says which step)."""


def _percentage(text: str, where: str) -> pymeshlab.PercentageValue:
    """``"5%"`` as a PercentageValue, by the one length rule (a percentage in (0, 100])."""
    try:
        parse_length(text, 100.0, where)
    except ConfigError as exc:
        raise ScriptError(one_line(exc)) from None
    return pymeshlab.PercentageValue(float(text.strip()[:-1]))


def _decode(value: Any, length: bool, where: str) -> Any:
    """Return a JSON value as a filter argument (see the module docstring)."""
    if isinstance(value, dict):
        if len(value) == 1 and set(value) <= {"percentage", "abs"}:
            (key, v), = value.items()
            if isinstance(v, (int, float)) and not isinstance(v, bool):
                if key == "percentage":
                    return _percentage(f"{float(v)!r}%", where)
                return pymeshlab.PureValue(float(v))
        raise ScriptError(f"{where}: an object value must be {{\"percentage\": number}} or "
                          f"{{\"abs\": number}}, got {json.dumps(value)}")
    if length and isinstance(value, str) and value.strip().endswith("%"):
        return _percentage(value, where)
    if length and isinstance(value, (int, float)) and not isinstance(value, bool):
        raise ScriptError(f"{where}: a length: write \"{value}%\" or {{\"percentage\": "
                          f"{value}}} (% of the bounding-box diagonal) or {{\"abs\": "
                          f"{value}}} (mesh units)")
    if isinstance(value, list):
        try:
            return np.array(value, dtype=np.float64)
        except (TypeError, ValueError):
            raise ScriptError(f"{where}: a list must hold numbers (a point or a matrix), "
                              f"got {json.dumps(value)}") from None
    return value


def check_script(steps: Any) -> list[tuple[str, dict[str, Any]]]:
    """Check a script (the decoded JSON) and return its steps as ``(filter, params)``.

    Parameters are decoded to filter arguments; those of our filters are checked against
    the parameter table (mesh ids are checked when the step runs).

    Raises
    ------
    ScriptError
        ``step <i>: <problem>`` (steps count from 1).
    """
    if not isinstance(steps, list):
        raise ScriptError(f"a script must be a JSON list of steps, got {type(steps).__name__}")
    known = set(pymeshlab.filter_list())
    out = []
    for i, step in enumerate(steps, 1):
        where = f"step {i}"
        if not isinstance(step, dict) or not isinstance(step.get("filter"), str):
            raise ScriptError(f"{where}: a step must be an object with a \"filter\" name, "
                              f"got {json.dumps(step)[:80]}")
        extra = set(step) - _STEP_KEYS
        if extra:
            raise ScriptError(f"{where}: unknown key(s) {', '.join(sorted(extra))} (a step "
                              "has \"filter\", \"params\" and \"comment\")")
        name = step["filter"]
        spec = FILTERS.get(name)
        if spec is None and name not in known:
            raise ScriptError(f"{where}: unknown filter {name!r}: neither a pymeshlab filter "
                              f"nor one of {', '.join(filter_list())}")
        raw = step.get("params", {})
        if not isinstance(raw, dict):
            raise ScriptError(f"{where} ({name}): \"params\" must be an object, got "
                              f"{json.dumps(raw)[:80]}")
        lengths = {p.name for p in spec.params if p.kind == "length"} if spec else set()
        params = {key: _decode(value, key in lengths, f"{where} ({name}), {key}")
                  for key, value in raw.items()}
        if spec is not None:
            try:
                spec.check(params)
            except MeshlabFilterError as exc:
                raise ScriptError(f"{where} ({name}): {exc}") from exc
        out.append((name, params))
    return out


def run_script(ms: pymeshlab.MeshSet, steps: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Run a filter script on ``ms``, step by step.

    Parameters
    ----------
    ms : pymeshlab.MeshSet
        Changed in place, as by the filters themselves.
    steps : list of dict
        The decoded JSON (see the module docstring), e.g.
        ``[{"filter": "meshing_close_holes_asrbf", "params": {"maxholesize": "5%"}}]``.

    Returns
    -------
    list of dict
        Per step ``filter`` and ``result`` (what the filter returned, JSON-ready: numpy
        values as lists and numbers, non-finite numbers as None).

    Raises
    ------
    ScriptError
        A malformed script (nothing run), or ``step <i> (<filter>): <error>`` for the
        first step that failed (the ones before it have run).
    """
    return _run(ms, check_script(steps))


def _run(ms: pymeshlab.MeshSet, steps: list[tuple[str, dict[str, Any]]]) -> list[dict[str, Any]]:
    results = []
    for i, (name, params) in enumerate(steps, 1):
        try:
            res = apply_filter(ms, name, **params)
        except MeshlabFilterError as exc:
            raise ScriptError(f"step {i} ({name}): {one_line(exc, 10_000)}") from exc
        except Exception as exc:  # pymeshlab's own filters: PyMeshLabException, casts, ...
            if name in FILTERS:
                raise
            raise ScriptError(f"step {i} ({name}): {one_line(exc, 10_000)}") from exc
        results.append({"filter": name, "result": _plain(res or {})})
    return results


def _plain(obj: Any) -> Any:
    """JSON-ready copy: numpy arrays and scalars to lists and numbers, NaN to None."""
    def default(o: Any) -> Any:
        if isinstance(o, (np.ndarray, np.generic)):
            return o.tolist()
        return str(o)

    return _jsonable(json.loads(json.dumps(obj, default=default)))


def load_script(path: str | os.PathLike) -> list[tuple[str, dict[str, Any]]]:
    """Read and check a JSON filter script (see :func:`check_script`).

    Raises
    ------
    AsrbfError
        ``<path>: <problem>``: missing or unreadable file, invalid JSON, a bad step.
    """
    p = Path(path)
    if not p.is_file():
        raise AsrbfError(f"{p}: no such file" if not p.exists() else f"{p}: not a file")
    try:
        steps = json.loads(p.read_text(encoding="utf-8"))
    except OSError as exc:
        raise AsrbfError(f"{p}: cannot read ({exc.strerror})") from None
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise AsrbfError(f"{p}: not a JSON filter script ({one_line(exc, 10_000)})") from None
    try:
        return check_script(steps)
    except ScriptError as exc:
        raise ScriptError(f"{p}: {exc}") from None


def run_script_file(script_path: str | os.PathLike, in_path: str | os.PathLike,
                    out_path: str | os.PathLike) -> dict[str, Any]:
    """Run a JSON filter script on a mesh file and save the current mesh: the CLI's hook.

    Loads ``in_path`` with pymeshlab's ``load_new_mesh`` into a new MeshSet, runs the
    script (:func:`run_script`), and saves the current mesh to ``out_path`` with
    ``save_current_mesh`` (format from the extension) atomically: to a temporary name
    in the same folder, then renamed. ``in_path`` is never written. A file pymeshlab
    loads in a format :func:`asrbf_mesh.load_scan` reads is also checked by it (not its
    shape), so that an empty or non-numeric file or NaN coordinates fail with the same
    message as in the other commands instead of running on a partial or empty mesh.

    Parameters
    ----------
    script_path : path-like
        The JSON script.
    in_path : path-like
        A mesh file pymeshlab reads (PLY, OBJ, OFF, STL, ...).
    out_path : path-like
        Where to save; not ``in_path`` nor ``script_path``.

    Returns
    -------
    dict
        JSON-ready: ``script``, ``input``, ``output``, ``steps`` (per step ``filter``
        and ``result``), ``meshes`` (layers at the end), ``saved`` (``mesh_id``,
        ``label``, ``vertices``, ``faces`` of the saved mesh) and ``seconds``.

    Raises
    ------
    AsrbfError
        One line starting with the file concerned: a missing or malformed script, an
        unreadable or corrupt input, an output path that is a directory, in a missing folder or an
        input, a failing step (``<script>: step <i> (<filter>): ...``), a failed save.
    """
    t0 = time.perf_counter()
    script, src, out = Path(script_path), Path(in_path), Path(out_path)
    steps = load_script(script)
    if not src.is_file():
        raise AsrbfError(f"{src}: no such file" if not src.exists() else f"{src}: not a file")
    check_output_path(out, src, script)
    ms = pymeshlab.MeshSet()
    cwd = os.getcwd()
    try:
        ms.load_new_mesh(str(src))
    except Exception as exc:  # pymeshlab's loaders raise PyMeshLabException and friends
        raise AsrbfError(f"{src}: cannot load ({one_line(exc, 10_000)})") from None
    finally:
        os.chdir(cwd)  # a failed load leaves pymeshlab in the file's folder
    if src.suffix.lower() in SUPPORTED_SCAN_FORMATS:  # what pymeshlab let through
        load_scan(in_path, min_points=1, height_field=False)
    try:
        results = _run(ms, steps)
    except ScriptError as exc:
        raise ScriptError(f"{script}: {one_line(exc, 10_000)}") from exc
    if ms.mesh_number() == 0:
        raise AsrbfError(f"{script}: the script left no mesh to save")
    m = ms.current_mesh()
    saved = {"mesh_id": int(ms.current_mesh_id()), "label": m.label(),
             "vertices": int(m.vertex_number()), "faces": int(m.face_number())}
    with atomic_path(out) as tmp:
        try:
            ms.save_current_mesh(str(tmp))
        except Exception as exc:
            raise AsrbfError(f"{out}: cannot save ({one_line(exc, 10_000)})") from None
    return {"script": str(script), "input": str(src), "output": str(out), "steps": results,
            "meshes": int(ms.mesh_number()), "saved": saved,
            "seconds": time.perf_counter() - t0}
