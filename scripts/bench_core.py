"""Core-engine benchmarks: fidelity, speed, baselines, pruning, polish, D_min.

    python scripts/bench_core.py            # everything, writes BENCHMARKS.md (~10 min)
    python scripts/bench_core.py --only speed fidelity

Uses the face range map shipped with pymeshlab and, when present, the Stanford
bunny scans in the folder $ASRBF_BUNNY_DIR names (when set).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np
from _bench_common import ROOT, machine, median_run, scans, table, timed, write_section
from scipy.interpolate import RBFInterpolator

import asrbf_mesh as am
from asrbf_mesh._polish import polish_weights

warnings.simplefilter("ignore")
SEEDS = (0, 1, 2)
PAPER_FACE_N = 18_370  # points of the paper's face scan


def run(scan: am.Scan, seed: int = 0, **kw) -> dict:
    kw.setdefault("pieces", 1)  # the paper's single network: these sections measure it
    net = am.fit(scan, seed=seed, progress=False, **kw)
    i = net.info
    counts = net.log_counters() or {}
    return {"net": net, "ebar": i["ebar"], "K": net.n_neurons, "nk": net.compression_ratio(),
            "sk": net.storage_ratio(), "mean": i["error_mean"], "std": i["error_std"],
            "us": i["us_per_step"], "learn": i["learn_seconds"], "fit": i["fit_seconds"],
            "polish": i["polish_seconds"], "added": counts.get("added", 0),
            "pruned": counts.get("pruned", 0),
            "seq": i["ebar_sequential"], "d_min": i["d_min"]}


def med(scan: am.Scan, **kw) -> dict:
    return median_run([run(scan, seed=s, **kw) for s in SEEDS])


# --------------------------------------------------------------------------------------------
def fidelity(S) -> str:
    targets = {"face": (0.0026, 50)}
    rows = []
    for name, scan in S.items():
        r = med(scan, polish="none")
        e_max, nk_min = targets.get(name, (0.0040, 20))
        ok = "yes" if r["ebar"] <= e_max and r["nk"] >= nk_min else "**no**"
        rows.append([name, scan.n_points, r["K"], r["ebar"], f"{r['nk']:.1f}:1",
                     f"{r['sk']:.1f}:1", r["mean"], r["std"], r["d_min"], r["us"],
                     f"E≤{e_max}, N:K≥{nk_min}: {ok}"])
    return ("### Fidelity of the paper's method (`--polish none`, E = E_ω = 0.01, ψ = 0.7, "
            "automatic D_min, 2 passes; median E̅ of seeds 0, 1, 2)\n\n" + table(
                ["scan", "N", "K", "E̅", "N:K", "3N:4K", "error mean (scan units)",
                 "error std", "D_min", "µs/step", "target"], rows))


def accuracy_curve(S) -> str:
    rows = []
    for name, scan in S.items():
        for e in (0.01, 0.005, 0.003):
            r = med(scan, polish="none", error_threshold=e, rms_threshold=e)
            rw = med(scan, error_threshold=e, rms_threshold=e)
            rows.append([name, e, r["d_min"], r["K"], f"{r['nk']:.1f}:1", r["ebar"], rw["ebar"]])
    return ("### Accuracy–size curve (E = E_ω; median of 3 seeds)\n\n" + table(
        ["scan", "E = E_ω", "D_min (auto)", "K", "N:K", "E̅ (polish none)",
         "E̅ (polish weights)"], rows))


def d_min_study(S) -> str:
    rows = []
    for name, scan in S.items():
        hf = am.to_height_field(scan.points)
        for label, d in (("2 × spacing", 2 * hf.spacing), ("auto = max(2 × spacing, E)", None),
                         ("paper's 0.01", 0.01)):
            r = med(scan, polish="none", d_min=d)
            rows.append([name, label, r["d_min"], r["K"], f"{r['nk']:.1f}:1", r["ebar"]])
    return ("### D_min (E = 0.01, polish none, median of 3 seeds)\n\n" + table(
        ["scan", "D_min rule", "D_min", "K", "N:K", "E̅"], rows))


def pruning(S) -> str:
    rows = []
    for name, scan in S.items():
        scaled = max(1000, round(1000 * scan.n_points / PAPER_FACE_N))
        for label, kw in (("none", {"pruning": "none"}),
                          ("literal, ω = 1000 (paper)", {"pruning": "literal"}),
                          (f"literal, ω = {scaled} (scaled with N)",
                           {"pruning": "literal", "prune_window": scaled}),
                          ("support (default)", {"pruning": "support"})):
            r = med(scan, polish="none", **kw)
            rows.append([name, label, r["K"], r["ebar"], r["added"], r["pruned"]])
    return ("### Pruning (polish none, median of 3 seeds)\n\n" + table(
        ["scan", "pruning", "K", "E̅", "added", "pruned"], rows))


def polish(S) -> str:
    rows = []
    for name, scan in S.items():
        for p in ("none", "weights", "full"):
            r = run(scan, seed=0, polish=p)
            rows.append([name, p, r["K"], r["ebar"], r["learn"], r["polish"]])
    return ("### Polish (seed 0; same sequential network, then the batch stage)\n\n" + table(
        ["scan", "polish", "K", "E̅", "learn s", "polish s"], rows))


def grid_lsq(hf: am.HeightField, k: int) -> float:
    """Least-squares weights of ~k Gaussians on a regular grid over the unit square."""
    g = max(2, round(np.sqrt(k)))
    u = (np.arange(g) + 0.5) / g
    centers = np.stack(np.meshgrid(u, u), -1).reshape(-1, 2)
    best = np.inf
    for factor in (0.7, 1.0, 1.5):  # the best width for the baseline
        widths = np.full(len(centers), factor / g)
        pr = polish_weights(hf.xy, hf.z, 0.0, centers, widths, np.zeros(len(centers)), 3.5,
                            ridge=1e-9)
        best = min(best, pr.ebar_after)
    return best


def baselines(S) -> str:
    rows = []
    for name, scan in S.items():
        hf = am.to_height_field(scan.points)
        t0 = time.perf_counter()
        net = am.fit(scan, seed=0, progress=False)
        f = net.evaluate(hf.xy, unit=True)
        ours_s = time.perf_counter() - t0
        ours = float(np.mean(np.abs(f - hf.z)))
        k = net.n_neurons
        t0 = time.perf_counter()
        tps = RBFInterpolator(hf.xy, hf.z, kernel="thin_plate_spline", neighbors=64)
        ft = tps(hf.xy)
        tps_s = time.perf_counter() - t0
        rng = np.random.default_rng(0)
        pick = rng.choice(hf.n_points, k, replace=False)
        t0 = time.perf_counter()
        tk = RBFInterpolator(hf.xy[pick], hf.z[pick], kernel="thin_plate_spline", neighbors=64)
        fk = tk(hf.xy)
        tk_s = time.perf_counter() - t0
        ek = float(np.mean(np.abs(fk - hf.z)))
        eg = grid_lsq(hf, k)
        win = "yes" if ours < min(ek, eg) else "**no**"
        faster = "yes" if ours_s < tps_s else "**no**"
        rows.append([name, k, ours, ours_s, float(np.mean(np.abs(ft - hf.z))), tps_s, faster,
                     ek, tk_s, eg, win])
    return ("### Side by side with the peers (same run; ours = default fit, polish `weights`, "
            "+ evaluation at all N points)\n\n" + table(
                ["scan", "K", "ours E̅", "ours fit+eval s", "TPS all points E̅",
                 "TPS all fit+eval s", "ours faster", "TPS on K random E̅", "s",
                 "LSQ grid of K E̅", "ours lowest E̅"], rows))


def speed(S) -> str:
    import numba

    scan = S["face"]
    runs = [run(scan, seed=0, polish="none") for _ in range(5)]
    us = float(np.median([r["us"] for r in runs]))
    learn = float(np.median([r["learn"] for r in runs]))
    steps = runs[0]["net"].info["steps"]
    hf = am.to_height_field(scan.points)
    nets = [run(scan, seed=s, polish="none", d_min=2 * hf.spacing)["net"] for s in range(5)]
    net = min(nets, key=lambda n: abs(n.n_neurons - 1300))  # the paper's K for the face
    rng = np.random.default_rng(0)
    q = rng.random((5_000_000, 2))
    lines = [f"Learning, warm (face map, {steps:,} steps, 2 passes, one thread): median "
             f"**{us:.2f} µs/step**, whole sequential fit {learn:.2f} s (5 runs)."]
    net.evaluate(q[:1000], unit=True)
    for threads in (1, os.cpu_count() or 1):
        numba.set_num_threads(threads)
        ts = [timed(net.evaluate, q, unit=True)[1] for _ in range(3)]
        lines.append(f"Evaluation, K = {net.n_neurons:,}, 5,000,000 random points in the unit "
                     f"square, {threads} thread(s): **{5e6 / min(ts) / 1e6:.1f} M points/s**.")
    numba.set_num_threads(os.cpu_count() or 1)
    with tempfile.TemporaryDirectory() as tmp:
        # the package source copied twice (two clones, no __pycache__). The first clone's
        # first fit, its prebuilt kernels turned off and its own empty kernel cache, is a
        # machine's very first run where no prebuilt set applies (JIT compile); the second
        # clone's first fit, with another empty cache, a machine's very first run with the
        # shipped kernels (asrbf_mesh._prebuilt); its second fit finds them cached
        base = {k: v for k, v in os.environ.items()
                if k not in ("NUMBA_CACHE_DIR", "ASRBF_NO_PREBUILT")}
        out = os.path.join(tmp, "f.asrbf")
        times = []
        for clone, extra in (("one", {"ASRBF_NO_PREBUILT": "1"}), ("two", {}), ("two", {})):
            root = os.path.join(tmp, clone)
            env = dict(base, ASRBF_CACHE_DIR=os.path.join(tmp, f"kernels-{clone}"), **extra)
            if not os.path.exists(root):
                shutil.copytree(os.path.join(ROOT, "asrbf_mesh"), os.path.join(root, "asrbf_mesh"),
                                ignore=shutil.ignore_patterns("__pycache__"))
            cmd = [sys.executable, "-c", "import sys; sys.path.insert(0, sys.argv[1]); "
                   "from asrbf_mesh.cli import main; sys.exit(main(sys.argv[2:]))", root,
                   "fit", str(am.face_map_path()), "-o", out, "--json"]
            t0 = time.perf_counter()
            res = subprocess.run(cmd, env=env, cwd=tmp, check=True, capture_output=True,
                                 text=True)
            times.append(time.perf_counter() - t0)
            if clone == "two" and len(times) == 2:
                first = json.loads(res.stdout)
        marks = Path(tmp, "kernels-two").rglob(".prebuilt")
        level = "; ".join(sorted({m.read_text().split()[0] for m in marks}))
        cold, fresh, warm = times
    fit_s = json.loads(res.stdout)["fit_seconds"]
    lines.append(f"`asrbf fit` on the face map as a fresh process, a machine's very first run: "
                 f"with the shipped kernels (set used: {level or 'none'}) **{fresh:.1f} s** "
                 f"(fit {first['fit_seconds']:.2f} s, of which compiling "
                 f"{first.get('compile_seconds') or 0.0:.2f} s); without them "
                 f"(`ASRBF_NO_PREBUILT=1`, JIT compile included) {cold:.1f} s; again "
                 f"{warm:.1f} s, of which the fit itself {fit_s:.2f} s (the rest is imports "
                 "and I/O).")
    return "### Speed\n\n" + "\n".join(f"- {x}" for x in lines)


SECTIONS = {"fidelity": fidelity, "curve": accuracy_curve, "dmin": d_min_study,
            "pruning": pruning, "polish": polish, "baselines": baselines,
            "speed": speed}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", nargs="*", choices=list(SECTIONS), default=list(SECTIONS))
    args = ap.parse_args()
    S = scans()
    S["face"].points  # noqa: B018  (the face map is required)
    am.fit(S["face"], seed=0, progress=False)  # JIT warm-up
    for name in args.only:
        t0 = time.perf_counter()
        body = SECTIONS[name](S)
        took = time.perf_counter() - t0
        head = (f"_Measured {time.strftime('%Y-%m-%d')} on {machine()}; "
                f"`python scripts/bench_core.py --only {name}` ({took:.0f} s)._\n\n")
        write_section(f"core-{name}", head + body)
        print(body, "\n", flush=True)


if __name__ == "__main__":
    os.chdir(ROOT)
    main()
