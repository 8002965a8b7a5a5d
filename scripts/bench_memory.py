"""Peak memory of a fit against the number of points N: O(N + K), up to 2 million points.

Run from the repository root:  python scripts/bench_memory.py [--sizes N ...]

Each size runs in a fresh process: a synthetic range scan (a sum of Gaussian bumps
over 1,000 x 750 mm with 0.05 mm noise, points at random in (x, y)) is made, then fitted
with the package defaults (seed 0). The process's peak RSS (``ru_maxrss``) is read
at the end, and the resident set (``VmRSS``) after the imports and once the points exist;
the fit's own share is the peak minus the resident set before the fit. A line fitted
through (N, fit share) gives the bytes per point; K shows the O(K) part. Writes the ``memory``
section of BENCHMARKS.md.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import numpy as np  # noqa: E402
from _bench_common import machine, table, write_section  # noqa: E402

CHILD = r"""
import json, resource, sys, time
import numpy as np
import asrbf_mesh as am

def rss():  # peak resident set so far, MiB (Linux: ru_maxrss in KiB)
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024

def now():  # resident set now, MiB
    with open("/proc/self/status") as fh:
        return next(int(l.split()[1]) for l in fh if l.startswith("VmRSS:")) / 1024

n = int(sys.argv[1])
# warm the compiled kernels on a small fit, so the big fit's peak is the fit's own
rng = np.random.default_rng(1)
xy = rng.random((2000, 2))
am.fit(np.c_[xy, np.sin(3 * xy[:, 0])], seed=0, progress=False)
base = now()
rng = np.random.default_rng(0)
xy = rng.random((n, 2)) * [1000.0, 750.0]
c = rng.random((12, 2)) * [1000.0, 750.0]
a = rng.normal(0, 40, 12)
s = rng.uniform(60, 250, 12)
z = np.zeros(n)
for i in range(12):
    z += a[i] * np.exp(-((xy - c[i]) ** 2).sum(1) / (2 * s[i] ** 2))
pts = np.c_[xy, z + rng.normal(0, 0.05, n)]
del xy, z
data = now()
t0 = time.perf_counter()
net = am.fit(pts, seed=0, progress=False)
secs = time.perf_counter() - t0
peak = rss()
print(json.dumps({"n": n, "base_mib": base, "data_mib": data, "peak_mib": peak,
                  "seconds": secs, "k": net.n_neurons, "ebar": net.info["ebar"],
                  "points_mib": pts.nbytes / 2**20}))
"""


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--sizes", type=int, nargs="*",
                    default=[250_000, 500_000, 1_000_000, 2_000_000])
    args = ap.parse_args()
    runs = []
    for n in args.sizes:
        out = subprocess.run([sys.executable, "-c", CHILD, str(n)], capture_output=True,
                             text=True, check=True)
        runs.append(json.loads(out.stdout.strip().splitlines()[-1]))
        r = runs[-1]
        print(f"N = {n:>9,}: fit {r['seconds']:.1f} s, K = {r['k']:,}, "
              f"peak {r['peak_mib']:.0f} MiB (imports {r['base_mib']:.0f}, "
              f"+points {r['data_mib'] - r['base_mib']:.0f}, "
              f"+fit {r['peak_mib'] - r['data_mib']:.0f})", flush=True)
    n = np.array([r["n"] for r in runs], float)
    fit_mib = np.array([r["peak_mib"] - r["data_mib"] for r in runs])
    slope, icpt = np.polyfit(n, fit_mib, 1)
    resid = fit_mib - (slope * n + icpt)
    rows = [[f"{r['n']:,}", f"{r['k']:,}", f"{r['ebar']:.5f}", f"{r['seconds']:.1f}",
             f"{r['base_mib']:.0f}", f"{r['data_mib'] - r['base_mib']:.0f}",
             f"{r['peak_mib'] - r['data_mib']:.0f}", f"{r['peak_mib']:.0f}"] for r in runs]
    body = "\n".join([
        "## Memory of a fit (O(N + K))", "",
        "`python scripts/bench_memory.py` (" + machine() + "). Each size in a fresh process: "
        "a synthetic scan (12 Gaussian bumps over 1,000 × 750 mm, 0.05 mm noise), fitted with "
        "the defaults, seed 0. Resident set (`VmRSS`) after the imports and a warm-up fit and "
        "once the points exist; peak RSS (`ru_maxrss`) at the end.", "",
        table(["N", "K", "E̅", "fit s", "imports MiB", "points MiB", "fit MiB (peak − before)",
               "peak RSS MiB"], rows), "",
        f"The fit's memory grows linearly in N: {slope * 2**20:.0f} bytes per point "
        f"(least squares over the sizes, largest residual {np.abs(resid).max():.0f} MiB), "
        f"i.e. {slope * 2**20 / 24:.1f}× the (N, 3) float64 input; the O(K) part (network, "
        "covariance blocks, neighbour grid) is small beside it at these K.",
    ])
    write_section("memory", body)
    print(body)


if __name__ == "__main__":
    main()
