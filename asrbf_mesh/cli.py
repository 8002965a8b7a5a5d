"""The ``asrbf`` command: fit, info, reconstruct, fill-holes, lod, metro, compare, report, demo.

Errors a user can cause print one line on stderr and exit with code 2; an
unexpected bug exits with code 1 and a traceback.
"""

from __future__ import annotations

import argparse
import inspect
import math
import os
import shlex
import signal
import sys
import threading
import warnings
from collections.abc import Iterator
from pathlib import Path
from typing import Any, NoReturn

from . import __version__, _warm
from ._atomic import atomic_path, check_output_dir
from ._config import (
    BLENDS,
    DECAYS,
    FOOTPRINT_MODES,
    PIECES,
    POLISHES,
    PRUNINGS,
    UPDATES,
    VIEW_AXES,
    FitConfig,
)
from ._validate import strict_json
from .errors import AsrbfError, ConfigError

__all__ = ["main", "build_parser", "task_options"]


def _tasks() -> Any:
    """Import the task layer when a command runs (``asrbf --help`` stays instant)."""
    from . import tasks

    return tasks

# FitConfig field -> (flag, type, help naming the paper's symbol)
_LEARNING_OPTIONS: list[tuple[str, str, type, str]] = [
    ("error_threshold", "--error-threshold", float, "E, local error threshold (criterion 2)"),
    ("rms_threshold", "--rms-threshold", float, "E_omega, windowed RMS threshold (criterion 3)"),
    ("d_max", "--d-max", float, "D_max, initial neuron separation (criterion 1)"),
    ("d_min", "--d-min", float,
     "D_min, neuron separation level (default: max(2 x scan spacing, E), at most 0.2)"),
    ("gamma", "--gamma", float, "gamma, decay factor of the separation distance, eq. (4)"),
    ("decay_fraction", "--decay-fraction", float,
     "--decay pass: share of the first pass after which D reaches D_min"),
    ("psi", "--psi", float, "psi, overlap factor of new neuron widths, eq. (7)"),
    ("window", "--window", int, "omega, RMS window (criterion 3) and pruning window"),
    ("prune_threshold", "--prune-threshold", float, "P, pruning contribution threshold"),
    ("prune_window", "--prune-window", int, "observations counted by pruning (default omega)"),
    ("passes", "--passes", int, "replays of the data in random order"),
    ("measurement_noise", "--measurement-noise", float, "R, EKF measurement noise variance"),
    ("process_noise", "--process-noise", float, "q, EKF process noise (relative)"),
    ("neighbourhood_factor", "--neighbourhood-factor", float,
     "NEKF neighbourhood radius in units of the separation distance D"),
    ("max_neighbours", "--max-neighbours", int, "cap on the NEKF neighbourhood size K'"),
    ("gd_rate", "--gd-rate", float, "step size of --update gd"),
    ("support", "--support", float, "Gaussian truncation radius in widths"),
    ("max_neurons", "--max-neurons", int, "hard cap on the number of neurons K"),
    ("polish_iterations", "--polish-iterations", int, "Levenberg-Marquardt iterations"),
]
_CHOICE_OPTIONS = [
    ("update", "--update", UPDATES, "parameter updater"),
    ("pruning", "--pruning", PRUNINGS, "pruning rule ('literal' is the paper's)"),
    ("decay", "--decay", DECAYS, "index of eq. (4): 'neurons' as printed in the paper; "
                                 "'observation' as in RAN/MRAN (gives the paper's results); "
                                 "'pass': D_min reached after --decay-fraction of the first "
                                 "pass"),
    ("polish", "--polish", POLISHES, "batch stage after learning ('none' is the paper's)"),
]


def _add_learning(p: argparse.ArgumentParser, full: bool = True) -> None:
    d = FitConfig()
    g = p.add_argument_group("learning parameters (unit cube; the numeric defaults are the "
                                 "paper's section 5.1 values but --d-min's rule and "
                                 "--decay-fraction; --decay, --pruning and --polish default "
                                 "to this package's choices, the paper's are named)")
    for field, flag, typ, text in _LEARNING_OPTIONS:
        g.add_argument(flag, dest=field, type=typ, default=None,
                       help=f"{text} [default: {getattr(d, field)}]")
    for field, flag, choices, text in _CHOICE_OPTIONS:
        g.add_argument(flag, dest=field, choices=choices, default=None,
                       help=f"{text} [default: {getattr(d, field)}]")
    if full:
        p.add_argument("--seed", type=int, default=0, help="random order seed [default: 0]")
    p.add_argument("--view-axis", choices=VIEW_AXES, default="z",
                   help="depth direction of the height field [default: z]")


def _add_pieces(p: argparse.ArgumentParser, what: str = "") -> None:
    p.add_argument("--pieces", choices=PIECES, default="auto",
                   help="auto: cut the scan at occlusion cliffs and walls and fit one network "
                        "per smooth piece; 1: the paper's single network over the whole scan"
                        f"{what} [default: auto]")


class _RangeOption(argparse.Action):
    """Collect a range-data option into ``namespace.range_options`` (a dict)."""

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace,
                 values: Any, option_string: str | None = None) -> None:
        opts = dict(getattr(namespace, "range_options", None) or {})
        opts[self.dest] = values
        namespace.range_options = opts


def _numbers(kind: type, count: int | None = None, name: str = "") -> Any:
    """Return an argparse type: comma-separated ``kind`` numbers (``count`` if given)."""
    def parse(text: str) -> tuple:
        try:
            vals = tuple(kind(t) for t in text.split(",") if t.strip())
        except ValueError:
            raise argparse.ArgumentTypeError(f"not a comma-separated list of {kind.__name__}s: "
                                             f"{text!r}") from None
        if not vals or (count is not None and len(vals) != count):
            raise argparse.ArgumentTypeError(f"{name or 'the list'} needs "
                                             f"{count or 'at least one'} numbers, got {text!r}")
        return vals
    return parse


def _returns(text: str) -> str | tuple[int, ...]:
    return text if text in ("first", "last", "single") else _numbers(int)(text)


def _add_range(p: argparse.ArgumentParser) -> None:
    """Options of range data: depth images, elevation grids, LiDAR (asrbf_mesh._range_io)."""
    g = p.add_argument_group("range data (depth images, elevation grids, LAS/LAZ)")
    kw: dict[str, Any] = {"action": _RangeOption, "default": argparse.SUPPRESS}
    g.add_argument("--depth-scale", dest="depth_scale", type=float, metavar="S", **kw,
                   help="depth image units per metre: 5000 for the TUM RGB-D benchmark, 1000 "
                        "for most RealSense devices (required for integer images)")
    g.add_argument("--invalid", type=_numbers(float), metavar="V[,V...]", **kw,
                   help="depth values meaning 'no measurement' [default: 0]")
    g.add_argument("--intrinsics", type=_numbers(float, 4, "--intrinsics"),
                   metavar="FX,FY,CX,CY", **kw,
                   help="pinhole intrinsics (pixels): work in metric camera coordinates "
                        "[default: the pixel grid, depth in metres]")
    g.add_argument("--cell", type=float, metavar="C", **kw,
                   help="cell size of a .npy/.npz elevation array (metres); makes a 2-D "
                        ".npy an elevation grid")
    g.add_argument("--classes", type=_numbers(int), metavar="C[,C...]", **kw,
                   help="LAS/LAZ: keep these classes only, e.g. 2 (ground)")
    g.add_argument("--returns", type=_returns, metavar="first|last|single|N[,N...]", **kw,
                   help="LAS/LAZ: keep these returns only")
    p.set_defaults(range_options=None)


def _f(value: Any, spec: str) -> str:
    """``value`` formatted, or ``n/a`` for a figure that does not exist (None, NaN)."""
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "n/a"
    return format(value, spec)


def _pieces_line(s: dict[str, Any]) -> str:
    """``3 (29,000 / 1,200 / 40 points)``, or the reason a streamed fit is one network."""
    pieces = s.get("pieces")
    if isinstance(pieces, str):
        return f"1 ({pieces})"
    if not pieces:
        return "1"
    if len(pieces) == 1:
        return "1 (one network)"
    sizes = " / ".join(f"{p['n_points']:,}" for p in pieces[:6])
    more = f" / ... {len(pieces) - 6} more" if len(pieces) > 6 else ""
    small = sum(p["constant"] for p in pieces)
    consts = f", {small} constant" if small else ""
    return f"{len(pieces)} ({sizes}{more} points{consts})"


def _print_summary(s: dict[str, Any], out=None) -> None:
    out = out or sys.stdout
    rows = [
        ("points N", f"{s['n_points']:,}"),
        ("neurons K", f"{s['n_neurons']:,}  (added {s['added']:,}, pruned {s['pruned']:,})"),
        ("E-bar (unit cube)", f"{_f(s['ebar'], '.5f')}  (sequential "
                              f"{_f(s['ebar_sequential'], '.5f')}, polish {s['polish']})"),
        ("pieces", _pieces_line(s)),
        ("N:K", f"{s['n_to_k']:.1f}:1"),
        ("3N:4K", f"{s['storage_ratio']:.1f}:1"),
        ("error (scan units)", f"mean {_f(s['error_mean'], '.4g')}, "
                               f"std {_f(s['error_std'], '.4g')}"),
        ("fit time", f"{s['fit_seconds']:.2f} s  ({s['steps']:,} steps, "
                     f"{s['us_per_step']:.2f} us/step, polish {s['polish_seconds']:.2f} s)"),
    ]
    if (s.get("compile_seconds") or 0.0) >= 0.05:
        rows.append(("of which compiling", f"{s['compile_seconds']:.2f} s  (the kernels' first "
                                           "run on this machine: later runs load them)"))
    w = max(len(k) for k, _ in rows)
    for k, v in rows:
        print(f"  {k:<{w}}  {v}", file=out)


# --------------------------------------------------------------------------- text output


def _show_fit(d: dict[str, Any], args: argparse.Namespace) -> None:
    print(f"fitted {args.scan} -> {d['output']}")
    _print_summary(d)


def _show_info(d: dict[str, Any], args: argparse.Namespace) -> None:
    info, st, c = d["info"], d["stats"], d["config"]
    print(f"{args.network}: ASRBF network, format version {d['format_version']}")
    print(f"  neurons K          {d['n_neurons']:,}")
    print(f"  pieces             {_pieces_line(d)}")
    if "n_points" in info:
        n, k = int(info["n_points"]), max(d["n_neurons"], 1)
        print(f"  fitted on N        {info['n_points']:,} points  (N:K {n / k:.1f}:1, "
              f"3N:4K {3.0 * n / (4.0 * k):.1f}:1)")
    if "ebar" in info:
        print(f"  E-bar              {_f(info['ebar'], '.5f')}")
    print("  width  max/min/mean/std   " + " ".join(
        _f(st[f"width_{k}"], ".4f") for k in ("max", "min", "mean", "std")))
    print("  |weight| max/min/mean/std " + " ".join(
        _f(st[f"weight_{k}"], ".4f") for k in ("max", "min", "mean", "std")))
    print(f"  learned with       update={c['update']} pruning={c['pruning']} "
          f"decay={c['decay']} polish={c['polish']} passes={c['passes']}")


def _show_reconstruct(d: dict[str, Any], args: argparse.Namespace) -> None:
    print(f"wrote {d['output']}: {d['vertices']:,} vertices, {d['faces']:,} faces")


def _show_fill_grid(d: dict[str, Any], args: argparse.Namespace) -> None:
    skipped = [h for h in d["holes"] if not h["filled"]]
    if "lattice" in d:
        lat = d["lattice"]
        what, how = ("point cloud", f", meshed on it ({lat['scan_faces']:,} triangles) and "
                     "filled") if lat.get("points_only") else ("mesh", "; filled on it")
        print(f"{args.scan}: a depth frame's {what}: its vertices on a {lat['cols']} x "
              f"{lat['rows']} pixel lattice (fx {lat['fx']:.4g}, fy {lat['fy']:.4g}){how} "
              "as a depth image (--as-mesh: in the view plane)")
    print(f"{args.scan}: {d['holes_found']} holes found (no-data regions open to the border "
          f"left as they are: {d['border_cells']:,} cells), {d['holes_filled']} filled, "
          f"{len(skipped)} skipped")
    shown = d["holes"][:12]
    for h in shown:
        how = {"far": " from the far side of a depth edge",
               "both": " from both sides of a depth edge",
               "membrane": " (a membrane of the values around it)"}.get(h.get("side"), "")
        state = f"filled{how}" if h["filled"] else f"skipped: {h['reason']}"
        print(f"  hole {h['index']:>4}  {h['cells']:>7,} cells  size {h['size_abs']:9.4g} "
              f"({h['size_pct']:5.2f} % of diagonal)  {state}")
    if len(d["holes"]) > len(shown):
        rest = d["holes"][len(shown):]
        print(f"  ... {len(rest):,} smaller holes ({sum(h['cells'] for h in rest):,} cells, "
              f"{sum(not h['filled'] for h in rest)} skipped)")
    extra = f" and {d['mask']}" if d.get("mask") else ""
    added = (f" (+{d['vertices_added']:,} vertices, +{d['faces_added']:,} faces, added "
             "vertices have quality 1)" if "lattice" in d else "")
    print(f"wrote {d['output']}{extra}: {d['cells_filled']:,} cells filled{added} in "
          f"{d['seconds']:.2f} s (fit {d['fit_seconds']:.2f} s)")


def _show_fill_holes(d: dict[str, Any], args: argparse.Namespace) -> None:
    if "cells_filled" in d:
        _show_fill_grid(d, args)
        return
    if d.get("frame") == "camera":
        print(f"{args.scan}: a depth camera's data (a perspective view from the origin, which "
              "the view plane folds over): filled in the camera's frame, hole sizes in the "
              "image at the median depth (--as-mesh: in the view plane)")
    print(f"{args.scan}: {d['holes_found']} holes found (outer border left open), "
          f"{d['holes_filled']} filled, {len(d['holes_skipped'])} skipped")
    for h in d["holes"]:
        state = "filled" if h["filled"] else f"skipped: {h['reason']}"
        print(f"  hole {h['index']:>3}  size {h['size_abs']:9.4g} ({h['size_pct']:5.2f} % of "
              f"diagonal)  rim {h['rim_vertices']:>5}  +{h['vertices_added']} vertices  {state}")
    print(f"wrote {d['output']}: +{d['vertices_added']:,} vertices, +{d['faces_added']:,} faces "
          f"(added vertices have quality 1) in {d['seconds']:.2f} s")


def _show_lod(d: dict[str, Any], args: argparse.Namespace) -> None:
    print(f"{args.scan}: {len(d['levels'])} levels ({args.method}) -> "
          f"{args.output}/manifest.json")
    for lv in d["levels"]:
        err = (f"RMS {lv['rms_pct']:.3f} %  Hausdorff {lv['hausdorff_pct']:.2f} %"
               if lv.get("rms_pct") is not None else "")
        print(f"  level {lv['index']}  {lv['faces']:>9,} faces  {lv['bytes'] / 1024:8.1f} KB  "
              f"{err}")
    for q in d.get("qem") or []:
        err = (f"RMS {q['rms_pct']:.3f} %  Hausdorff {q['hausdorff_pct']:.2f} %"
               if q.get("rms_pct") is not None else "")
        print(f"  qem {q['method']:<20} {q['faces']:>9,} faces  {q['bytes'] / 1024:8.1f} KB  "
              f"{err}")


def _show_metro(d: dict[str, Any], args: argparse.Namespace) -> None:
    print(f"{args.mesh} vs {args.reference} (reference diagonal {d['diagonal']:.6g})")
    rows = [("symmetric", d["hausdorff"], d["mean"], d["rms"], d["n_samples"])]
    rows += [(name, r["max"], r["mean"], r["rms"], r["n_samples"]) for name, r in
             (("mesh -> reference", d["a_to_b"]), ("reference -> mesh", d["b_to_a"])) if r]
    print(f"  {'':<18} {'Hausdorff':>12} {'mean':>12} {'RMS':>12} {'samples':>9}")
    for name, h, m, r, n in rows:
        print(f"  {name:<18} {h:12.5g} {m:12.5g} {r:12.5g} {n:9,}")
    print(f"  % of diagonal      {_f(d['hausdorff_pct'], '12.4f'):>12} "
          f"{_f(d['mean_pct'], '12.4f'):>12} {_f(d['rms_pct'], '12.4f'):>12}")
    for x in (args.error_mesh, args.samples_out):
        if x:
            print(f"  wrote {x}")


def _show_compare(d: dict[str, Any], args: argparse.Namespace) -> None:
    print(f"{args.scan}: {d['n_points']:,} points, {d['n_neurons']:,} neurons; "
          f"SOM {d['som_shape'][0]}x{d['som_shape'][1]} ({d['som_nodes']:,} nodes)")
    print(f"  {'':<8} {'Hausdorff %':>12} {'mean %':>10} {'RMS %':>10}")
    for name, key in (("ASRBF", "asrbf"), ("SOM", "som")):
        m = d[key]
        print(f"  {name:<8} {m['hausdorff_pct']:12.4f} {m['mean_pct']:10.4f} "
              f"{m['rms_pct']:10.4f}")
    for r in d.get("holes") or []:
        print(f"  holes: {r['method']:<38} RMS {r['rms_pct']:.4f} %  {r['seconds']:.2f} s")
    print(f"  wrote {d['files']['html']} and {d['files']['markdown']}")


def _show_report(d: dict[str, Any], args: argparse.Namespace) -> None:
    out = Path(args.output)
    print((out / "summary.md").read_text(encoding="utf-8"))
    print(f"wrote {out / 'summary.html'}")


def _show_filter_script(d: dict[str, Any], args: argparse.Namespace) -> None:
    print(f"ran {len(d['steps'])} steps of {args.script} on {args.input}; "
          f"wrote {args.output} ({d['saved']['vertices']:,} vertices, "
          f"{d['saved']['faces']:,} faces) in {d['seconds']:.2f} s")


#: argparse destinations that are not options of the task.
_NOT_OPTIONS = ("command", "run", "show", "json")


def _task_kwargs(args: argparse.Namespace, command: str, quiet: bool) -> dict[str, Any]:
    """Return the namespace of a command as keyword arguments of its task function."""
    kwargs = {k: v for k, v in vars(args).items() if k not in _NOT_OPTIONS
              and not (k == "range_options" and v is None)}
    if "progress" in inspect.signature(_tasks().COMMANDS[command]).parameters:
        kwargs["progress"] = False if quiet else None
    return kwargs


def _run_task(args: argparse.Namespace) -> int:
    result = _tasks().COMMANDS[args.command](**_task_kwargs(args, args.command, args.json))
    if args.json:
        print(strict_json(result, indent=1) if args.command == "report"
              else strict_json(result))
    else:
        args.show(result, args)
    return 0


def _cmd_demo(args: argparse.Namespace) -> int:
    from ._io import face_map_path

    print(f"asrbf-mesh {__version__} demo: the face range map shipped with pymeshlab\n  "
          f"{face_map_path()}")
    d = _tasks().demo(args.output, seed=args.seed)
    _print_summary(d)
    print(f"  wrote {d['network']} ({d['network_bytes']:,} bytes)")
    print(f"  wrote {d['footprint_mesh']} ({d['footprint_vertices']:,} vertices, footprint of "
          "the scan)")
    print(f"  wrote {d['full_mesh']} ({d['full_vertices']:,} vertices, whole normalized square)")
    from numba.core import config

    from ._prebuilt import LEVELS

    if config.CPU_NAME in LEVELS:
        print(f"  (kernels: the shipped {config.CPU_NAME} set, compiled ahead of time)")
    else:
        print("  (the first run on a machine compiles the numba kernels, about 10 s before the "
              "fit, into a per-user cache: later runs, and other installs of this version, "
              "start at once)")
    return 0


# --------------------------------------------------------------------------- batch


class _OptionsParser(argparse.ArgumentParser):
    """A parser of ``--task-options``: errors raise ConfigError instead of exiting."""

    def error(self, message: str) -> NoReturn:
        hint = " (batch sets it: use --seeds / -o)" if any(
            f in message.split() for f in ("--seed", "-o", "--output")) else ""
        raise ConfigError(f"--task-options: {message}{hint}")

    def exit(self, status: int = 0, message: str | None = None) -> NoReturn:
        raise ConfigError(f"--task-options: {(message or '').strip() or 'not an option'}")


def task_options(task: str, text: str) -> dict[str, Any]:
    """Parse and validate ``--task-options`` of ``asrbf batch --task TASK`` into task kwargs.

    The options are those of ``asrbf TASK`` less the ones a batch sets itself (the scan,
    ``-o``, ``--seed``, ``--json``). Raises :class:`ConfigError` naming a bad option.
    """
    p = _OptionsParser(prog=f"asrbf batch --task {task} --task-options", add_help=False,
                       exit_on_error=False)
    _TASK_OPTIONS[task](p, False)
    try:
        tokens = shlex.split(text)
    except ValueError as exc:
        raise ConfigError(f"--task-options: {exc}") from None
    try:
        ns = p.parse_args(tokens)
    except argparse.ArgumentError as exc:
        p.error(str(exc))
    return _tasks().check_options(task, **_task_kwargs(ns, task, quiet=True))


def _cmd_batch(args: argparse.Namespace) -> int:
    from . import _batch as batch

    options = task_options(args.task, args.task_options)
    out = check_output_dir(args.output)
    jobs = batch.plan_jobs(batch.expand_inputs(args.inputs), out, args.task,
                           batch.parse_seeds(args.seeds), options)
    res = batch.run_batch(jobs, workers=args.workers, scheduler=args.scheduler,
                          skip_existing=args.skip_existing,
                          tasks_per_worker=args.tasks_per_worker,
                          progress=True if args.progress else None if not args.json else False)
    summary = res.to_dict()
    table = batch.summary_table(res)
    out.mkdir(parents=True, exist_ok=True)
    with atomic_path(out / "summary.json") as tmp:
        tmp.write_text(strict_json(summary, indent=1))
    with atomic_path(out / "summary.md") as tmp:
        tmp.write_text(f"# asrbf batch --task {args.task}\n\n{table}\n")
    if args.json:
        print(strict_json(summary))
    else:
        print(table)
    return 1 if res.failed else 0


def _fit_options(f: argparse.ArgumentParser, full: bool = True) -> None:
    if full:
        f.add_argument("scan", help="scan file (PLY, OBJ, OFF, STL, XYZ/PTS/TXT, NPY; depth "
                                    "image PNG/TIFF, GeoTIFF, NPZ grid, LAS/LAZ)")
        f.add_argument("-o", "--output", required=True, help="output network file (.asrbf)")
    f.add_argument("--float32", action="store_true", help="store parameters in single precision")
    if full:
        f.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    f.add_argument("--stream", action="store_true",
                   help="read the scan in blocks instead of loading it: memory O(K + block) "
                        "for scans larger than memory (NPY, binary PLY, XYZ)")
    f.add_argument("--chunk", type=int, default=None,
                   help="--stream: points per block, a multiple of 8192 [default: 65536]")
    f.add_argument("--mix", type=int, default=None,
                   help="--stream: blocks learned together in a random order [default: 16]")
    _add_pieces(f, " (a --stream fit is always one network)")
    _add_range(f)
    _add_learning(f, full)


def _fill_holes_options(h: argparse.ArgumentParser, full: bool = True) -> None:
    if full:
        h.add_argument("scan", help="scan file (a range grid / mesh, or a bare point cloud)")
        h.add_argument("-o", "--output", required=True,
                       help="repaired mesh (PLY, OBJ, OFF, STL); for a depth image or "
                            "elevation grid also the same kind of file (PNG, TIFF, NPY, NPZ), "
                            "for LAS/LAZ a LAS/LAZ file")
    h.add_argument("--network", help="a network fitted to this scan (fitted here if omitted)")
    h.add_argument("--max-hole-size", default=None,
                   help="fill only holes up to this size: a length in scan units or a "
                        "percentage of the bounding-box diagonal, e.g. 5%% [default: all]")
    h.add_argument("--blend", choices=BLENDS, default="thin-plate",
                   help="thin-plate: a thin plate of the points around the hole over their "
                        "own plane (the network's substrate where that plane does not suit); "
                        "harmonic: substrate + harmonic rim residuals [default: thin-plate]")
    h.add_argument("--lowpass-rel", type=float, default=1.0,
                   help="where the substrate fills a hole, only neurons at least this many "
                        "times as wide as the hole; 0 keeps every neuron [default: 1]")
    h.add_argument("--mask", help="gridded input: also write a mask image of the filled "
                                  "cells (uint8, 255 = filled)")
    h.add_argument("--as-mesh", dest="lattice", action="store_false",
                   help="a mesh or point cloud made from one depth frame (vertices on a "
                        "pixel lattice) is filled on that lattice, as its depth image, and a "
                        "depth camera's mesh or point cloud off its lattice in the camera's "
                        "frame; this fills any of them as any mesh, in the view plane")
    _add_pieces(h, " (for the fit made here)")
    _add_range(h)
    if full:
        h.add_argument("--seed", type=int, default=0, help="seed of the fit [default: 0]")
        h.add_argument("--json", action="store_true", help="print a JSON summary on stdout")


def _lod_options(lo: argparse.ArgumentParser, full: bool = True) -> None:
    if full:
        lo.add_argument("scan", help="scan file (a range grid / mesh, or a point cloud)")
        lo.add_argument("-o", "--output", required=True, help="output folder")
    lo.add_argument("--levels", type=int, default=4, help="number of levels [default: 4]")
    lo.add_argument("--method", choices=("resample", "refit"), default="resample",
                    help="resample: one network on coarser grids; refit: one fit per level "
                         "with D_min = 0.01 x 2^i [default: resample]")
    lo.add_argument("--compare-qem", action="store_true",
                    help="also decimate the scan mesh to the same face counts (fast-"
                         "simplification and pymeshlab quadric edge collapse)")
    lo.add_argument("--no-metro", dest="metro", action="store_false",
                    help="skip the Metro error measures")
    lo.add_argument("--fill-holes", action="store_true",
                    help="also mesh the holes the scan encloses (the network's surface "
                         "over them) [default: the scan's surface only, holes open]")
    _add_pieces(lo)
    _add_range(lo)
    if full:
        lo.add_argument("--seed", type=int, default=0)
        lo.add_argument("--json", action="store_true", help="print the manifest on stdout")


def _compare_options(c: argparse.ArgumentParser, full: bool = True) -> None:
    if full:
        c.add_argument("scan", help="scan file with faces (range grid or mesh)")
        c.add_argument("-o", "--output", required=True, help="output folder")
    c.add_argument("--network", help="a network fitted to this scan (fitted here if omitted)")
    c.add_argument("--holes", action="store_true",
                   help="also the punched-hole benchmark (ours, TPS, Close Holes, Poisson)")
    c.add_argument("--lod", action="store_true",
                   help="also a 4-level LOD set with the quadric-decimation comparison")
    c.add_argument("--no-meshes", dest="meshes", action="store_false",
                   help="do not write the two meshes")
    c.add_argument("--som-iterations", type=int, metavar="N",
                   help="SOM training steps (default 500 per node; fewer run faster)")
    _add_pieces(c, " (for the fit made here)")
    _add_range(c)
    if full:
        c.add_argument("--seed", type=int, default=0)
        c.add_argument("--json", action="store_true", help="print the results as JSON")


#: Options of the tasks a batch runs (``full=False``: without scan, -o, --seed, --json).
_TASK_OPTIONS = {"fit": _fit_options, "fill-holes": _fill_holes_options, "lod": _lod_options,
                 "compare": _compare_options}


def build_parser() -> argparse.ArgumentParser:
    """Build the argument parser of the ``asrbf`` command."""
    p = argparse.ArgumentParser(
        prog="asrbf", description="Adaptive sequential learning RBF networks for range scans.")
    p.add_argument("--version", action="version", version=f"asrbf-mesh {__version__}")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")

    f = sub.add_parser("fit", help="fit a network to a scan and save it (.asrbf)")
    _fit_options(f)
    f.set_defaults(run=_run_task, show=_show_fit)

    i = sub.add_parser("info", help="describe a network file")
    i.add_argument("network")
    i.add_argument("--json", action="store_true")
    i.set_defaults(run=_run_task, show=_show_info)

    r = sub.add_parser("reconstruct", help="mesh the network surface on a grid")
    r.add_argument("network")
    r.add_argument("-o", "--output", required=True, help="output mesh (PLY, OBJ, OFF, STL)")
    g = r.add_mutually_exclusive_group()
    g.add_argument("--resolution", type=int, help="samples along the longer side")
    g.add_argument("--spacing", type=float, help="grid spacing in scan units")
    r.add_argument("--footprint", help="the scan whose footprint limits the mesh")
    r.add_argument("--mode", choices=FOOTPRINT_MODES, default=None,
                   help="surface: the cells with data (holes stay open); scan: those plus "
                        "the holes they enclose; hull: a concave hull of the points; full: "
                        "the whole normalized square [default: surface with --footprint, "
                        "else full]")
    r.add_argument("--margin", type=float, default=0.0,
                   help="mode full: extend the square by this fraction per side [default: 0]")
    r.add_argument("--json", action="store_true")
    _add_range(r)
    r.set_defaults(run=_run_task, show=_show_reconstruct)

    h = sub.add_parser("fill-holes", help="fill the holes of a scan from its network")
    _fill_holes_options(h)
    h.set_defaults(run=_run_task, show=_show_fill_holes)

    lo = sub.add_parser("lod", help="write a level-of-detail mesh set with a manifest")
    _lod_options(lo)
    lo.set_defaults(run=_run_task, show=_show_lod)

    m = sub.add_parser("metro", help="Metro distances between a mesh and a reference scan")
    m.add_argument("mesh", help="the mesh under test (PLY, OBJ, OFF, STL)")
    m.add_argument("reference", help="the reference: a mesh, or a point cloud (then only "
                                     "reference -> mesh is measured)")
    m.add_argument("--samples", type=int, default=None,
                   help="area samples per direction [default: max(4 x vertices, 10000)]")
    m.add_argument("--seed", type=int, default=0, help="seed of the area sampling [0]")
    m.add_argument("--error-mesh", help="write the mesh with its per-vertex distance to the "
                                        "reference as vertex quality (view it in MeshLab)")
    m.add_argument("--samples-out", help="write every sample and its distance (.npz)")
    m.add_argument("--json", action="store_true", help="print the result as JSON")
    _add_range(m)
    m.set_defaults(run=_run_task, show=_show_metro)

    c = sub.add_parser("compare", help="our reconstruction vs the SOM baseline (and holes, "
                                       "LOD): tables, plots, HTML + Markdown report")
    _compare_options(c)
    c.set_defaults(run=_run_task, show=_show_compare)

    rp = sub.add_parser("report", help="one page over several `asrbf compare` results")
    rp.add_argument("inputs", nargs="+", help="compare output folders (or compare.json files)")
    rp.add_argument("-o", "--output", required=True, help="output folder")
    rp.add_argument("--json", action="store_true", help="print the summary as JSON")
    rp.set_defaults(run=_run_task, show=_show_report)

    fs = sub.add_parser("filter-script", help="run a JSON list of pymeshlab and asrbf filters")
    fs.add_argument("script", help="JSON list of steps: {\"filter\": NAME, \"params\": {...}}")
    fs.add_argument("input", help="mesh or scan file (loaded by pymeshlab)")
    fs.add_argument("-o", "--output", required=True, help="where the current mesh is saved")
    fs.add_argument("--json", action="store_true", help="print the run as JSON")
    fs.set_defaults(run=_run_task, show=_show_filter_script)

    b = sub.add_parser("batch", help="run fit / fill-holes / lod / compare over many scans "
                                     "on dask.distributed")
    b.add_argument("inputs", nargs="+", metavar="INPUT",
                   help="scan files, folders of scans or glob patterns")
    b.add_argument("-o", "--output", required=True, help="output folder (one folder per job)")
    b.add_argument("--task", choices=("fit", "fill-holes", "lod", "compare"), default="fit")
    b.add_argument("--workers", type=int, default=min(2, os.cpu_count() or 1),
                   help="worker processes of the local cluster, one thread each "
                        "[default: min(2, cores)]")
    b.add_argument("--scheduler", metavar="tcp://HOST:PORT",
                   help="use a running dask scheduler instead of a local cluster")
    b.add_argument("--seeds", default="0",
                   help="seeds to run every file with: 0, 0,3,5 or 0-7 [default: 0]")
    b.add_argument("--skip-existing", action="store_true",
                   help="skip jobs whose record.json says ok and whose outputs exist")
    b.add_argument("--tasks-per-worker", type=int, default=50,
                   help="restart a worker after this many tasks [default: 50]")
    b.add_argument("--progress", action="store_true", help="progress bar even off a terminal")
    b.add_argument("--json", action="store_true", help="print the summary as JSON")
    b.add_argument("--task-options", default="", metavar="'OPTIONS'",
                   help="options for every task, quoted, e.g. '--levels 3 --compare-qem'")
    b.set_defaults(run=_cmd_batch)

    d = sub.add_parser("demo", help="fit the face range map shipped with pymeshlab")
    d.add_argument("-o", "--output", default="asrbf-demo", help="output folder [asrbf-demo]")
    d.add_argument("--seed", type=int, default=0)
    d.set_defaults(run=_cmd_demo)
    return p


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    print(f"asrbf: warning: {message}", file=sys.stderr)


class _Terminated(BaseException):
    """SIGTERM, raised as an exception so that partial outputs are removed on the way out."""


def _terminate(signum: int, frame: Any) -> None:
    raise _Terminated


def _chain(exc: BaseException) -> Iterator[BaseException]:
    """Yield an exception, its causes and contexts (numba wraps interrupts in SystemError)."""
    seen: set[int] = set()
    e: BaseException | None = exc
    while e is not None and id(e) not in seen:
        seen.add(id(e))
        yield e
        e = e.__cause__ or e.__context__


def _exit_code(exc: BaseException) -> int | None:
    """Print the one line for ``exc`` and return the exit code; None: not ours (re-raise)."""
    chain = list(_chain(exc))
    if any(isinstance(e, _Terminated) for e in chain):
        print("asrbf: terminated", file=sys.stderr)
        return 128 + signal.SIGTERM
    if any(isinstance(e, KeyboardInterrupt) for e in chain):
        print("asrbf: interrupted", file=sys.stderr)
        return 130
    if isinstance(exc, AsrbfError):
        print(f"asrbf: error: {exc}", file=sys.stderr)
        return 2
    if isinstance(exc, BrokenPipeError):  # output piped into head & co.
        return 0
    if isinstance(exc, MemoryError):
        print("asrbf: error: out of memory (the input is too large for this machine; a fit "
              "needs about 120 bytes per point, see 'Memory of a fit' in BENCHMARKS.md)",
              file=sys.stderr)
        return 1
    return None


def _flags(parser: argparse.ArgumentParser, command: str | None) -> dict[str, str]:
    """Map the options of sub-command ``command`` to their flags (``seed`` -> ``--seed``)."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction) and command in action.choices:
            return {a.dest: a.option_strings[-1] for a in action.choices[command]._actions
                    if a.option_strings and a.dest != "help"}
    return {}


def _named_as_flag(exc: ConfigError, flags: dict[str, str]) -> ConfigError:
    """Name a parameter the way the command line spells it: ``seed`` -> ``--seed``."""
    text = str(exc)
    first = text.split(" ", 1)[0]
    if first in flags and " " in text:
        return ConfigError(f"{flags[first]} {text.split(' ', 1)[1]}")
    return exc


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``asrbf`` command; returns the exit code."""
    parser = build_parser()
    args = parser.parse_args(argv)
    handler = None
    if threading.current_thread() is threading.main_thread():
        handler = signal.signal(signal.SIGTERM, _terminate)
    try:
        with warnings.catch_warnings(), _warm.alongside(getattr(args, "command", None)):
            warnings.showwarning = _show_warning
            return int(args.run(args))
    except (Exception, KeyboardInterrupt, _Terminated) as exc:
        if type(exc) is ConfigError:
            exc = _named_as_flag(exc, _flags(parser, getattr(args, "command", None)))
        code = _exit_code(exc)
        if code is None:
            raise
        return code
    finally:
        if handler is not None:
            signal.signal(signal.SIGTERM, handler)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
