"""Piecewise model (``--pieces auto``, the default) vs the paper's single network (``1``).

Run from the repository root:  python scripts/bench_pieces.py [--seeds 0 1 2]

For the face map and the Stanford bunny scans (read from the folder named by
$ASRBF_BUNNY_DIR; skipped without it), fit each scan with each seed both ways
(``am.fit(scan, pieces=1)`` and ``am.fit(scan)``) and mesh the default reconstruction
(``am.reconstruct(net, footprint=scan)``: mode surface at the scan's spacing). Prints one
Markdown table, each cell the median over the seeds and, in brackets, the worst seed:
neurons K, N:K, E-bar (mean |f - z| in the unit cube over all N points), fit seconds,
and the 99.9th percentile and maximum of the vertex-to-surface distances of the
reconstruction both ways (scan vertices -> mesh, mesh vertices -> scan mesh), in % of
the scan's bounding-box diagonal.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _bench_common import (  # noqa: E402
    label,
    machine,
    median_worst,
    scans,
    table,
    timed,
    write_section,
)

import asrbf_mesh as am  # noqa: E402
from asrbf_mesh._igl import point_mesh_distance  # noqa: E402

#: Set by ``--scans``: scan files to read instead of the face map and the bunnies, the
#: suffix of the sections they are written to, and the option as the command shows it.
_PATHS: list[str] | None = None
_SUFFIX = ""
_CMD = ""

HEADERS = ["scan", "N", "model", "pieces", "K", "N:K", "E̅", "fit s",
           "scan→mesh 99.9 % / max", "same, samples in triangles", "mesh→scan 99.9 % / max",
           "mode scan (holes filled): mesh→scan 99.9 %",
           "seeds with fewer K and lower E̅ than single"]


def _title() -> str:
    """The sections' title suffix: what the scans are."""
    if not _SUFFIX:
        return ""
    return " on other scans" + ("" if _SUFFIX == "-views" else f" ({_SUFFIX[1:]})")


def _origin() -> str:
    """What the scans of ``--scans`` are (a paragraph), or nothing for the dev scans."""
    if not _PATHS:
        return ""
    return ("The scans: range scans made by `scripts/synth_views.py` (the bunny's surface "
            "from new views; with `--mesh`, other models, e.g. pymeshlab's sample meshes "
            "`cow.obj`, `bone.ply`, `airplane.obj`, three views each).\n\n")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--lod", action="store_true",
                    help="only the LOD part: 4 resample levels per scan, model and seed")
    ap.add_argument("--ratio", type=int, metavar="REPS", default=0,
                    help="only the fit-time ratio: REPS interleaved fits per model and seed")
    ap.add_argument("--scans", nargs="+", metavar="PATH",
                    help="scan files instead of the face map and the bunnies (e.g. the "
                         "views of scripts/synth_views.py); written to their own sections")
    ap.add_argument("--section", default="views", metavar="NAME",
                    help="with --scans: the BENCHMARKS sections they go to (pieces-NAME, ...)")
    ap.add_argument("--clouds", action="store_true",
                    help="with --ratio: each scan as a bare point cloud (the points its "
                         "triangles use, no faces: an XYZ or NPY file); its own section")
    args = ap.parse_args(argv)
    global _PATHS, _SUFFIX, _CMD
    _PATHS = args.scans
    _SUFFIX = f"-{args.section}" if args.scans else ""
    _CMD = " --scans " + " ".join(args.scans) if args.scans else ""
    if args.scans and args.section != "views":
        _CMD += f" --section {args.section}"
    if args.lod:
        return lod_main(args.seeds)
    if args.ratio:
        return ratio_main(args.seeds, args.ratio, clouds=args.clouds)
    if args.clouds:
        ap.error("--clouds goes with --ratio")
    found = scans(_PATHS)
    warm = next(iter(found.values()))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        am.fit(warm, seed=0, progress=False)  # compile the kernels first
    t0 = time.perf_counter()
    rows = []
    for name, scan in found.items():
        rows += _rows(name, scan, args.seeds)
    seeds = ", ".join(map(str, args.seeds))
    body = ("## Piecewise model vs the single network (issue 14)"
            f"{_title()}\n\n"
            f"_Measured {time.strftime('%Y-%m-%d')} on {machine()}; "
            f"`python scripts/bench_pieces.py --seeds {' '.join(map(str, args.seeds))}{_CMD}` "
            f"({time.perf_counter() - t0:.0f} s)._ Seeds {seeds}.\n\n" + _origin() +
            "Single: `am.fit(scan, pieces=1)` (`--pieces 1`, the paper's model). Pieces: "
            "`am.fit(scan)` (`--pieces auto`, the default): the scan cut by `am.segment` "
            "(defaults), one network per piece in the whole scan's unit cube with the same "
            "thresholds, pieces under 30 points up to three least-squares neurons (as few "
            "as fit them within E) or a constant, "
            "the tails refined after the polish. E̅: mean |f − z| in the unit "
            "cube over all N points, each by its own piece. Distances: the default "
            "reconstruction (`am.reconstruct(net, footprint=scan)`, mode surface at the "
            "scan's spacing: the cells on the scan's triangles, holes open but pinholes; "
            "pieces stitched by walls) against the scan mesh, vertex to surface (libigl), "
            "99.9th percentile / maximum in % of the bounding-box diagonal. *Samples in "
            "triangles*: the scan vertices used by its triangles (the face map has 667 "
            "samples in none, flying pixels at the silhouettes 1.4 % of the diagonal off "
            "the surface (median); the bunnies 4–11). Last column: mode scan, which also "
            "meshes the enclosed holes (1.6–4.3 % of its vertices; their distance to the "
            "scan is the hole's size, not an error: the hole benchmarks measure fills). "
            "Each cell: median over the seeds (worst seed); the last column counts the seeds "
            "on which the pieces have both fewer neurons and a lower E̅ than the single "
            "network of the same seed.\n\n"
            + table(HEADERS, rows))
    print(body)
    write_section("pieces" + _SUFFIX, body)
    return 0


LOD_HEADERS = ["scan", "model", "RMS by level 0→3 (%)", "RMS never falls", "worst 99.9 % "
               "scan→mesh", "worst 99.9 % mesh→scan", "same, --fill-holes",
               "level 0 RMS / QEM at equal bytes"]


def lod_main(seeds: list[int]) -> int:
    """LOD targets: monotone RMS, 99.9th percentiles per level, finest level vs free QEM."""
    import tempfile

    from bench_lod import free_qem

    from asrbf_mesh._lod import network_file_bytes
    from asrbf_mesh.evaluate import write_lod_set

    t0 = time.perf_counter()
    rows = []
    for name, scan in scans(_PATHS).items():
        diag = scan.bbox_diagonal
        ref = am.Mesh(scan.points, scan.faces)
        used = np.unique(scan.faces)
        for model, pieces in (("single", 1), ("pieces", "auto")):
            rms, mono, p_sm, p_ms, ratio, surf = [], [], [], [], [], []
            for seed in seeds:
                with warnings.catch_warnings(), tempfile.TemporaryDirectory() as tmp:
                    warnings.simplefilter("ignore")
                    net = am.fit(scan, seed=seed, pieces=pieces, progress=False)
                    levels = am.lod_set(scan, levels=4, net=net, seed=seed)
                    man = write_lod_set(scan, levels, tmp)
                r = [lv["rms_pct"] for lv in man["levels"]]
                rms.append(r)
                mono.append(all(b >= a for a, b in zip(r, r[1:], strict=False)))
                p_sm.append(max(np.percentile(point_mesh_distance(scan.points[used], lv.mesh),
                                              99.9) for lv in levels) * 100 / diag)
                p_ms.append(max(np.percentile(point_mesh_distance(lv.mesh.vertices, ref), 99.9)
                                for lv in levels) * 100 / diag)
                filled = am.lod_set(scan, levels=4, net=net, seed=seed, fill_holes=True)
                surf.append(max(np.percentile(point_mesh_distance(lv.mesh.vertices, ref), 99.9)
                                for lv in filled) * 100 / diag)
                q = free_qem(ref, network_file_bytes(net))
                ratio.append(r[0] / q["rms_pct"])
                print(f"{label(name)} {model} seed {seed}: RMS {r}, 99.9 {p_sm[-1]:.2f} / "
                      f"{p_ms[-1]:.2f} %, level 0 / QEM {ratio[-1]:.2f}", flush=True)
            med = np.median(np.array(rms), axis=0)
            rows.append([label(name), model, " / ".join(f"{v:.3f}" for v in med),
                         f"{sum(mono)} of {len(mono)} seeds", median_worst(p_sm, ".2f"),
                         median_worst(p_ms, ".2f"), median_worst(surf, ".2f"),
                         median_worst(ratio, ".2f")])
    body = (f"## LOD sets of the piecewise model (issue 14){_title()}: "
            f"seeds {', '.join(map(str, seeds))}"
            f"\n\n_Measured {time.strftime('%Y-%m-%d')} on {machine()}; "
            f"`python scripts/bench_pieces.py --lod --seeds {' '.join(map(str, seeds))}{_CMD}` "
            f"({time.perf_counter() - t0:.0f} s)._\n\n"
            "`am.lod_set(scan, levels=4, net=am.fit(scan, pieces=...))` (what `asrbf lod` "
            "does; resample: one model sampled on grids from the scan's own spacing at "
            "level 0, twice it at level 1, coarser after (`resample_spacings`), each piece "
            "on its own cells, walls between them). RMS: Metro RMS against the scan mesh "
            "(`write_lod_set`), % of the diagonal, median over the seeds. 99.9 %: the "
            "worst level's 99.9th percentile of vertex-to-surface distances (scan vertices "
            "used by faces → level mesh; level vertices → scan mesh), % of the diagonal; "
            "*--fill-holes*: the same levels with the scan's enclosed holes meshed too "
            "(`lod_set(fill_holes=True)`; the default leaves them open as the scan does). "
            "QEM: fast-simplification with a free border, decimated until its binary PLY "
            "takes the bytes of the `.asrbf` file a LOD set ships (compact: uint16 centres, "
            "float16 widths and weights; no log); the "
            "ratio is level 0's Metro RMS over the QEM mesh's. Cells: median (worst seed).\n\n"
            + table(LOD_HEADERS, rows))
    print(body)
    write_section("pieces-lod" + _SUFFIX, body)
    return 0


def ratio_main(seeds: list[int], reps: int, *, clouds: bool = False) -> int:
    """Fit seconds of the piecewise model over the single network's, per scan and seed.

    The fits alternate (pieces, single, and two variants of pieces that say where its
    extra time goes: the cut into pieces given, and no tail refinement) ``reps`` times
    per seed and each keeps its fastest run: on a shared machine a slow run says more
    about the neighbours than about the code, and alternating gives every model the same
    conditions. With ``clouds`` each scan is the bare point cloud of its triangles'
    points: the cut triangulates it in the view plane first.
    """
    import asrbf_mesh._pieces as pieces_mod

    found = scans(_PATHS)
    if clouds:
        found = {name: am.Scan(scan.points[np.unique(scan.faces)], None, source=scan.source)
                 for name, scan in found.items()}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for scan in found.values():  # compile the kernels and warm the caches first
            am.fit(scan, seed=0, progress=False)
            am.fit(scan, seed=0, pieces=1, progress=False)
    t0 = time.perf_counter()
    rows = []
    rounds = pieces_mod.TAIL_ROUNDS
    for name, scan in found.items():
        cut = am.segment(scan.points if clouds else am.Mesh(scan.points, scan.faces))
        runs = {"auto": ("auto", rounds), "1": (1, rounds), "cut": (cut, rounds),
                "no tails": ("auto", 0)}
        best = {m: {s: np.inf for s in seeds} for m in runs}
        try:
            for _ in range(reps):
                for seed in seeds:
                    for m, (pieces, tail_rounds) in runs.items():
                        pieces_mod.TAIL_ROUNDS = tail_rounds
                        with warnings.catch_warnings():
                            warnings.simplefilter("ignore")
                            _, sec = timed(am.fit, scan, seed=seed, pieces=pieces,
                                           progress=False)
                        best[m][seed] = min(best[m][seed], sec)
        finally:
            pieces_mod.TAIL_ROUNDS = rounds
        ratio = [best["auto"][s] / best["1"][s] for s in seeds]
        print(f"{label(name)}: " + ", ".join(f"{r:.2f}" for r in ratio), flush=True)
        rows.append([label(name), median_worst([best["1"][s] for s in seeds], ".3f"),
                     median_worst([best["auto"][s] for s in seeds], ".3f"),
                     median_worst(ratio, ".2f"), ", ".join(f"{r:.2f}" for r in ratio),
                     median_worst([best["cut"][s] for s in seeds], ".3f"),
                     median_worst([best["no tails"][s] for s in seeds], ".3f")])
    seeds_s = ", ".join(map(str, seeds))
    what = " --clouds" if clouds else ""
    body = ("## Piecewise fit time against the single fit (issue 14)"
            f"{_title()}{', bare point clouds' * clouds}\n\n"
            f"_Measured {time.strftime('%Y-%m-%d')} on {machine()}; "
            f"`python scripts/bench_pieces.py --ratio {reps}{what} --seeds "
            f"{' '.join(map(str, seeds))}"
            f"{_CMD}`"
            f" ({time.perf_counter() - t0:.0f} s)._\n\n" + _origin() +
            f"`am.fit(scan)` (pieces) and `am.fit(scan, pieces=1)` (single) alternate {reps} "
            "times per seed with two variants of pieces; each keeps its fastest run "
            "(wall-clock seconds of the fit, the frame and the cut into pieces included). "
            "*Cut given*: the segmentation passed in (`pieces=am.segment(...)`), so the fit "
            "skips the cut that otherwise runs beside the frame; *no tails*: no tail "
            "refinement (`_pieces.TAIL_ROUNDS = 0`). The piecewise model's extra time over "
            "the single network is the gap between its column and these. Cells: median over "
            f"the seeds {seeds_s} (worst seed).\n\n"
            + table(["scan", "single s", "pieces s", "pieces / single", "per seed",
                     "pieces, cut given s", "pieces, no tails s"], rows))
    print(body)
    write_section("pieces-time" + _SUFFIX + "-clouds" * clouds, body)
    return 0


def _rows(name: str, scan: am.Scan, seeds: list[int]) -> list[list]:
    diag = scan.bbox_diagonal
    ref = am.Mesh(scan.points, scan.faces)
    used = np.unique(scan.faces)
    out = []
    single: list[tuple] = []
    for model, pieces in (("single", 1), ("pieces", "auto")):
        rec = []
        for seed in seeds:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                net, sec = timed(am.fit, scan, seed=seed, pieces=pieces, progress=False)
                mesh = am.reconstruct(net, footprint=scan)
                filled = am.reconstruct(net, footprint=scan, mode="scan")
            to_mesh = 100 * point_mesh_distance(scan.points, mesh) / diag
            to_scan = 100 * point_mesh_distance(mesh.vertices, ref) / diag
            filled_to_scan = 100 * point_mesh_distance(filled.vertices, ref) / diag
            n = net.info["n_points"]
            rec.append((net.n_pieces, net.n_neurons, n / max(net.n_neurons, 1),
                        net.info["ebar"], sec, np.percentile(to_mesh, 99.9), to_mesh.max(),
                        np.percentile(to_scan, 99.9), to_scan.max(),
                        np.percentile(to_mesh[used], 99.9),
                        np.percentile(filled_to_scan, 99.9)))
            print(f"{label(name)} {model} seed {seed}: K {net.n_neurons} E {net.info['ebar']:.5f} "
                  f"{sec:.1f} s, 99.9 % {rec[-1][5]:.2f} / {rec[-1][7]:.2f} %", flush=True)
        c = list(zip(*rec, strict=True))
        # seed by seed against the single network (the medians and worst seeds above may
        # come from different seeds)
        better = "" if model == "single" else (
            f"{sum(r[1] < q[1] and r[3] < q[3] for r, q in zip(rec, single, strict=True))} "
            f"of {len(rec)}")
        single = single or rec
        out.append([label(name), f"{scan.n_points:,}", model, str(int(statistics.median(c[0]))),
                    median_worst(c[1], ","), median_worst(c[2], ".0f", min),
                    median_worst(c[3], ".5f"),
                    median_worst(c[4], ".2f"),
                    f"{median_worst(c[5], '.2f')} / {median_worst(c[6], '.2f')}",
                    median_worst(c[9], ".2f"),
                    f"{median_worst(c[7], '.2f')} / {median_worst(c[8], '.2f')}",
                    median_worst(c[10], ".2f"), better])
    return out


if __name__ == "__main__":
    raise SystemExit(main())
