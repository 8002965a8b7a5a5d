"""LOD benchmark (issue 3): resample / refit against quadric decimation, errors vs bytes.

    python scripts/bench_lod.py                  # face map and bun000, writes BENCHMARKS.md
    python scripts/bench_lod.py --scans face     # one scan
    python scripts/bench_lod.py --no-grid-study  # skip the refit grid-spacing study

For each scan, 4 levels by `resample` and by `refit` (asrbf_mesh._lod), and at each level's
face count the two QEM baselines (fast-simplification with preserve_border, pymeshlab's
quadric edge collapse with preserveboundary). Errors are Metro-style against the scan mesh
(pymeshlab Hausdorff filter, both directions, % of the scan's bounding-box diagonal).
Plots of RMS error vs bytes go to docs/img/lod_<scan>.png.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
import warnings

import matplotlib
import numpy as np
from _bench_common import ROOT, machine, scans, table, write_section

import asrbf_mesh as am
from asrbf_mesh._lod import lod_set, ply_bytes
from asrbf_mesh.evaluate import _meshlab, _simplify, write_lod_set

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

warnings.simplefilter("ignore")
IMG = ROOT / "docs" / "img"
LEVELS = 4
SEED = 0
LABELS = {"resample": "ours, resample", "refit": "ours, refit",
          "fast-simplification": "QEM fast-simplification (border kept)",
          "pymeshlab-quadric": "QEM pymeshlab (border kept)",
          "free": "QEM fast-simplification, border free, at our bytes"}


def kb(n: int | None) -> str:
    return "–" if n is None else f"{n / 1024:,.1f}"


def fmt_pct(v: float | None) -> str:
    if v is None:
        return "–"
    return "0" if abs(v) < 1e-9 else f"{v:.3g}"


def run_scan(name: str, scan: am.Scan, out_root: str) -> dict:
    """Both LOD methods with QEM baselines; plus QEM with a free border at our byte sizes."""
    res: dict = {"name": name, "sets": {}}
    for method in ("resample", "refit"):
        # the resample set's network is fitted here (as lod_set would): a level's network
        # is the compact one the set ships, without the fit's timings
        net = am.fit(scan, seed=SEED, progress=False) if method == "resample" else None
        t0 = time.perf_counter()
        levels = lod_set(scan, levels=LEVELS, method=method, seed=SEED, net=net)
        made = time.perf_counter() - t0
        man = write_lod_set(scan, levels, os.path.join(out_root, f"{name}-{method}"),
                            compare_qem=True)
        res["sets"][method] = {"manifest": man, "seconds": made,
                               "fit_seconds": None if net is None else net.info["fit_seconds"]}
    # QEM with a free border at the byte sizes of our networks (equal storage)
    ref = am.Mesh(*_meshlab.compact(scan.points, scan.faces))
    free = []
    targets: list[int] = []
    for nbytes in sorted({r["bytes"] for s in res["sets"].values()
                          for r in s["manifest"]["levels"]}):
        if not targets or nbytes > 1.02 * targets[-1]:
            targets.append(nbytes)
    for nbytes in targets:
        ours = [f"{m} L{r['index']}: {r['rms_pct']:.3g}" for m, st in res["sets"].items()
                for r in st["manifest"]["levels"] if abs(r["bytes"] - nbytes) <= 0.02 * nbytes]
        free.append(free_qem(ref, nbytes) | {"ours": "; ".join(ours)})
    res["free"] = free
    return res


def free_qem(ref: am.Mesh, nbytes: int) -> dict:
    """QEM (fast-simplification, free border) whose binary PLY takes about ``nbytes``."""
    f = max(int(nbytes / 19), 8)  # about 12 V + 13 F with V ~ F / 2
    for _ in range(3):
        t = time.perf_counter()
        mesh = _simplify.fast_decimate(ref, target_faces=f, preserve_border=False)
        sec = time.perf_counter() - t
        got = ply_bytes(mesh.n_vertices, mesh.n_faces)
        if abs(got - nbytes) <= 0.05 * nbytes or (got > nbytes and f <= 8):
            break
        f = max(int(f * nbytes / got), 8)
    d = _meshlab.hausdorff(mesh, ref)
    return {"target_bytes": nbytes, "bytes": got, "faces": mesh.n_faces,
            "mean_pct": d["mean_pct"], "rms_pct": d["rms_pct"],
            "hausdorff_pct": d["hausdorff_pct"], "seconds": sec}


def lod_table(res: dict) -> str:
    rows = []
    for method in ("resample", "refit"):
        man = res["sets"][method]["manifest"]
        qem = {(q["index"], q["method"]): q for q in man["qem"]}
        for lv in man["levels"]:
            i = lv["index"]
            rows.append([f"{i}", f"**{method}**", f"{lv['faces']:,}", kb(lv["bytes"]),
                         kb(lv["mesh_bytes"]), fmt_pct(lv["mean_pct"]), fmt_pct(lv["rms_pct"]),
                         fmt_pct(lv["hausdorff_pct"]), f"{lv['seconds']:.2f}",
                         f"K = {lv['n_neurons']:,}, D_min = {lv['d_min']:g}, "
                         f"grid {lv['spacing_abs']:.3g}, footprint {kb(lv['footprint_bytes'])} KB, "
                         f"border ≤ {lv['border_offset_abs']:.2g}"])
            for base in ("fast-simplification", "pymeshlab-quadric"):
                q = qem[(i, base)]
                note = "" if q["reached"] else f"target {q['target_faces']:,} not reached"
                if q["note"] and "itself" in q["note"]:
                    note = f"target {q['target_faces']:,} > scan: the scan itself"
                rows.append([f"{i}", base, f"{q['faces']:,}", kb(q["bytes"]), kb(q["bytes"]),
                             fmt_pct(q["mean_pct"]), fmt_pct(q["rms_pct"]),
                             fmt_pct(q["hausdorff_pct"]), f"{q['seconds']:.2f}", note])
    return table(["level", "method", "faces", "bytes (KB)", "mesh as PLY (KB)", "mean %",
                  "RMS %", "Hausdorff %", "seconds", "notes"], rows)


def free_table(res: dict) -> str:
    rows = [[kb(f["target_bytes"]), f["ours"], kb(f["bytes"]), f"{f['faces']:,}",
             fmt_pct(f["mean_pct"]), fmt_pct(f["rms_pct"]), fmt_pct(f["hausdorff_pct"])]
            for f in res["free"]]
    return table(["our network (KB)", "our RMS % at that size", "QEM mesh as PLY (KB)",
                  "QEM faces", "QEM mean %", "QEM RMS %", "QEM Hausdorff %"], rows)


def _is_scan_itself(q: dict) -> bool:
    return bool(q["note"]) and "itself" in q["note"]


def plot(res: dict) -> str:
    """RMS error vs bytes (left) and vs faces (right), log-log."""
    fig, axes = plt.subplots(1, 2, figsize=(12.0, 5.0), dpi=110)
    styles = {"resample": ("o", "C0", ":"), "refit": ("s", "C1", "-"),
              "fast-simplification": ("^", "C2", "--"), "pymeshlab-quadric": ("v", "C3", "--"),
              "free": ("x", "C4", "-.")}
    series: dict[str, list[tuple]] = {k: [] for k in styles}
    for method in ("resample", "refit"):
        man = res["sets"][method]["manifest"]
        series[method] = [(lv["bytes"], lv["faces"], lv["rms_pct"], lv["index"])
                          for lv in man["levels"]]
        for q in man["qem"]:
            if not _is_scan_itself(q):
                series[q["method"]].append((q["bytes"], q["faces"], q["rms_pct"], q["index"]))
    series["free"] = [(f["bytes"], f["faces"], f["rms_pct"], None) for f in res["free"]]
    for ax, col, xlabel in (
            (axes[0], 0, "bytes (ours: .asrbf network file; QEM: mesh as float32 binary PLY)"),
            (axes[1], 1, "faces")):
        for key, pts in series.items():
            if not pts:
                continue
            pts = sorted(set(pts), key=lambda p: (p[col], p[2]))
            m, c, ls = styles[key]
            ax.plot([p[col] for p in pts], [p[2] for p in pts], marker=m, color=c, ls=ls,
                    label=LABELS[key])
            if key in ("resample", "refit"):
                for p in pts:
                    dy = -11 * p[3] if (key == "resample" and col == 0) else 3
                    ax.annotate(f"L{p[3]}", (p[col], p[2]), fontsize=7, color=c,
                                xytext=(5, dy), textcoords="offset points")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel(xlabel)
        ax.grid(True, which="both", alpha=0.3)
    axes[0].set_ylabel("RMS distance to the scan, % of bbox diagonal (Metro, both ways)")
    axes[0].set_title(f"{res['name']}: error vs storage")
    axes[1].set_title(f"{res['name']}: error vs faces")
    axes[1].legend(fontsize=7, loc="lower left")
    fig.tight_layout()
    IMG.mkdir(parents=True, exist_ok=True)
    path = IMG / f"lod_{res['name']}.png"
    fig.savefig(path)
    plt.close(fig)
    return os.path.relpath(path, ROOT)


def grid_study(scan: am.Scan) -> str:
    """RMS of refit networks meshed at grids of D_min / k, against the scan's own spacing."""
    rows = []
    for d_min in (0.01, 0.02, 0.04, 0.08):
        net = am.fit(scan, seed=SEED, d_min=d_min, progress=False)
        g = float(np.sqrt(net.frame.scale[0] * net.frame.scale[1]))
        fine = net.info["spacing"] * g
        cells = []
        for label, s in (("D_min", d_min * g), ("D_min/2", d_min * g / 2),
                         ("D_min/4", d_min * g / 4), ("scan spacing", fine)):
            mesh = am.reconstruct(net, spacing_abs=max(s, fine), footprint=scan, mode="scan")
            d = _meshlab.hausdorff(mesh, scan.to_mesh())
            cells.append((label, mesh.n_faces, d["rms_pct"]))
        limit = cells[-1][2]
        rows.append([d_min, net.n_neurons] + [
            f"{r:.3f} ({f / 1000:.1f}k f, {100 * (r / limit - 1):+.0f} %)"
            for _, f, r in cells[:-1]] + [f"{limit:.3f} ({cells[-1][1] / 1000:.0f}k f)"])
    return table(["D_min", "K", "grid D_min: RMS %", "grid D_min/2", "grid D_min/4",
                  "grid = scan spacing (the network's own error)"], rows)


def summary(res: dict) -> list[str]:
    """A few computed comparisons for the reading."""
    out = []
    for method in ("resample", "refit"):
        man = res["sets"][method]["manifest"]
        q = {(r["index"], r["method"]): r for r in man["qem"]}
        for lv in man["levels"]:
            best = min((q[(lv["index"], b)] for b in ("fast-simplification",
                                                       "pymeshlab-quadric")),
                       key=lambda r: r["rms_pct"])
            if best["rms_pct"] > 0:
                out.append(f"{method} L{lv['index']}: RMS {lv['rms_pct']:.3g} % vs best QEM "
                           f"{best['rms_pct']:.3g} % ({best['method']}, {best['faces']:,} "
                           f"faces); bytes {kb(lv['bytes'])} KB vs {kb(best['bytes'])} KB")
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scans", nargs="*", default=["face", "bun000"])
    ap.add_argument("--no-grid-study", action="store_true")
    args = ap.parse_args()
    t0 = time.perf_counter()
    S = scans(args.scans)
    am.fit(S[next(iter(S))], seed=0, progress=False)  # JIT warm-up
    parts = [
        "### Levels of detail (issue 3): `resample`, `refit` and quadric decimation\n",
        "Four levels per method (`asrbf_mesh._lod.lod_set`, seed 0; level 0 is the finest). "
        "`resample`: the default network sampled at the scan's spacing × 2^i. `refit`: one "
        "fit per level with D_min = 0.01 × 2^i, meshed at a grid of D_min / 4 (not finer than "
        "the scan). Both mesh the scan's footprint (`reconstruct(..., mode=\"scan\")`). QEM: "
        "the scan mesh decimated to each level's face count, border preserved, by "
        "fast-simplification 0.2 (`preserve_border=True`) and pymeshlab 2025.7 "
        "(`meshing_decimation_quadric_edge_collapse`, `preserveboundary=True`, every parameter "
        "explicit). **bytes**: ours = the `.asrbf` network file (float32 parameters, deflated, "
        "about 2 KB of JSON metadata, no learning log; a `resample` set shares one network, so "
        "all its levels show the same size; the footprint bitmap needed to rebuild a level is "
        "listed apart in the notes); QEM = the mesh as a float32 binary PLY (12 bytes per "
        "vertex, 13 per face). **Errors**: Metro-style, pymeshlab's Hausdorff filter in both "
        "directions between the level and the scan mesh (unreferenced scan points ignored), "
        "all vertices plus max(V, 10,000) seeded area samples per direction; mean and RMS "
        "are area-weighted and averaged over the two directions, Hausdorff is the larger "
        "maximum; % of the scan's bounding-box diagonal. seconds: `refit` = fit + grid, "
        "`resample` = grid only (the shared fit is given below), QEM = decimation. "
        "\"border ≤\" is the largest view-plane distance (scan units) from a border vertex "
        "of the level to the scan's border; \"grid\" is the level's grid spacing.\n",
    ]
    with tempfile.TemporaryDirectory() as tmp:
        for name, scan in S.items():
            t = time.perf_counter()
            res = run_scan(name, scan, tmp)
            img = plot(res)
            fit_s = res["sets"]["resample"]["fit_seconds"]
            parts.append(f"#### {name} ({scan.n_points:,} points, {scan.n_faces:,} faces)\n")
            parts.append(lod_table(res) + "\n")
            parts.append(f"The `resample` network took {fit_s:.2f} s to fit. "
                         f"QEM with a free border (fast-simplification, "
                         f"`preserve_border=False`) at the byte sizes of our networks:\n")
            parts.append(free_table(res) + "\n")
            parts.append(f"![LOD error vs bytes, {name}]({img})\n")
            print(f"{name}: {time.perf_counter() - t:.0f} s", flush=True)
            for line in summary(res):
                print("  ", line)
    if not args.no_grid_study and "face" in S:
        parts.append("#### `refit` grid spacing (face map): RMS % of each network meshed at "
                     "grids of D_min / k, and its excess over the same network at the scan's "
                     "spacing\n")
        parts.append(grid_study(S["face"]) + "\n")
    took = time.perf_counter() - t0
    head = (f"_Measured {time.strftime('%Y-%m-%d')} on {machine()}; "
            f"`python scripts/bench_lod.py` ({took:.0f} s)._\n\n")
    body = head + "\n".join(parts)
    write_section("lod", body)
    print(body)


if __name__ == "__main__":
    os.chdir(ROOT)
    main()
