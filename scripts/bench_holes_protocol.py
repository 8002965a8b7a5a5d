"""Hole filling on the punch protocol (issue 15): crashes, holes left open, error per hole.

Run from the repository root:

    python scripts/bench_holes_protocol.py --seeds 0 1 2 3 --poisson   # + screened Poisson
    python scripts/bench_holes_protocol.py --seeds $(seq 0 199) --fuzz  # crash campaign
    python scripts/bench_holes_protocol.py --seeds $(seq 0 9) --poisson --peers  # every peer

For the face map and the Stanford bunny scans (from $ASRBF_BUNNY_DIR; skipped without
it), each seed punches the scan by the protocol of :mod:`asrbf_mesh.evaluate._punch_protocol`
and runs ``fill_holes`` (``--max-hole-size 20%``, the default fit) in a worker process, so a
crash (SIGSEGV, abort) is counted, not fatal. Per enclosed hole: filled or left open (the
fill's own report names the reason) and the RMS of its truth points' distances to the
output, % of the diagonal; with ``--poisson`` the same for screened Poisson (depth 9).
``--fuzz`` skips the scores and only counts outcomes (writes the "holes-fuzz" section).
``--peers`` adds MeshFix, MeshLab Close Holes, VTK's hole filter and a thin-plate height
field (:mod:`_hole_peers`, the ``bench`` extra). Every table comes twice: notches told
from enclosed holes by libigl's longest boundary loop (the issue's protocol), and by the
outer border of every part, parts joined by triangles' edges (a bite out of a
fragment's border is a notch, a fragment pinched to the rest at a vertex is a part, a
fragment erased whole is no hole; see :mod:`asrbf_mesh.evaluate._punch_protocol`).
"""

from __future__ import annotations

import argparse
import concurrent.futures as cf
import json
import os
import re
import sys
import time
from collections import Counter
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _bench_common import BUNNIES, label, machine, scans, table, write_section  # noqa: E402

#: A case still running after this many seconds is stopped (SIGALRM ends its worker) and
#: reported with the crashes: a native library looping forever (triangle did, on a
#: synthetic view punched with seed 69) would otherwise hold the campaign for ever. The
#: slowest cases take about 30 s.
CASE_SECONDS = 600


def _guarded(fn, c: tuple) -> dict:
    """Run ``fn(c)`` in a worker that SIGALRM ends after :data:`CASE_SECONDS`."""
    import signal

    signal.signal(signal.SIGALRM, signal.SIG_DFL)  # the default action ends the process
    signal.alarm(CASE_SECONDS)
    try:
        return fn(c)
    finally:
        signal.alarm(0)


def _case(args: tuple[str, int, bool, str, bool]) -> dict:
    """One punched case, in a worker process: fill, report, score every method."""
    import warnings

    import asrbf_mesh as am
    from asrbf_mesh.evaluate._punch_protocol import punch_protocol, score_holes

    name, seed, poisson, pieces, peers = args
    warnings.simplefilter("ignore")
    scan = _SCANS[name]
    p = punch_protocol(scan, seed)  # notches by libigl's longest loop (the issue's)
    traced = punch_protocol(scan, seed, border="parts").enclosed[p.enclosed]
    t0 = time.perf_counter()
    res = am.fill_holes(p.scan, seed=seed, max_hole_size="20%", progress=False, pieces=pieces)
    secs = time.perf_counter() - t0
    out = {"name": name, "seed": seed, "traced": traced, "open": _open_holes(p, res),
           "n": np.bincount(p.hole, minlength=len(p.enclosed))[p.enclosed],
           "rms": score_holes(p, res.mesh)[0][p.enclosed], "seconds": secs,
           "crossing": _crossing(res.mesh, len(p.scan.faces)),
           "far": _past_reach(res, p.scan.points)}
    methods = {}
    if poisson:
        from asrbf_mesh.evaluate import _meshlab

        methods["poisson"] = lambda sc: _meshlab.screened_poisson(sc.points, depth=9)
    if peers:
        import _hole_peers

        methods.update(_hole_peers.PEERS)
    for method, fn in methods.items():
        t0 = time.perf_counter()
        mesh = fn(p.scan)
        out[f"{method}_seconds"] = time.perf_counter() - t0
        out[f"{method}_rms"] = score_holes(p, mesh)[0][p.enclosed]
    return out


def _crossing(mesh, n_scan_faces: int) -> int:
    """Fill triangles that pymeshlab's self-intersection selection finds (the issue's check)."""
    import pymeshlab

    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=mesh.vertices, face_matrix=mesh.faces))
    ms.compute_selection_by_self_intersections_per_face()
    return int(np.count_nonzero(ms.current_mesh().face_selection_array()[n_scan_faces:]))


def _past_reach(res, points: np.ndarray) -> int:
    """Fill vertices past the scan's depths by more than the widest hole filled is wide.

    Holes filled in part count too (vertices added, an edge left open): a synthetic cylinder's
    hole of 13.7 units (seed 28) left open with 2,075 vertices added, 0.3 past the
    scan's depths, was counted against a width of 0.
    """
    new = res.mesh.vertices[len(points):, 2]
    widest = max((h.size_abs for h in res.holes if h.filled or h.vertices_added),
                 default=0.0)
    z = points[:, 2]
    return int(np.count_nonzero((new < z.min() - widest) | (new > z.max() + widest)))


def _open_holes(p, res) -> list[str | None]:
    """For each enclosed truth hole left open, why (else None).

    Open: most of its truth points have no output vertex within 1.5 median spacings in
    the view plane (a fill puts vertices at the scan's spacing). The reason is the one
    the fill reported for the nearest hole it left open, or "not found as a hole".
    """
    from scipy.spatial import cKDTree

    from asrbf_mesh._frame import sampling_spacing

    out_xy = res.mesh.vertices[:, :2]
    gap = 1.5 * sampling_spacing(p.scan.points[:, :2])
    far = cKDTree(out_xy).query(p.truth[:, :2], distance_upper_bound=gap)[0] > gap
    skipped = [info for info in res.holes if not info.filled]
    out: list[str | None] = []
    for h in np.flatnonzero(p.enclosed):
        mine = p.hole == h
        if np.mean(far[mine]) <= 0.5:
            out.append(None)
            continue
        c = p.truth[mine][:, :2].mean(axis=0)
        near = min(skipped, key=lambda i: float(np.linalg.norm(np.asarray(i.centre[:2]) - c)),
                   default=None)
        out.append((near.reason or "not filled") if near else "not found as a hole")
    return out


_SCANS: dict = {}


def _init(names: list[str]) -> None:
    _SCANS.update(scans(names))


def _other_case(args: tuple[str, int, str]) -> dict:
    """A scan's natural holes, or a synthetic holed scan, in a worker: fill and check.

    ``(name, seed, pieces)``: ``name`` is a scan's (its own holes, as it is) or
    ``synth:<kind>`` (:func:`asrbf_mesh.evaluate._synthetic_holes.synthetic_holes`).
    Returns the holes found and filled, the reasons of those left open and the checks
    that failed: vertices finite, the scan's own points kept as they are, no triangle with
    a vertex twice, no edge with more triangles than the scan's own edges have, no fill
    vertex past the scan's depths by more than the widest hole filled (wholly or in
    part) is wide.
    """
    import warnings

    import asrbf_mesh as am
    from asrbf_mesh.evaluate._synthetic_holes import synthetic_holes

    name, seed, pieces = args
    warnings.simplefilter("ignore")
    scan = synthetic_holes(name[6:], seed) if name.startswith("synth:") else _SCANS[name]
    res = am.fill_holes(scan, seed=seed, progress=False, pieces=pieces)
    out_f, n = res.mesh.faces, scan.n_points

    def most_faces_per_edge(f: np.ndarray) -> int:
        e = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
        return int(np.unique(e, axis=0, return_counts=True)[1].max()) if len(e) else 0

    failed = [what for what, ok in (
        ("finite", bool(np.isfinite(res.mesh.vertices).all())),
        ("scan kept", bool(np.array_equal(res.mesh.vertices[:n], scan.points))),
        ("no repeated vertex", not bool(np.any((out_f[:, 0] == out_f[:, 1])
                                               | (out_f[:, 1] == out_f[:, 2])
                                               | (out_f[:, 0] == out_f[:, 2])))),
        ("edges", most_faces_per_edge(out_f) <= max(2, most_faces_per_edge(scan.faces))),
        ("within reach", _past_reach(res, scan.points) == 0),
    ) if not ok]
    return {"name": name, "seed": seed, "found": res.holes_found, "filled": res.holes_filled,
            "open": [h.reason or "not filled" for h in res.holes if not h.filled],
            "failed": failed}


def run(names: list[str], seeds: list[int], poisson: bool, pieces: str, workers: int,
        peers: bool = False, cases: list[tuple] | None = None, fn=None
        ) -> tuple[list[dict], list[tuple[str, int, str]]]:
    """Every (scan, seed) case (or ``cases`` through ``fn``); crashed or failed cases are
    returned apart."""
    fn = fn or _case
    if cases is None:
        cases = [(n, s, poisson, pieces, peers) for n in names for s in seeds]
    done: list[dict] = []
    bad: list[tuple[str, int, str]] = []
    todo = list(cases)
    while todo:
        with cf.ProcessPoolExecutor(workers, initializer=_init, initargs=(names,)) as ex:
            futures = {ex.submit(_guarded, fn, c): c for c in todo}
            todo = []
            broken = False
            for fut in cf.as_completed(futures):
                c = futures[fut]
                try:
                    done.append(fut.result())
                    r = done[-1]
                    found = len(r["rms"]) if "rms" in r else r["found"]
                    print(f"{c[0]} seed {c[1]}: {found} holes, "
                          f"{sum(w is not None for w in r['open'])} open", flush=True)
                except cf.process.BrokenProcessPool:
                    broken = True
                    todo.append(c)
                except Exception as exc:  # noqa: BLE001 - a case that raised: report it
                    bad.append((c[0], c[1], f"raised {type(exc).__name__}: {exc}"))
            if broken:  # find the crashing case(s): rerun the unfinished ones one by one
                for c in todo:
                    with cf.ProcessPoolExecutor(1, initializer=_init, initargs=(names,)) as one:
                        try:
                            done.append(one.submit(_guarded, fn, c).result())
                        except cf.process.BrokenProcessPool:
                            bad.append((c[0], c[1], "CRASH (worker died, or ran over "
                                                    f"{CASE_SECONDS} s)"))
                        except Exception as exc:  # noqa: BLE001
                            bad.append((c[0], c[1], f"raised {type(exc).__name__}: {exc}"))
                todo = []
    return done, bad


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3])
    ap.add_argument("--poisson", action="store_true")
    ap.add_argument("--fuzz", action="store_true")
    ap.add_argument("--pieces", default="auto", choices=("auto", "1"))
    ap.add_argument("--peers", action="store_true")
    ap.add_argument("--synthetic", type=int, default=0, metavar="N",
                    help="with --fuzz: also N seeds of every synthetic kind (cliffs, spirals, "
                         "nested and folded holes, cylinders, random holes)")
    ap.add_argument("--json", metavar="PATH", help="with --fuzz: write every case's outcome")
    ap.add_argument("--workers", type=int, default=max(1, min(2, os.cpu_count() or 1)))
    ap.add_argument("--scans", nargs="+", metavar="PATH",
                    help="scan files instead of the face map and the bunnies (e.g. the "
                         "views of scripts/synth_views.py); written to their own section")
    ap.add_argument("--section", metavar="NAME",
                    help="write to the sections ...-NAME (e.g. held-out seeds, other models) "
                         "instead of the default ones")
    args = ap.parse_args(argv)
    if args.peers:  # a peer that cannot run would score as the punched scan itself
        try:
            import pymeshfix  # noqa: F401
            import pyvista  # noqa: F401
        except ImportError as exc:
            ap.exit(2, f"--peers needs the bench extra (pip install -e '.[bench]'): {exc}\n")
    names = list(scans(args.scans))
    t0 = time.perf_counter()
    done, bad = run(names, args.seeds, args.poisson, args.pieces, args.workers, args.peers)
    took = time.perf_counter() - t0
    crashes = [b for b in bad if b[2].startswith("CRASH")]
    holes = sum(len(r["rms"]) for r in done)
    opened = [(r["name"], r["seed"], why) for r in done for why in r["open"] if why]
    views = " --scans " + " ".join(args.scans) if args.scans else ""
    flags = " --poisson" * args.poisson + " --peers" * args.peers + " --fuzz" * args.fuzz + (
        f" --pieces {args.pieces}" if args.pieces != "auto" else "")
    if args.synthetic:
        flags += f" --synthetic {args.synthetic}"
    if args.section:
        flags += f" --section {args.section}"

    def header(seconds: float) -> str:
        return (f"_Measured {time.strftime('%Y-%m-%d')} on {machine()}; `python "
                f"scripts/bench_holes_protocol.py --seeds {_seeds(args.seeds)}{flags}{views}` "
                f"({seconds:.0f} s)._\n\n")

    head = header(took)
    lines = [f"- cases: {len(done) + len(bad):,} ({len(names)} scans × {len(args.seeds)} seeds); "
             f"crashes: {len(crashes)}; cases that raised: {len(bad) - len(crashes)}",
             f"- enclosed holes: {holes:,}; left open: {len(opened)}"]
    crossing = [r.get("crossing", 0) for r in done]
    if not args.fuzz:
        lines.insert(1, f"- outputs with fill triangles that cross the scan or another fill "
                        f"(pymeshlab's self-intersection selection): "
                        f"{sum(c > 0 for c in crossing)} of {len(done)} ({sum(crossing):,} "
                        "triangles)")
        far = [r.get("far", 0) for r in done]
        lines.insert(2, f"- outputs with fill vertices past the scan's depths by more than "
                        "the widest hole filled (wholly or in part) is wide: "
                        f"{sum(c > 0 for c in far)} of {len(done)} ({sum(far):,} vertices)")
    for name, seed, why in (bad + opened)[:20]:
        lines.append(f"  - {label(name)} seed {seed}: {why}")
    suffix = "-views" if args.scans and not set(args.scans) & {"face", *BUNNIES} else ""
    if args.section:
        suffix = f"-{args.section}"
    if args.fuzz:
        from asrbf_mesh.evaluate._synthetic_holes import SYNTHETIC_KINDS

        traced_open = [(r["name"], r["seed"], why) for r in done
                       for why, t in zip(r["open"], r["traced"], strict=True) if why and t]
        enclosed = sum(int(np.sum(r["traced"])) for r in done)
        lines = lines[:1] + [
            f"- enclosed holes, notches told by every part's outer border (parts joined by "
            f"edges; fragments erased whole left out): {enclosed:,}; left open: "
            f"{len(traced_open)}"]
        lines += [f"  - {label(n)} seed {s}: {why}" for n, s, why in (bad + traced_open)[:20]]
        lines.append(f"- enclosed holes by libigl's longest boundary loop (the issue's "
                     f"protocol): {holes:,}; left open: {len(opened)}, "
                     f"{len(opened) - len(traced_open)} of them bites out of a part's outer "
                     f"border (a fragment's, or the border beyond a pinch vertex), which the "
                     f"fill leaves open as it leaves the border")
        others = [(n, 0, args.pieces) for n in names] + [
            (f"synth:{k}", s, args.pieces) for k in SYNTHETIC_KINDS
            for s in range(args.synthetic)]
        t1 = time.perf_counter()
        more, more_bad = run(names, [], False, args.pieces, args.workers, cases=others,
                             fn=_other_case)
        took += time.perf_counter() - t1
        head = header(took)
        if args.json:  # every case: its outcome, or how it failed (a crash, an exception)
            Path(args.json).write_text(json.dumps(
                [{k: v.tolist() if isinstance(v, np.ndarray) else v for k, v in r.items()}
                 for r in done + more]
                + [{"name": n, "seed": s, "error": why} for n, s, why in bad + more_bad],
                default=str))
        crashes += [b for b in more_bad if b[2].startswith("CRASH")]
        lines.append(f"- natural holes and synthetic scans: {len(others):,} cases; crashes: "
                     f"{sum(b[2].startswith('CRASH') for b in more_bad)}; cases that raised: "
                     f"{sum(not b[2].startswith('CRASH') for b in more_bad)}")
        for name, seed, why in more_bad[:20]:
            lines.append(f"  - {name} seed {seed}: {why}")
        rows = []
        for group in [*names, *(f"synth:{k}" for k in SYNTHETIC_KINDS)]:
            rs = [r for r in more if r["name"] == group]
            if not rs:
                continue
            why = Counter(re.sub(r"\d[\d,]*", "N", w) for r in rs for w in r["open"])
            rows.append([f"{label(group)} (its own holes)" if group in names else group[6:],
                         len(rs), sum(r["found"] for r in rs), sum(r["filled"] for r in rs),
                         sum(len(r["open"]) for r in rs),
                         "; ".join(f"{c} × {w}" for w, c in why.most_common()) or "",
                         sum(bool(r["failed"]) for r in rs)])
        body = (f"## Hole filling: crash campaign (issue 15){' on other scans' * bool(suffix)}"
                "\n\n" + head + "\n".join(lines) + "\n\n" + "Natural holes (each scan as it "
                "is, default options) and synthetic holed scans "
                "(`asrbf_mesh.evaluate._synthetic_holes`, default options); 'checks failed': "
                "cases whose output had a non-finite vertex, a scan point moved, a triangle "
                "with a vertex twice, an edge with more triangles than the scan's own "
                "edges or a fill vertex past the scan's depths by more than the widest hole "
                "filled (wholly or in part) is wide.\n\n"
                + table(["case", "runs", "holes found", "filled", "left open", "why left open",
                         "checks failed"], rows) + "\n")
        print(body)
        write_section("holes-fuzz" + suffix, body)
        return 1 if crashes else 0
    methods = ["ours"] + ["poisson"] * args.poisson + (list(_peer_names()) if args.peers else [])
    headers = ["method", "enclosed holes", "left open", "pooled RMS %", "median %", "90th %",
               "worst %", "holes > 0.5 %", "ours lower on", "s per scan"]
    parts = []
    for traced in (False, True):
        parts.append("### Notches told by libigl's longest boundary loop (the issue's protocol)"
                     if not traced else "### Notches told by every part's outer border (parts "
                     "joined by edges; fragments erased whole left out)")
        for name in [*names, "pooled"]:
            rs = [r for r in done if name in ("pooled", r["name"])]
            if rs:
                rows = [_row(m, rs, traced) for m in methods]
                parts.append(f"**{label(name)}**\n\n" + table(headers, rows))
    tag = f"holes-protocol-{args.pieces}{suffix}"
    title = f" ({args.section})" if args.section else " on other scans" * bool(suffix)
    body = (f"## Hole filling on the punch protocol (issue 15){title}"
            ": seeds "
            f"{_seeds(args.seeds)}, --pieces {args.pieces}\n\n" + head
            + "\n".join(lines) + "\n\nPer hole: RMS of its truth points' distances to the "
            "output, % of the bounding-box diagonal; pooled: over all enclosed truth points; "
            "'left open': enclosed holes our fill reported open; 'ours lower on': the share "
            "of enclosed holes where our RMS is below the method's. Screened Poisson at "
            "depth 9; the peers as in `scripts/_hole_peers.py`.\n\n" + "\n\n".join(parts))
    print(body)
    write_section(tag, body)
    return 1 if crashes else 0


def _seeds(seeds: list[int]) -> str:
    """``0 1 2 3`` or ``$(seq 4 203)`` for a run of consecutive seeds."""
    if len(seeds) > 4 and seeds == list(range(seeds[0], seeds[-1] + 1)):
        return f"$(seq {seeds[0]} {seeds[-1]})"
    return " ".join(map(str, seeds))


def _peer_names() -> list[str]:
    import _hole_peers

    return list(_hole_peers.PEERS)


def _row(method: str, rs: list[dict], traced: bool) -> list:
    """One method's figures over the cases ``rs`` (the traced border's enclosed holes only)."""
    key = "" if method == "ours" else f"{method}_"

    def pick(r: dict, k: str) -> np.ndarray:
        v = np.asarray(r[k])
        return v[r["traced"]] if traced else v

    rms = np.concatenate([pick(r, f"{key}rms") for r in rs])
    ours = np.concatenate([pick(r, "rms") for r in rs])
    n = np.concatenate([pick(r, "n") for r in rs])
    opened = sum(w is not None for r in rs for w in (
        np.asarray(r["open"], dtype=object)[r["traced"]] if traced else r["open"]))
    if len(rms) == 0:
        return [method, 0, "", "", "", "", "", "", "", ""]
    return [method, len(rms), opened if method == "ours" else "",
            f"{np.sqrt(np.sum(n * rms ** 2) / np.sum(n)):.3f}", f"{np.median(rms):.3f}",
            f"{np.percentile(rms, 90):.3f}", f"{rms.max():.3f}", int(np.sum(rms > 0.5)),
            "" if method == "ours" else f"{100 * np.mean(ours < rms):.0f} %",
            f"{np.mean([r[f'{key}seconds'] for r in rs]):.1f}"]


if __name__ == "__main__":
    raise SystemExit(main())
