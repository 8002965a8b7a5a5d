"""One network per smooth piece vs one network for the whole scan (private prototype).

Run from the repository root:  python scripts/bench_pieces.py [--seeds 0 1 2]

For the face map and the Stanford bunny scans (read from the folder named by
$ASRBF_BUNNY_DIR; skipped without it), fit each scan with each seed twice: one network
(``am.fit``, defaults) and one network per piece of ``am.segment`` (defaults) in the
whole scan's frame (``asrbf_mesh._pieces.fit_pieces``, same FitConfig). Prints one
Markdown table, each cell the median over the seeds and, in brackets, the worst seed:
neurons K, E-bar (mean |f - z| in the unit cube over all N points), N:K and the wall
time of the call (the pieces' time includes the segmentation).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _bench_common import machine, scans, table, timed, write_section  # noqa: E402

import asrbf_mesh as am  # noqa: E402
from asrbf_mesh._pieces import fit_pieces  # noqa: E402

HEADERS = ["scan", "N", "pieces (small)", "K single", "K pieces", "E̅ single", "E̅ pieces",
           "N:K single", "N:K pieces", "s single", "s pieces"]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    args = ap.parse_args(argv)
    found = scans()
    warm = next(iter(found.values()))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        am.fit(warm.points[:2000], seed=0, progress=False)  # compile the kernels first
    t0 = time.perf_counter()
    rows = [_row(name, scan, args.seeds) for name, scan in found.items()]
    seeds = ", ".join(map(str, args.seeds))
    body = (f"## One network per piece (issue 14, prototype): seeds {seeds}\n\n"
            f"_Measured {time.strftime('%Y-%m-%d')} on {machine()}; "
            f"`python scripts/bench_pieces.py` ({time.perf_counter() - t0:.0f} s)._\n\n"
            "Single: `am.fit` with defaults. Pieces: `am.segment` (defaults), then one "
            "network per piece (learning + the default weights polish) in the whole scan's "
            "unit cube, so every piece uses the same E, E_ω, D_max and D_min (from the whole "
            "scan's spacing); small pieces (under 30 points) get a constant. E̅ is the mean "
            "|f − z| in the unit cube over all N points, each by its own piece's network. "
            "Each cell: median over the seeds (worst seed); seconds are the wall time of the "
            "call, the pieces' including the segmentation. Private prototype "
            "(`asrbf_mesh._pieces.fit_pieces`), not in the API or the command line yet.\n\n"
            + table(HEADERS, rows))
    print(body)
    write_section("pieces", body)
    return 0


def _cell(values: list[float], fmt: str, worst=max) -> str:
    return f"{format(statistics.median(values), fmt)} ({format(worst(values), fmt)})"


def _row(name: str, scan: am.Scan, seeds: list[int]) -> list:
    single, pieces = [], []
    seg = None
    for seed in seeds:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            net, s1 = timed(am.fit, scan, seed=seed, progress=False)
            pf, s2 = timed(fit_pieces, scan, seed=seed)
        n = pf.n_points
        seg = pf.segmentation
        single.append((net.n_neurons, net.info["ebar"], n / max(net.n_neurons, 1), s1))
        pieces.append((pf.n_neurons, pf.ebar, n / max(pf.n_neurons, 1), s2))
        print(f"{name} seed {seed}: single K {net.n_neurons} E {net.info['ebar']:.5f} "
              f"{s1:.1f} s; pieces K {pf.n_neurons} E {pf.ebar:.5f} {s2:.1f} s", flush=True)
    col = list(zip(*single, strict=True)), list(zip(*pieces, strict=True))
    return [name, f"{scan.n_points:,}", f"{seg.n_pieces} ({int(seg.small.sum())})",
            _cell(col[0][0], ","), _cell(col[1][0], ","),
            _cell(col[0][1], ".5f"), _cell(col[1][1], ".5f"),
            _cell(col[0][2], ".0f", min), _cell(col[1][2], ".0f", min),
            _cell(col[0][3], ".1f"), _cell(col[1][3], ".1f")]


if __name__ == "__main__":
    raise SystemExit(main())
