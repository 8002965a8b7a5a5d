"""ASRBF vs SOM at equal node counts (paper section 5.4) on the benchmark scans.

Run from the repository root:  python scripts/bench_som.py [--seed 0] [--json OUT.json] [scan ...]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import numpy as np  # noqa: E402
from _bench_common import scans, table  # noqa: E402

import asrbf_mesh as am  # noqa: E402
from asrbf_mesh.evaluate.metro import metro  # noqa: E402
from asrbf_mesh.evaluate.som import _ball_pivoting, compare_som  # noqa: E402

ap = argparse.ArgumentParser()
ap.add_argument("names", nargs="*")
ap.add_argument("--seed", type=int, default=0)
ap.add_argument("--json", default=None)
args = ap.parse_args()

rows, out = [], {}
for name, scan in scans(args.names or None).items():
    t0 = time.perf_counter()
    net = am.fit(scan, seed=args.seed, progress=False)
    fit_s = time.perf_counter() - t0
    c = compare_som(scan, net, seed=args.seed, progress=False)
    # the same SOM with its dead nodes kept (no retraining)
    kept = metro(_ball_pivoting(c.som_map.nodes, "SOM nodes"), scan.to_mesh(), seed=args.seed)
    a, s = c.asrbf, c.som
    d = c.to_dict() | {"fit_seconds": fit_s, "som_with_dead": kept.to_dict()}
    out[name] = d
    wins = "".join("y" if w else "n" for w in c.asrbf_wins.values())
    rows.append([name, c.n_neurons, f"{c.som_shape[0]}x{c.som_shape[1]}", c.som_dead,
                 c.asrbf_mesh.n_vertices,
                 f"{a.hausdorff_pct:.2f} / {a.mean_pct:.3f} / {a.rms_pct:.3f}",
                 f"{s.hausdorff_pct:.2f} / {s.mean_pct:.3f} / {s.rms_pct:.3f}",
                 f"{kept.hausdorff_pct:.2f} / {kept.mean_pct:.3f} / {kept.rms_pct:.3f}",
                 wins, f"{fit_s:.1f}", f"{c.seconds['som']:.0f}",
                 f"{c.seconds['vertices'] + c.seconds['ball_pivoting']:.1f}",
                 f"{c.seconds['metro']:.1f}"])
    print(name, json.dumps({k: d[k] for k in ("n_neurons", "som_shape", "som_dead")}),
          rows[-1][5:9], flush=True)

keys = ("hausdorff_pct", "mean_pct", "rms_pct")
avg_a = [np.mean([out[n]["asrbf"][k] for n in out]) for k in keys]
avg_s = [np.mean([out[n]["som"][k] for n in out]) for k in keys]
avg_k = [np.mean([out[n]["som_with_dead"][k] for n in out]) for k in keys]
rows.append(["average", "", "", "", "", " / ".join(f"{v:.3g}" for v in avg_a),
             " / ".join(f"{v:.3g}" for v in avg_s), " / ".join(f"{v:.3g}" for v in avg_k),
             "", "", "", "", ""])
print()
print(table(["scan", "K", "SOM grid", "dead", "vertices (each)",
             "ours H / mean / RMS %", "SOM H / mean / RMS % (dead dropped)",
             "SOM with dead nodes", "ours wins H,mean,RMS", "fit s", "SOM s",
             "sample+BPA s", "Metro s"], rows))
if args.json:
    Path(args.json).write_text(json.dumps(out, indent=1, default=float))
