"""Piecewise model vs the single network on synthetic height fields with known shape.

Run from the repository root:  python scripts/bench_pieces_synthetic.py [--seeds 0 1 2]

Smooth surfaces sampled on regular grids of the unit square as bare point clouds (what
an XYZ or NPY file holds): steep ones (slopes up to 6-13, past the segmentation's wall
angle), with and without Gaussian noise on z, and one of steep Gaussian bumps. Each is
fitted with each seed both ways (``am.fit(points, pieces=1)`` and ``am.fit(points)``).
Cells: median over the seeds (worst seed) of the pieces, neurons K, E-bar (mean |f - z|
in the unit cube) and fit seconds; the last columns the worst seed's E-bar and K of the
pieces over the single network's. Needs no data: the surfaces are made here.
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _bench_common import machine, median_worst, table, timed, write_section  # noqa: E402

import asrbf_mesh as am  # noqa: E402


def surfaces() -> dict[str, np.ndarray]:
    """The test surfaces, name -> (N, 3) points (noise drawn once, seed 0)."""
    rng = np.random.default_rng(0)
    out = {}
    g = np.linspace(0.0, 1.0, 100)
    x, y = np.meshgrid(g, g)
    for k in (2, 3, 4):
        z = np.sin(k * np.pi * x) * np.cos(k * np.pi * y)
        for noise in (0.0, 0.005):
            zz = z + noise * rng.standard_normal(z.shape)
            out[f"sin({k}πx)·cos({k}πy), 100², noise {noise:g}"] = np.c_[
                x.ravel(), y.ravel(), zz.ravel()]
    centres = rng.random((8, 2))
    z = sum(np.exp(-((x - a) ** 2 + (y - b) ** 2) / 0.01) for a, b in centres)
    zz = z + 0.0005 * rng.standard_normal(z.shape)
    out["8 Gaussian bumps (σ 0.07, height 1), 100², noise 0.0005"] = np.c_[
        x.ravel(), y.ravel(), zz.ravel()]
    g = np.linspace(0.0, 1.0, 300)
    x, y = np.meshgrid(g, g)
    z = np.sin(4 * x) * np.cos(3 * y)
    for noise in (0.0005, 0.002):
        zz = z + noise * rng.standard_normal(z.shape)
        out[f"sin(4x)·cos(3y), 300², noise {noise:g}"] = np.c_[x.ravel(), y.ravel(), zz.ravel()]
    # smooth surfaces whose noise is near E (the tails' threshold within its reach), drawn
    # after the others so that their noise stays as it was
    g = np.linspace(0.0, 1.0, 100)
    x, y = np.meshgrid(g, g)
    for name, z, noise in (("sin(x)·cos(y)", np.sin(x) * np.cos(y), 0.003),
                           ("sin(x)·cos(y)", np.sin(x) * np.cos(y), 0.01),
                           ("x² − y²", x ** 2 - y ** 2, 0.01),
                           ("(x − ½)(y − ½)", (x - 0.5) * (y - 0.5), 0.002)):
        zz = z + noise * rng.standard_normal(z.shape)
        out[f"{name}, 100², noise {noise:g}"] = np.c_[x.ravel(), y.ravel(), zz.ravel()]
    # steep surfaces with noise of 1 % of their depth range (the cut's noise scale)
    z = np.sin(3 * np.pi * x) * np.cos(3 * np.pi * y) + 0.02 * rng.standard_normal(x.shape)
    out["sin(3πx)·cos(3πy), 100², noise 0.02"] = np.c_[x.ravel(), y.ravel(), z.ravel()]
    z = sum(np.exp(-((x - a) ** 2 + (y - b) ** 2) / 0.01) for a, b in centres)
    z = z + 0.01 * rng.standard_normal(x.shape)
    out["8 Gaussian bumps (σ 0.07, height 1), 100², noise 0.01"] = np.c_[
        x.ravel(), y.ravel(), z.ravel()]
    # an airborne LiDAR tile: 60,000 points strewn at random over 200 x 200 m of rolling
    # ground with 12 box buildings 6-20 m tall, noise 5 cm (not on a lattice: Delaunay)
    xy = rng.uniform(0.0, 200.0, size=(60_000, 2))
    z = 5 * np.sin(xy[:, 0] / 40) * np.cos(xy[:, 1] / 55) + 0.02 * xy[:, 0]
    for _ in range(12):
        c, w, h = rng.uniform(20, 180, 2), rng.uniform(10, 25, 2), rng.uniform(6, 20)
        z[np.all(np.abs(xy - c) < w / 2, axis=1)] += h
    z = z + 0.05 * rng.standard_normal(len(z))
    out["LiDAR-like tile, 60,000 random points, 12 buildings, noise 0.05 m"] = np.c_[xy, z]
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    args = ap.parse_args(argv)
    found = surfaces()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        warm = next(iter(found.values()))
        am.fit(warm, seed=0, progress=False)  # compile the kernels first
        am.fit(warm, seed=0, pieces=1, progress=False)
    t0 = time.perf_counter()
    rows = []
    for name, pts in found.items():
        got: dict[str, list] = {"1": [], "auto": []}
        for seed in args.seeds:
            for model in ("1", "auto"):
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    net, sec = timed(am.fit, pts, seed=seed, pieces=model, progress=False)
                got[model].append((net.n_pieces, net.n_neurons, net.info["ebar"], sec))
        one, auto = np.array(got["1"]), np.array(got["auto"])
        rows.append([name, f"{len(pts):,}", median_worst(list(auto[:, 0]), ".0f"),
                     median_worst(list(one[:, 1]), ",.0f"), median_worst(list(auto[:, 1]), ",.0f"),
                     median_worst(list(one[:, 2]), ".5f"), median_worst(list(auto[:, 2]), ".5f"),
                     median_worst(list(one[:, 3]), ".2f"), median_worst(list(auto[:, 3]), ".2f"),
                     f"{(auto[:, 2] / one[:, 2]).max():.3f}",
                     f"{(auto[:, 1] / one[:, 1]).max():.2f}"])
        print(" | ".join(map(str, rows[-1])), flush=True)
    body = ("## Piecewise model on synthetic height fields (issue 14)\n\n"
            f"_Measured {time.strftime('%Y-%m-%d')} on {machine()}; "
            f"`python scripts/bench_pieces_synthetic.py --seeds "
            f"{' '.join(map(str, args.seeds))}` ({time.perf_counter() - t0:.0f} s)._\n\n"
            "Bare point clouds on regular grids of the unit square, and a LiDAR-like tile "
            "of points strewn at random (made by the script, noise on z drawn once). "
            "Single: `am.fit(points, pieces=1)`; pieces: "
            "`am.fit(points)` (the default). Cells: median over the seeds (worst seed); "
            "the last two columns: the worst seed's ratio of the pieces' E̅ (K) to the "
            "single network's.\n\n"
            + table(["surface", "N", "pieces", "K single", "K pieces", "E̅ single",
                     "E̅ pieces", "fit s single", "fit s pieces", "E̅ ratio (worst)",
                     "K ratio (worst)"], rows))
    print(body)
    write_section("pieces-synthetic", body)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
