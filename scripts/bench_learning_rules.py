"""The learning loop's open questions (issue 17): separation decay and pruning, measured.

Run from the repository root:  python scripts/bench_learning_rules.py [--seeds 0 1 2]

For the face map and the Stanford bunny scans (read from the folder named by
$ASRBF_BUNNY_DIR; skipped without it), fit each scan with each seed under each rule,
both as the paper's single network (``pieces=1``) and as the default piecewise model,
and print one Markdown table per model: neurons K, E-bar of the learned network before
the polish and after it (mean |f - z| in the unit cube over all N points), fit seconds;
each cell the median over the seeds and, in brackets, the worst seed (largest K, E-bar
or time). Rules: today's defaults (``decay="observation"``, gamma 0.99, ``pruning=
"support"``); ``decay="pass"`` reaching D_min after 2 %, 10 % and 30 % of the first pass;
the paper's literal pruning; no pruning.
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _bench_common import machine, median_worst, scans, table, write_section  # noqa: E402

import asrbf_mesh as am  # noqa: E402

RULES: list[tuple[str, dict]] = [
    ("today: observation, gamma 0.99; support pruning", {}),
    ("decay pass, D_min at 2 % of pass 1", {"decay": "pass", "decay_fraction": 0.02}),
    ("decay pass, D_min at 10 % of pass 1", {"decay": "pass", "decay_fraction": 0.1}),
    ("decay pass, D_min at 30 % of pass 1", {"decay": "pass", "decay_fraction": 0.3}),
    ("pruning literal (the paper's)", {"pruning": "literal"}),
    ("pruning none", {"pruning": "none"}),
]
HEADERS = ["scan", "rule", "K", "E̅ learned", "E̅ polished", "fit s"]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    args = ap.parse_args(argv)
    found = scans()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        am.fit(next(iter(found.values())), seed=0, progress=False)  # compile first
    t0 = time.perf_counter()
    sections = []
    for label, pieces in (("single network (`pieces=1`)", 1), ("piecewise model (default)",
                                                                "auto")):
        rows = []
        for name, scan in found.items():
            for rule, kw in RULES:
                k, seq, pol, sec = [], [], [], []
                for seed in args.seeds:
                    with warnings.catch_warnings():
                        warnings.simplefilter("ignore")
                        t = time.perf_counter()
                        net = am.fit(scan, seed=seed, pieces=pieces, progress=False, **kw)
                        sec.append(time.perf_counter() - t)
                    k.append(net.n_neurons)
                    seq.append(net.info["ebar_sequential"])
                    pol.append(net.info["ebar"])
                rows.append([name, rule, median_worst(k, ".0f"), median_worst(seq, ".5f"),
                             median_worst(pol, ".5f"), median_worst(sec, ".2f")])
                print(" | ".join(map(str, rows[-1])), flush=True)
        sections.append(f"### {label}\n\n" + table(HEADERS, rows))
    seeds = ", ".join(map(str, args.seeds))
    body = (f"## Separation decay and pruning rules (issue 17): seeds {seeds}\n\n"
            f"_Measured {time.strftime('%Y-%m-%d')} on {machine()}; "
            f"`python scripts/bench_learning_rules.py` ({time.perf_counter() - t0:.0f} s)._"
            "\n\n`am.fit(scan, pieces=..., **rule)` with every other option at its default "
            "(the weight polish on; the piecewise model also refines its tails and drops "
            "idle neurons). E̅ learned: the sequential network before the polish; E̅ "
            "polished: the network `fit` returns. Each cell: median over the seeds (worst "
            "seed).\n\n" + "\n\n".join(sections))
    print(body)
    write_section("learning-rules", body)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
