"""Streaming fit of a 20-million-point synthetic scan: peak memory, time, accuracy.

Run from the repository root:  python scripts/bench_stream.py [--points 20000000] [--dir /tmp]

1. Writes a synthetic range scan (a ripple and 30 Gaussian bumps over 1,000 x 750 mm,
   0.05 mm noise, points at random in (x, y)) as an (N, 3) float64 NPY, block by block.
2. ``asrbf fit SCAN --stream`` in a child process: wall time and the child's peak
   resident set (``wait4``'s ``ru_maxrss``).
3. An in-memory ``asrbf_mesh.fit`` of a 2-million-point random subsample, in a child
   process (time, peak memory); both networks' E-bar is then measured over all N points
   (block by block) as well as over the subsample.

Writes the ``streaming`` section of BENCHMARKS.md.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import numpy as np  # noqa: E402
from _bench_common import machine, table, write_section  # noqa: E402

import asrbf_mesh as am  # noqa: E402
from asrbf_mesh._stream import open_points  # noqa: E402

BLOCK = 1 << 20


def surface(xy: np.ndarray, rng_params: dict) -> np.ndarray:
    """Depth (mm) of the synthetic scan at (M, 2) points (mm)."""
    x, y = xy[:, 0], xy[:, 1]
    z = 8.0 * np.sin(x / 37.0) * np.cos(y / 29.0)
    for (cx, cy), a, s in zip(rng_params["c"], rng_params["a"], rng_params["s"], strict=True):
        z += a * np.exp(-((x - cx) ** 2 + (y - cy) ** 2) / (2 * s * s))
    return z


def write_scan(path: Path, n: int) -> dict:
    rng = np.random.default_rng(0)
    params = {"c": rng.random((30, 2)) * [1000.0, 750.0], "a": rng.normal(0, 25, 30),
              "s": rng.uniform(30, 150, 30)}
    out = np.lib.format.open_memmap(path, mode="w+", dtype=np.float64, shape=(n, 3))
    for lo in range(0, n, BLOCK):
        m = min(BLOCK, n - lo)
        xy = rng.random((m, 2)) * [1000.0, 750.0]
        out[lo:lo + m] = np.c_[xy, surface(xy, params) + rng.normal(0, 0.05, m)]
    out.flush()
    del out
    return params


def run_measured(argv: list[str]) -> tuple[str, float, float]:
    """Run a command and measure its peak RSS with wait4 (before the status is reaped)."""
    t0 = time.perf_counter()
    out_path = Path(f"/tmp/bench_stream_{os.getpid()}.out")
    with open(out_path, "w") as fh:
        pid = subprocess.Popen(argv, stdout=fh).pid
        _, status, usage = os.wait4(pid, 0)
    secs = time.perf_counter() - t0
    if status != 0:
        raise SystemExit(f"{' '.join(argv[:5])} failed with status {status}")
    out = out_path.read_text()
    out_path.unlink()
    return out, secs, usage.ru_maxrss / 1024


SUBSAMPLE_FIT = r"""
import json, sys, time
import numpy as np
import asrbf_mesh as am
path, m, out = sys.argv[1], int(sys.argv[2]), sys.argv[3]
arr = np.load(path, mmap_mode="r")
idx = np.sort(np.random.default_rng(1).choice(len(arr), m, replace=False))
pts = np.array(arr[idx])
del arr
t0 = time.perf_counter()
net = am.fit(pts, seed=0, progress=False)
secs = time.perf_counter() - t0
net.save(out)
print(json.dumps({"seconds": secs, "k": net.n_neurons, "ebar": net.info["ebar"]}))
"""


def ebar_over(net: am.Network, path: Path) -> float:
    """Mean |f - z| in the unit cube of ``net`` over every point of the file."""
    src = open_points(path, BLOCK)
    total = 0.0
    for b in range(src.n_blocks):
        u = net.frame.to_unit(src.block(b))
        total += float(np.abs(np.clip(u[:, 2], 0, 1)
                              - net.evaluate(np.clip(u[:, :2], 0, 1), unit=True)).sum())
    return total / src.n


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--points", type=int, default=20_000_000)
    ap.add_argument("--subsample", type=int, default=2_000_000)
    ap.add_argument("--dir", type=Path, default=Path("/tmp"))
    args = ap.parse_args()
    args.dir.mkdir(parents=True, exist_ok=True)
    scan = args.dir / f"synthetic_{args.points}.npy"
    if not scan.exists() or scan.stat().st_size < 24 * args.points:
        t0 = time.perf_counter()
        write_scan(scan, args.points)
        print(f"wrote {scan} ({scan.stat().st_size / 2**20:,.0f} MiB) in "
              f"{time.perf_counter() - t0:.0f} s", flush=True)
    net_s = args.dir / "stream.asrbf"
    out, s_secs, s_rss = run_measured([sys.executable, "-m", "asrbf_mesh.cli", "fit",
                                       str(scan), "-o", str(net_s), "--stream", "--json"])
    s = json.loads(out)
    print(f"streaming: {s_secs:.0f} s, peak {s_rss:.0f} MiB, K = {s['n_neurons']:,}, "
          f"E-bar {s['ebar']:.5f}", flush=True)
    net_m = args.dir / "subsample.asrbf"
    out, m_secs, m_rss = run_measured([sys.executable, "-c", SUBSAMPLE_FIT, str(scan),
                                       str(args.subsample), str(net_m)])
    m = json.loads(out)
    print(f"in memory ({args.subsample:,}): {m_secs:.0f} s, peak {m_rss:.0f} MiB, "
          f"K = {m['k']:,}, E-bar {m['ebar']:.5f}", flush=True)
    stream_net, sub_net = am.Network.load(net_s), am.Network.load(net_m)
    e_sub_all = ebar_over(sub_net, scan)
    info = stream_net.info
    rows = [
        ["streaming fit, all points", f"{args.points:,}", f"{s['n_neurons']:,}",
         f"{s_secs:.0f}", f"{s_rss:.0f}", f"{s['ebar']:.5f}", f"{s['ebar']:.5f}",
         f"{s['steps'] * s['us_per_step'] / 1e6:.0f} / {s['polish_seconds']:.0f}"],
        [f"in-memory fit, random {args.subsample:,}", f"{args.subsample:,}", f"{m['k']:,}",
         f"{m_secs:.0f}", f"{m_rss:.0f}", f"{m['ebar']:.5f}", f"{e_sub_all:.5f}", ""],
    ]
    how = "exact" if info.get("spacing_exact") else "from tiles of the footprint"
    body = "\n".join([
        "## Streaming fit of a 20-million-point scan", "",
        f"`python scripts/bench_stream.py --points {args.points}` ({machine()}). A synthetic "
        "range scan (a ripple and 30 Gaussian bumps over 1,000 × 750 mm, 0.05 mm noise, "
        f"points at random in (x, y)) written as a {scan.stat().st_size / 2**30:.2f} GiB "
        "float64 NPY. `asrbf fit SCAN --stream` (defaults: blocks of 65,536 points, 16 "
        "blocks learned together, 2 passes, weight polish) against `asrbf_mesh.fit` in "
        "memory on a random subsample; each in a fresh process, peak resident set from "
        "`wait4`. E̅ in the unit cube of each network's own frame.", "",
        table(["run", "points fitted", "K", "wall s", "peak RSS MiB", "E̅ (fitted points)",
               "E̅ over all points", "learn / polish s"], rows), "",
        f"Sampling spacing ({how}): {info['spacing']:.3g}, D_min {info['d_min']:.3g} "
        "(unit square).",
    ])
    write_section("streaming", body)
    print(body)


if __name__ == "__main__":
    main()
