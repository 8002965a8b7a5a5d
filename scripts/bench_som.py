"""ASRBF vs SOM at equal node counts (paper section 5.4) on the benchmark scans.

Run from the repository root:  python scripts/bench_som.py [--seed 0] [--json OUT.json] [scan ...]

Then the SOM's speed: the compiled training loop against MiniSom (the reference it
reproduces, installed with the ``test`` extra) for the same steps, weights compared.
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
from asrbf_mesh.evaluate._metro import metro  # noqa: E402
from asrbf_mesh.evaluate._som import _ball_pivoting, compare_som, som_grid, train_som  # noqa: E402

ap = argparse.ArgumentParser()
ap.add_argument("names", nargs="*")
ap.add_argument("--seed", type=int, default=0)
ap.add_argument("--json", default=None)
ap.add_argument("--speed-steps", type=int, default=20_000,
                help="steps of the MiniSom speed comparison per scan (0: skip)")
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


def minisom_nodes(points: np.ndarray, n: int, seed: int, steps: int) -> tuple[np.ndarray, float]:
    """MiniSom with train_som's standardisation, start, schedule and order."""
    from minisom import MiniSom

    rows_, cols_ = som_grid(n)
    centre = points.mean(axis=0)
    scale = np.sqrt(np.linalg.eigvalsh(np.cov(points.T)).max())
    x = (points - centre) / scale
    som = MiniSom(rows_, cols_, 3, sigma=1.0, learning_rate=0.5,
                  decay_function="asymptotic_decay", sigma_decay_function="asymptotic_decay",
                  neighborhood_function="gaussian", topology="rectangular",
                  activation_distance="euclidean", random_seed=seed)
    som.pca_weights_init(x)
    order = np.arange(steps) % len(x)
    np.random.default_rng(seed).shuffle(order)
    t0 = time.perf_counter()
    for t in range(steps):
        sample = x[order[t]]
        som.update(sample, som.winner(sample), t, steps)
    return som.get_weights().reshape(-1, 3) * scale + centre, time.perf_counter() - t0


if args.speed_steps:
    speed = []
    for name, scan in scans(args.names or None).items():
        n = out[name]["n_neurons"]
        ref, ref_s = minisom_nodes(scan.points, n, args.seed, args.speed_steps)
        ours = train_som(scan.points, n, seed=args.seed, iterations=args.speed_steps,
                         progress=False)
        same = "yes" if np.array_equal(ours.nodes, ref) else (
            f"no (max {np.abs(ours.nodes - ref).max():.1e})")
        speed.append([name, f"{ours.n_nodes:,}", f"{1e6 * ref_s / args.speed_steps:.0f}",
                      f"{1e6 * ours.seconds / args.speed_steps:.1f}",
                      f"{ref_s / ours.seconds:.0f}x", same])
        print(name, speed[-1][2:], flush=True)
    print()
    print(f"SOM training speed, {args.speed_steps:,} steps (us per step):")
    print(table(["scan", "nodes", "MiniSom", "compiled", "speed-up", "same weights"], speed))
