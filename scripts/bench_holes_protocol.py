"""Hole filling on the punch protocol (issue 15): crashes, holes left open, error per hole.

Run from the repository root:

    python scripts/bench_holes_protocol.py --seeds 0 1 2 3 --poisson   # + screened Poisson
    python scripts/bench_holes_protocol.py --seeds $(seq 0 199) --fuzz  # crash campaign

For the face map and the Stanford bunny scans (from $ASRBF_BUNNY_DIR; skipped without
it), each seed punches the scan by the protocol of :mod:`asrbf_mesh.evaluate._punch_protocol`
and runs ``fill_holes`` (``--max-hole-size 20%``, the default fit) in a worker process, so a
crash (SIGSEGV, abort) is counted, not fatal. Per enclosed hole: filled or left open (the
fill's own report names the reason) and the RMS of its truth points' distances to the
output, % of the diagonal; with ``--poisson`` the same for screened Poisson (depth 9).
``--fuzz`` skips the scores and only counts outcomes (writes the "holes-fuzz" section).
"""

from __future__ import annotations

import argparse
import concurrent.futures as cf
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _bench_common import machine, scans, table, write_section  # noqa: E402


def _case(args: tuple[str, int, bool, str]) -> dict:
    """One punched case, in a worker process: fill, report, score."""
    import warnings

    import asrbf_mesh as am
    from asrbf_mesh.evaluate._punch_protocol import punch_protocol, score_holes

    name, seed, poisson, pieces = args
    warnings.simplefilter("ignore")
    scan = _SCANS[name]
    p = punch_protocol(scan, seed)
    t0 = time.perf_counter()
    res = am.fill_holes(p.scan, seed=seed, max_hole_size="20%", progress=False, pieces=pieces)
    secs = time.perf_counter() - t0
    rms, pooled = score_holes(p, res.mesh)
    open_ = _open_holes(p, res)
    out = {"name": name, "seed": seed, "holes": int(p.n_enclosed), "rms": rms[p.enclosed],
           "pooled": pooled, "open": open_, "seconds": secs, "truth": len(p.truth)}
    if poisson:
        from asrbf_mesh.evaluate import _meshlab

        t0 = time.perf_counter()
        sp = _meshlab.screened_poisson(p.scan.points, depth=9)
        out["poisson_seconds"] = time.perf_counter() - t0
        prms, ppooled = score_holes(p, sp)
        out["poisson_rms"], out["poisson_pooled"] = prms[p.enclosed], ppooled
    return out


def _open_holes(p, res) -> list[str]:
    """Reasons of the fill's holes that were not filled and lie on an enclosed truth hole."""
    reasons = []
    tree_pts = {h: p.truth[p.hole == h][:, :2] for h in np.flatnonzero(p.enclosed)}
    for info in res.holes:
        if info.filled:
            continue
        c = np.asarray(info.centre[:2])
        for pts in tree_pts.values():
            lo, hi = pts.min(0), pts.max(0)
            pad = 0.25 * float((hi - lo).max())
            if np.all(c >= lo - pad) and np.all(c <= hi + pad):
                reasons.append(info.reason or "not filled")
                break
    return reasons


_SCANS: dict = {}


def _init(names: list[str]) -> None:
    _SCANS.update(scans(names))


def run(names: list[str], seeds: list[int], poisson: bool, pieces: str,
        workers: int) -> tuple[list[dict], list[tuple[str, int, str]]]:
    """Every (scan, seed) case; crashed or failed cases are returned apart."""
    cases = [(n, s, poisson, pieces) for n in names for s in seeds]
    done: list[dict] = []
    bad: list[tuple[str, int, str]] = []
    todo = list(cases)
    while todo:
        with cf.ProcessPoolExecutor(workers, initializer=_init, initargs=(names,)) as ex:
            futures = {ex.submit(_case, c): c for c in todo}
            todo = []
            broken = False
            for fut in cf.as_completed(futures):
                c = futures[fut]
                try:
                    done.append(fut.result())
                    r = done[-1]
                    print(f"{c[0]} seed {c[1]}: {r['holes']} enclosed, {len(r['open'])} open, "
                          f"pooled {r['pooled']:.3f} %", flush=True)
                except cf.process.BrokenProcessPool:
                    broken = True
                    todo.append(c)
                except Exception as exc:  # noqa: BLE001 - a case that raised: report it
                    bad.append((c[0], c[1], f"raised {type(exc).__name__}: {exc}"))
            if broken:  # find the crashing case(s): rerun the unfinished ones one by one
                for c in todo:
                    with cf.ProcessPoolExecutor(1, initializer=_init, initargs=(names,)) as one:
                        try:
                            done.append(one.submit(_case, c).result())
                        except cf.process.BrokenProcessPool:
                            bad.append((c[0], c[1], "CRASH (worker died)"))
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
    ap.add_argument("--workers", type=int, default=max(1, min(2, os.cpu_count() or 1)))
    args = ap.parse_args(argv)
    names = list(scans())
    t0 = time.perf_counter()
    done, bad = run(names, args.seeds, args.poisson, args.pieces, args.workers)
    took = time.perf_counter() - t0
    crashes = [b for b in bad if b[2].startswith("CRASH")]
    holes = sum(r["holes"] for r in done)
    opened = [(r["name"], r["seed"], why) for r in done for why in r["open"]]
    flags = " --poisson" * args.poisson + " --fuzz" * args.fuzz + (
        f" --pieces {args.pieces}" if args.pieces != "auto" else "")
    head = (f"_Measured {time.strftime('%Y-%m-%d')} on {machine()}; `python "
            f"scripts/bench_holes_protocol.py --seeds {_seeds(args.seeds)}{flags}` "
            f"({took:.0f} s)._\n\n")
    lines = [f"- cases: {len(done) + len(bad):,} ({len(names)} scans × {len(args.seeds)} seeds); "
             f"crashes: {len(crashes)}; cases that raised: {len(bad) - len(crashes)}",
             f"- enclosed holes: {holes:,}; left open: {len(opened)}"]
    for name, seed, why in (bad + opened)[:20]:
        lines.append(f"  - {name} seed {seed}: {why}")
    if args.fuzz:
        body = "## Hole filling: crash campaign (issue 15)\n\n" + head + "\n".join(lines) + "\n"
        print(body)
        write_section("holes-fuzz", body)
        return 1 if crashes else 0
    rows = []
    for name in names:
        rs = [r for r in done if r["name"] == name]
        if not rs:
            continue
        rows.append(_row(name, rs, args.poisson))
    rows.append(_row("pooled", done, args.poisson))
    headers = ["scan", "enclosed holes", "left open", "pooled RMS %", "median %", "90th %",
               "worst %", "holes > 0.5 %", "s per scan"]
    if args.poisson:
        headers += ["Poisson pooled RMS %", "Poisson median %", "Poisson worst %",
                    "Poisson > 0.5 %", "ours lower than Poisson", "Poisson s"]
    body = ("## Hole filling on the punch protocol (issue 15): seeds "
            f"{_seeds(args.seeds)}, --pieces {args.pieces}\n\n" + head
            + "\n".join(lines) + "\n\n" + table(headers, rows))
    print(body)
    write_section(f"holes-protocol-{args.pieces}", body)
    return 1 if crashes else 0


def _seeds(seeds: list[int]) -> str:
    """``0 1 2 3`` or ``$(seq 4 203)`` for a run of consecutive seeds."""
    if len(seeds) > 4 and seeds == list(range(seeds[0], seeds[-1] + 1)):
        return f"$(seq {seeds[0]} {seeds[-1]})"
    return " ".join(map(str, seeds))


def _row(name: str, rs: list[dict], poisson: bool) -> list:
    rms = np.concatenate([r["rms"] for r in rs]) if rs else np.zeros(0)
    d2 = sum(r["pooled"] ** 2 * r["truth"] for r in rs if np.isfinite(r["pooled"]))
    n = sum(r["truth"] for r in rs if np.isfinite(r["pooled"]))
    row = [name, len(rms), sum(len(r["open"]) for r in rs), f"{np.sqrt(d2 / max(n, 1)):.3f}",
           f"{np.median(rms):.3f}", f"{np.percentile(rms, 90):.3f}", f"{rms.max():.3f}",
           int(np.sum(rms > 0.5)), f"{np.mean([r['seconds'] for r in rs]):.1f}"]
    if poisson:
        prms = np.concatenate([r["poisson_rms"] for r in rs])
        p2 = sum(r["poisson_pooled"] ** 2 * r["truth"] for r in rs)
        row += [f"{np.sqrt(p2 / max(n, 1)):.3f}", f"{np.median(prms):.3f}",
                f"{prms.max():.3f}", int(np.sum(prms > 0.5)),
                f"{100 * np.mean(rms < prms):.0f} %",
                f"{np.mean([r['poisson_seconds'] for r in rs]):.1f}"]
    return row


if __name__ == "__main__":
    raise SystemExit(main())
