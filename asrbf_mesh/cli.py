"""The ``asrbf`` command: fit, info, reconstruct, fill-holes, lod, metro, compare, report, demo.

Errors a user can cause print one line on stderr and exit with code 2; an
unexpected bug exits with code 1 and a traceback.
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import signal
import sys
import threading
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from . import __version__
from ._atomic import atomic_path, check_output_dir, check_output_path
from ._config import DECAYS, POLISHES, PRUNINGS, UPDATES, FitConfig
from ._frame import VIEW_AXES
from ._holes import BLENDS, fill_holes
from ._io import face_map_path, load_scan, save_mesh
from ._learn import fit
from ._lod import lod_set
from ._network import FORMAT_VERSION, Network
from ._surface import FOOTPRINT_MODES, reconstruct
from .errors import AsrbfError

__all__ = ["main", "build_parser"]

# FitConfig field -> (flag, type, help naming the paper's symbol)
_LEARNING_OPTIONS: list[tuple[str, str, type, str]] = [
    ("error_threshold", "--error-threshold", float, "E, local error threshold (criterion 2)"),
    ("rms_threshold", "--rms-threshold", float, "E_omega, windowed RMS threshold (criterion 3)"),
    ("d_max", "--d-max", float, "D_max, initial neuron separation (criterion 1)"),
    ("d_min", "--d-min", float, "D_min, neuron separation level (default: 2 x scan spacing)"),
    ("gamma", "--gamma", float, "gamma, decay factor of the separation distance, eq. (4)"),
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
    ("decay", "--decay", DECAYS, "index of eq. (4): observation count or neuron count"),
    ("polish", "--polish", POLISHES, "batch stage after learning ('none' is the paper)"),
]


def _add_learning(p: argparse.ArgumentParser) -> None:
    d = FitConfig()
    g = p.add_argument_group("learning parameters (unit cube; paper section 5.1 defaults)")
    for field, flag, typ, text in _LEARNING_OPTIONS:
        g.add_argument(flag, dest=field, type=typ, default=None,
                       help=f"{text} [default: {getattr(d, field)}]")
    for field, flag, choices, text in _CHOICE_OPTIONS:
        g.add_argument(flag, dest=field, choices=choices, default=None,
                       help=f"{text} [default: {getattr(d, field)}]")
    p.add_argument("--seed", type=int, default=0, help="random order seed [default: 0]")
    p.add_argument("--view-axis", choices=VIEW_AXES, default="z",
                   help="depth direction of the height field [default: z]")


def _config(args: argparse.Namespace) -> FitConfig:
    fields = [f for f, *_ in _LEARNING_OPTIONS] + [f for f, *_ in _CHOICE_OPTIONS]
    changes = {f: getattr(args, f) for f in fields if getattr(args, f) is not None}
    return FitConfig().replace(**changes)


def _fit_summary(net: Network) -> dict[str, Any]:
    info = net.info
    n = int(info["n_points"])
    return {
        "n_points": n,
        "n_neurons": net.n_neurons,
        "ebar": info["ebar"],
        "ebar_sequential": info["ebar_sequential"],
        "n_to_k": net.compression_ratio(n),
        "storage_ratio": net.storage_ratio(n),
        "error_mean": info["error_mean"],
        "error_std": info["error_std"],
        "steps": info["steps"],
        "fit_seconds": info["fit_seconds"],
        "learn_seconds": info["learn_seconds"],
        "polish_seconds": info["polish_seconds"],
        "us_per_step": info["us_per_step"],
        "d_min": info["d_min"],
        "seed": info["seed"],
        "polish": net.config.polish,
        "added": net.log.added if net.log else None,
        "pruned": net.log.pruned if net.log else None,
    }


def _print_summary(s: dict[str, Any], out=None) -> None:
    out = out or sys.stdout
    rows = [
        ("points N", f"{s['n_points']:,}"),
        ("neurons K", f"{s['n_neurons']:,}  (added {s['added']:,}, pruned {s['pruned']:,})"),
        ("E-bar (unit cube)", f"{s['ebar']:.5f}  (sequential {s['ebar_sequential']:.5f}, "
                              f"polish {s['polish']})"),
        ("N:K", f"{s['n_to_k']:.1f}:1"),
        ("3N:4K", f"{s['storage_ratio']:.1f}:1"),
        ("error (scan units)", f"mean {s['error_mean']:.4g}, std {s['error_std']:.4g}"),
        ("fit time", f"{s['fit_seconds']:.2f} s  ({s['steps']:,} steps, "
                     f"{s['us_per_step']:.2f} us/step, polish {s['polish_seconds']:.2f} s)"),
    ]
    w = max(len(k) for k, _ in rows)
    for k, v in rows:
        print(f"  {k:<{w}}  {v}", file=out)


def _cmd_fit(args: argparse.Namespace) -> int:
    cfg = _config(args)
    out = Path(args.output)
    if out.suffix.lower() != ".asrbf":
        raise AsrbfError(f"{out}: a network file must end in .asrbf")
    if args.stream:
        from ._stream import open_points

        open_points(args.scan, args.chunk)  # the input's errors first
    else:
        scan = load_scan(args.scan)
    check_output_path(out, args.scan)  # before the fit, not after it
    if args.stream:
        from ._stream import fit_stream

        net = fit_stream(args.scan, cfg, seed=args.seed, view_axis=args.view_axis,
                         chunk=args.chunk, mix=args.mix,
                         progress=None if not args.json else False)
    else:
        net = fit(scan, cfg, seed=args.seed, view_axis=args.view_axis,
                  progress=None if not args.json else False)
    net.save(out, float32=args.float32, inputs=(args.scan,))
    summary = _fit_summary(net) | {"output": str(out)}
    if args.json:
        print(json.dumps(summary))
    else:
        print(f"fitted {args.scan} -> {out}")
        _print_summary(summary)
    return 0


def _cmd_info(args: argparse.Namespace) -> int:
    net = Network.load(args.network)
    st = net.stats()
    data = {"n_neurons": net.n_neurons, "format_version": FORMAT_VERSION,
            "config": net.config.to_dict(), "frame": net.frame.to_dict(),
            "stats": st.__dict__, "info": net.info,
            "log": net.log.counters() if net.log else None}
    if args.json:
        print(json.dumps(data))
        return 0
    print(f"{args.network}: ASRBF network, format version {FORMAT_VERSION}")
    print(f"  neurons K          {net.n_neurons:,}")
    if "n_points" in net.info:
        n = net.info["n_points"]
        print(f"  fitted on N        {n:,} points  (N:K {net.compression_ratio():.1f}:1, "
              f"3N:4K {net.storage_ratio():.1f}:1)")
    if "ebar" in net.info:
        print(f"  E-bar              {net.info['ebar']:.5f}")
    print(f"  width  max/min/mean/std   {st.width_max:.4f} {st.width_min:.4f} "
          f"{st.width_mean:.4f} {st.width_std:.4f}")
    print(f"  |weight| max/min/mean/std {st.weight_max:.4f} {st.weight_min:.4f} "
          f"{st.weight_mean:.4f} {st.weight_std:.4f}")
    c = net.config
    print(f"  learned with       update={c.update} pruning={c.pruning} decay={c.decay} "
          f"polish={c.polish} passes={c.passes}")
    return 0


def _cmd_reconstruct(args: argparse.Namespace) -> int:
    net = Network.load(args.network)
    footprint = load_scan(args.footprint) if args.footprint else None
    mesh = reconstruct(net, resolution=args.resolution, spacing_abs=args.spacing,
                       footprint=footprint, mode=args.mode, margin_rel=args.margin)
    save_mesh(mesh, args.output, overwrite_inputs=(args.network, args.footprint))
    if args.json:
        print(json.dumps({"output": args.output, "vertices": mesh.n_vertices,
                          "faces": mesh.n_faces}))
    else:
        print(f"wrote {args.output}: {mesh.n_vertices:,} vertices, {mesh.n_faces:,} faces")
    return 0


def _cmd_fill_holes(args: argparse.Namespace) -> int:
    scan = load_scan(args.scan)
    out = check_output_path(args.output, args.scan, args.network)
    net = Network.load(args.network) if args.network else None
    lowpass = None if args.lowpass_rel <= 0 else args.lowpass_rel
    res = fill_holes(scan, net, max_hole_size=args.max_hole_size, blend=args.blend,
                     lowpass_rel=lowpass, seed=args.seed,
                     progress=None if not args.json else False)
    save_mesh(res.mesh, out, overwrite_inputs=(args.scan, args.network))
    if args.json:
        print(json.dumps(res.to_dict() | {"output": str(out)}))
        return 0
    print(f"{args.scan}: {res.holes_found} holes found (outer border left open), "
          f"{res.holes_filled} filled, {len(res.holes_skipped)} skipped")
    for h in res.holes:
        state = "filled" if h.filled else f"skipped: {h.reason}"
        print(f"  hole {h.index:>3}  size {h.size_abs:9.4g} ({h.size_pct:5.2f} % of diagonal)  "
              f"rim {h.rim_vertices:>5}  +{h.vertices_added} vertices  {state}")
    print(f"wrote {out}: +{res.vertices_added:,} vertices, +{res.faces_added:,} faces "
          f"(added vertices have quality 1) in {res.seconds:.2f} s")
    return 0


def _cmd_lod(args: argparse.Namespace) -> int:
    from .evaluate import write_lod_set

    scan = load_scan(args.scan)
    check_output_dir(args.output)
    levels = lod_set(scan, levels=args.levels, method=args.method, seed=args.seed)
    manifest = write_lod_set(scan, levels, args.output, compare_qem=args.compare_qem,
                             metro=not args.no_metro)
    if args.json:
        print(json.dumps(manifest))
        return 0
    print(f"{args.scan}: {len(levels)} levels ({args.method}) -> {args.output}/manifest.json")
    for lv in manifest["levels"]:
        err = (f"RMS {lv['rms_pct']:.3f} %  Hausdorff {lv['hausdorff_pct']:.2f} %"
               if lv.get("rms_pct") is not None else "")
        print(f"  level {lv['index']}  {lv['faces']:>9,} faces  {lv['bytes'] / 1024:8.1f} KB  "
              f"{err}")
    for q in manifest.get("qem") or []:
        err = (f"RMS {q['rms_pct']:.3f} %  Hausdorff {q['hausdorff_pct']:.2f} %"
               if q.get("rms_pct") is not None else "")
        print(f"  qem {q['method']:<20} {q['faces']:>9,} faces  {q['bytes'] / 1024:8.1f} KB  "
              f"{err}")
    return 0


def _cmd_metro(args: argparse.Namespace) -> int:
    from .evaluate._metro import metro

    a, b = load_scan(args.mesh), load_scan(args.reference)
    outs = [x for x in (args.error_mesh, args.samples_out) if x]
    for x in outs:
        check_output_path(x, args.mesh, args.reference)
    if args.samples_out and not args.samples_out.lower().endswith(".npz"):
        raise AsrbfError(f"{args.samples_out}: the samples file must end in .npz")
    if args.error_mesh and b.faces is None:
        raise AsrbfError(f"{args.reference}: a point cloud without faces; --error-mesh needs "
                         "a mesh reference (point distances measure the cloud's gaps)")
    res = metro(a, b if b.faces is not None else b.points, samples=args.samples,
                seed=args.seed, per_sample=bool(outs))
    if args.error_mesh:
        save_mesh(res.error_mesh(), args.error_mesh, overwrite_inputs=(args.mesh,
                                                                       args.reference))
    if args.samples_out:
        from ._atomic import atomic_path

        arrays = {f"{name}_{k}": getattr(d, k) for name, d in
                  (("a_to_b", res.a_to_b), ("b_to_a", res.b_to_a)) if d is not None
                  for k in ("points", "distances")}
        with atomic_path(args.samples_out) as tmp, open(tmp, "wb") as fh:
            np.savez_compressed(fh, **arrays)
    if args.json:
        print(json.dumps(res.to_dict() | {"mesh": args.mesh, "reference": args.reference}))
        return 0
    print(f"{args.mesh} vs {args.reference} (reference diagonal {res.diagonal:.6g})")
    rows = [("symmetric", res.hausdorff, res.mean, res.rms, res.n_samples)]
    rows += [(name, d.max, d.mean, d.rms, d.n_samples) for name, d in
             (("mesh -> reference", res.a_to_b), ("reference -> mesh", res.b_to_a)) if d]
    print(f"  {'':<18} {'Hausdorff':>12} {'mean':>12} {'RMS':>12} {'samples':>9}")
    for name, h, m, r, n in rows:
        print(f"  {name:<18} {h:12.5g} {m:12.5g} {r:12.5g} {n:9,}")
    print(f"  % of diagonal      {res.hausdorff_pct:12.4f} {res.mean_pct:12.4f} "
          f"{res.rms_pct:12.4f}")
    for x in outs:
        print(f"  wrote {x}")
    return 0


def _cmd_compare(args: argparse.Namespace) -> int:
    from .evaluate._report import compare, write_compare

    scan = load_scan(args.scan)
    out = check_output_dir(args.output)
    net = Network.load(args.network) if args.network else None
    c = compare(scan, net=net, seed=args.seed, holes=args.holes, lod=args.lod,
                lod_dir=out / "lod", som_iterations=args.som_iterations,
                progress=False if args.json else None)
    paths = write_compare(c, out, meshes=not args.no_meshes)
    d = c.to_dict()
    if args.json:
        print(json.dumps(d | {"files": {k: str(v) for k, v in paths.items()}},
                         default=float))
        return 0
    print(f"{args.scan}: {d['n_points']:,} points, {d['n_neurons']:,} neurons; "
          f"SOM {d['som_shape'][0]}x{d['som_shape'][1]} ({d['som_nodes']:,} nodes)")
    print(f"  {'':<8} {'Hausdorff %':>12} {'mean %':>10} {'RMS %':>10}")
    for name, key in (("ASRBF", "asrbf"), ("SOM", "som")):
        m = d[key]
        print(f"  {name:<8} {m['hausdorff_pct']:12.4f} {m['mean_pct']:10.4f} "
              f"{m['rms_pct']:10.4f}")
    for r in d.get("holes") or []:
        print(f"  holes: {r['method']:<38} RMS {r['rms_pct']:.4f} %  {r['seconds']:.2f} s")
    print(f"  wrote {paths['html']} and {paths['markdown']}")
    return 0


def _cmd_report(args: argparse.Namespace) -> int:
    from .evaluate._report import load_compare, write_summary

    results = [load_compare(p) for p in args.inputs]
    out = check_output_dir(args.output)
    links = []
    for p in args.inputs:
        page = (Path(p) if Path(p).is_dir() else Path(p).parent) / "report.html"
        links.append(os.path.relpath(page, out) if page.exists() else None)
    paths = write_summary(results, out, links)
    if args.json:
        print(paths["json"].read_text(encoding="utf-8"))
        return 0
    print(paths["markdown"].read_text(encoding="utf-8"))
    print(f"wrote {paths['html']}")
    return 0


def _cmd_filter_script(args: argparse.Namespace) -> int:
    from meshlab_filter import run_script_file

    res = run_script_file(args.script, args.input, args.output)
    if args.json:
        print(json.dumps(res, default=str))
    else:
        print(f"ran {len(res['steps'])} steps of {args.script} on {args.input}; "
              f"wrote {args.output} ({res['saved']['vertices']:,} vertices, "
              f"{res['saved']['faces']:,} faces) in {res['seconds']:.2f} s")
    return 0


def _cmd_demo(args: argparse.Namespace) -> int:
    src = face_map_path()
    out = Path(args.output)
    out.mkdir(parents=True, exist_ok=True)
    print(f"asrbf-mesh {__version__} demo: the face range map shipped with pymeshlab\n  {src}")
    scan = load_scan(src)
    net = fit(scan, seed=args.seed, progress=None)
    net_path = net.save(out / "face.asrbf")
    fp = reconstruct(net, footprint=scan)
    full = reconstruct(net)
    p1 = save_mesh(fp, out / "face_footprint.ply")
    p2 = save_mesh(full, out / "face_full.ply")
    s = _fit_summary(net)
    _print_summary(s)
    print(f"  wrote {net_path} ({net_path.stat().st_size:,} bytes)")
    print(f"  wrote {p1} ({fp.n_vertices:,} vertices, footprint of the scan)")
    print(f"  wrote {p2} ({full.n_vertices:,} vertices, whole normalized square)")
    print("  (the first run after installing compiles the numba kernels, about 20 s, and caches "
          "them: later fits take about a second)")
    return 0


def _cmd_batch(args: argparse.Namespace) -> int:
    from . import _batch as batch

    out = check_output_dir(args.output)
    jobs = batch.plan_jobs(batch.expand_inputs(args.inputs), out, args.task,
                           batch.parse_seeds(args.seeds), shlex.split(args.task_options))
    res = batch.run_batch(jobs, workers=args.workers, scheduler=args.scheduler,
                          skip_existing=args.skip_existing,
                          tasks_per_worker=args.tasks_per_worker,
                          progress=True if args.progress else None if not args.json else False)
    summary = res.to_dict()
    table = batch.summary_table(res)
    out.mkdir(parents=True, exist_ok=True)
    with atomic_path(out / "summary.json") as tmp:
        tmp.write_text(json.dumps(summary, indent=1, default=str))
    with atomic_path(out / "summary.md") as tmp:
        tmp.write_text(f"# asrbf batch --task {args.task}\n\n{table}\n")
    if args.json:
        print(json.dumps(summary, default=str))
    else:
        print(table)
    return 1 if res.failed else 0


def build_parser() -> argparse.ArgumentParser:
    """Build the argument parser of the ``asrbf`` command."""
    p = argparse.ArgumentParser(
        prog="asrbf", description="Adaptive sequential learning RBF networks for range scans.")
    p.add_argument("--version", action="version", version=f"asrbf-mesh {__version__}")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")

    f = sub.add_parser("fit", help="fit a network to a scan and save it (.asrbf)")
    f.add_argument("scan", help="scan file (PLY, OBJ, OFF, STL, XYZ/PTS/TXT, NPY)")
    f.add_argument("-o", "--output", required=True, help="output network file (.asrbf)")
    f.add_argument("--float32", action="store_true", help="store parameters in single precision")
    f.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    f.add_argument("--stream", action="store_true",
                   help="read the scan in blocks instead of loading it: memory O(K + block) "
                        "for scans larger than memory (NPY, binary PLY, XYZ)")
    f.add_argument("--chunk", type=int, default=65_536,
                   help="--stream: points per block, a multiple of 8192 [default: 65536]")
    f.add_argument("--mix", type=int, default=16,
                   help="--stream: blocks learned together in a random order [default: 16]")
    _add_learning(f)
    f.set_defaults(func=_cmd_fit)

    i = sub.add_parser("info", help="describe a network file")
    i.add_argument("network")
    i.add_argument("--json", action="store_true")
    i.set_defaults(func=_cmd_info)

    r = sub.add_parser("reconstruct", help="mesh the network surface on a grid")
    r.add_argument("network")
    r.add_argument("-o", "--output", required=True, help="output mesh (PLY, OBJ, OFF, STL)")
    g = r.add_mutually_exclusive_group()
    g.add_argument("--resolution", type=int, help="samples along the longer side")
    g.add_argument("--spacing", type=float, help="grid spacing in scan units")
    r.add_argument("--footprint", help="the scan whose footprint limits the mesh")
    r.add_argument("--mode", choices=FOOTPRINT_MODES, default=None,
                   help="scan: cells with data plus the holes they enclose; hull: a concave "
                        "hull of the points; full: the whole normalized square "
                        "[default: scan with --footprint, else full]")
    r.add_argument("--margin", type=float, default=0.0,
                   help="mode full: extend the square by this fraction per side [default: 0]")
    r.add_argument("--json", action="store_true")
    r.set_defaults(func=_cmd_reconstruct)

    h = sub.add_parser("fill-holes", help="fill the holes of a scan from its network")
    h.add_argument("scan", help="scan file (a range grid / mesh, or a bare point cloud)")
    h.add_argument("-o", "--output", required=True, help="repaired mesh (PLY, OBJ, OFF, STL)")
    h.add_argument("--network", help="a network fitted to this scan (fitted here if omitted)")
    h.add_argument("--max-hole-size", default=None,
                   help="fill only holes up to this size: a length in scan units or a "
                        "percentage of the bounding-box diagonal, e.g. 5%% [default: all]")
    h.add_argument("--blend", choices=BLENDS, default="thin-plate",
                   help="how the scan's residual z - f crosses the hole [default: thin-plate]")
    h.add_argument("--lowpass-rel", type=float, default=1.0,
                   help="over a hole use only neurons at least this many times as wide as "
                        "the hole; 0 keeps every neuron [default: 1]")
    h.add_argument("--seed", type=int, default=0, help="seed of the fit [default: 0]")
    h.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    h.set_defaults(func=_cmd_fill_holes)

    lo = sub.add_parser("lod", help="write a level-of-detail mesh set with a manifest")
    lo.add_argument("scan", help="scan file (a range grid / mesh, or a point cloud)")
    lo.add_argument("-o", "--output", required=True, help="output folder")
    lo.add_argument("--levels", type=int, default=4, help="number of levels [default: 4]")
    lo.add_argument("--method", choices=("resample", "refit"), default="resample",
                    help="resample: one network on coarser grids; refit: one fit per level "
                         "with D_min = 0.01 x 2^i [default: resample]")
    lo.add_argument("--compare-qem", action="store_true",
                    help="also decimate the scan mesh to the same face counts (fast-"
                         "simplification and pymeshlab quadric edge collapse)")
    lo.add_argument("--no-metro", action="store_true", help="skip the Metro error measures")
    lo.add_argument("--seed", type=int, default=0)
    lo.add_argument("--json", action="store_true", help="print the manifest on stdout")
    lo.set_defaults(func=_cmd_lod)

    m = sub.add_parser("metro", help="Metro distances between a mesh and a reference scan")
    m.add_argument("mesh", help="the mesh under test (PLY, OBJ, OFF, STL)")
    m.add_argument("reference", help="the reference: a mesh, or a point cloud (then only "
                                     "reference -> mesh is measured)")
    m.add_argument("--samples", type=int, default=None,
                   help="area samples per direction [default: max(vertices, 10000)]")
    m.add_argument("--seed", type=int, default=0, help="seed of the area sampling [0]")
    m.add_argument("--error-mesh", help="write the mesh with its per-vertex distance to the "
                                        "reference as vertex quality (view it in MeshLab)")
    m.add_argument("--samples-out", help="write every sample and its distance (.npz)")
    m.add_argument("--json", action="store_true", help="print the result as JSON")
    m.set_defaults(func=_cmd_metro)

    c = sub.add_parser("compare", help="our reconstruction vs the SOM baseline (and holes, "
                                       "LOD): tables, plots, HTML + Markdown report")
    c.add_argument("scan", help="scan file with faces (range grid or mesh)")
    c.add_argument("-o", "--output", required=True, help="output folder")
    c.add_argument("--network", help="a network fitted to this scan (fitted here if omitted)")
    c.add_argument("--holes", action="store_true",
                   help="also the punched-hole benchmark (ours, TPS, Close Holes, Poisson)")
    c.add_argument("--lod", action="store_true",
                   help="also a 4-level LOD set with the quadric-decimation comparison")
    c.add_argument("--no-meshes", action="store_true", help="do not write the two meshes")
    c.add_argument("--som-iterations", type=int, metavar="N",
                   help="SOM training steps (default 500 per node; fewer run faster)")
    c.add_argument("--seed", type=int, default=0)
    c.add_argument("--json", action="store_true", help="print the results as JSON")
    c.set_defaults(func=_cmd_compare)

    rp = sub.add_parser("report", help="one page over several `asrbf compare` results")
    rp.add_argument("inputs", nargs="+", help="compare output folders (or compare.json files)")
    rp.add_argument("-o", "--output", required=True, help="output folder")
    rp.add_argument("--json", action="store_true", help="print the summary as JSON")
    rp.set_defaults(func=_cmd_report)

    fs = sub.add_parser("filter-script", help="run a JSON list of pymeshlab and asrbf filters")
    fs.add_argument("script", help="JSON list of steps: {\"filter\": NAME, \"params\": {...}}")
    fs.add_argument("input", help="mesh or scan file (loaded by pymeshlab)")
    fs.add_argument("-o", "--output", required=True, help="where the current mesh is saved")
    fs.add_argument("--json", action="store_true", help="print the run as JSON")
    fs.set_defaults(func=_cmd_filter_script)

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
    b.set_defaults(func=_cmd_batch)

    d = sub.add_parser("demo", help="fit the face range map shipped with pymeshlab")
    d.add_argument("-o", "--output", default="asrbf-demo", help="output folder [asrbf-demo]")
    d.add_argument("--seed", type=int, default=0)
    d.set_defaults(func=_cmd_demo)
    return p


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    print(f"asrbf: warning: {message}", file=sys.stderr)


class _Terminated(BaseException):
    """SIGTERM, raised as an exception so that partial outputs are removed on the way out."""


def _terminate(signum: int, frame: Any) -> None:
    raise _Terminated


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``asrbf`` command; returns the exit code."""
    args = build_parser().parse_args(argv)
    handler = None
    if threading.current_thread() is threading.main_thread():
        handler = signal.signal(signal.SIGTERM, _terminate)
    try:
        with warnings.catch_warnings():
            warnings.showwarning = _show_warning
            return int(args.func(args))
    except _Terminated:
        print("asrbf: terminated", file=sys.stderr)
        return 128 + signal.SIGTERM
    except AsrbfError as exc:
        print(f"asrbf: error: {exc}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # output piped into head & co.
        return 0
    except MemoryError:
        print("asrbf: error: out of memory (the input is too large for this machine; a fit "
              "needs about 120 bytes per point, see 'Memory of a fit' in BENCHMARKS.md)",
              file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("asrbf: interrupted", file=sys.stderr)
        return 130
    finally:
        if handler is not None:
            signal.signal(signal.SIGTERM, handler)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
