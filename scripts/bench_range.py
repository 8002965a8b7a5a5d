"""Grid hole filling (issue 16): ``fill_grid`` against raster peers on an SRTM tile.

    python scripts/bench_range.py                 # seeds 0-9, every method
    python scripts/bench_range.py --seeds 0 1 --methods ours gdal

Ground truth: matplotlib's sample SRTM tile ``jacksboro_fault_dem.npz`` (344 x 403 cells
of 3 arc-seconds, read with :func:`asrbf_mesh._range.read_grid_array`). For each seed,
6 disk voids of radius U(0.03, 0.06) x the larger side (in cells) are cut at random
valid centres (``numpy.random.default_rng(seed)``), inside the tile (at least 2 cells
from its edge: a void open to the border is outside the scan for ``fill_grid``) and not
overlapping; the removed elevations are the truth. Methods:

* ``ours``: :func:`asrbf_mesh._grid_fill.fill_grid` (network fitted on the voided grid,
  fit included in the seconds);
* ``gdal``: GDAL FillNodata (``rasterio.fill.fillnodata``, inverse-distance weighting
  with smoothing passes 0, search distance = the largest void's diameter);
* ``ns`` / ``telea``: OpenCV ``cv2.inpaint`` (Navier-Stokes / Telea) on the float32
  elevation (``cv2.inpaint`` takes 8-bit, 16-bit unsigned or 32-bit float single-channel
  images: float32 keeps the metres without quantisation), inpaint radius 5 cells;
* ``linear`` / ``cubic``: ``scipy.interpolate.griddata`` of the valid cells within a
  margin (half the void's radius, at least 3 cells) around each void.

All methods run with one BLAS thread (set before numpy is imported; override with
``OPENBLAS_NUM_THREADS``). Reported: RMS of the fill over the void cells in % of the
tile's elevation range, per method and seed, and wall seconds per fill. The peers are
optional (imported lazily); a missing one is reported as such.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
import warnings
from importlib import metadata
from pathlib import Path

# One BLAS thread for every method: on the shared 2-core machine (load 5) threaded
# OpenBLAS made scipy's LinearNDInterpolator take up to 30 s per void instead of 3 ms.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from asrbf_mesh._grid_fill import fill_grid  # noqa: E402
from asrbf_mesh._range import RangeGrid, read_grid_array  # noqa: E402

METHODS = ("ours", "gdal", "ns", "telea", "linear", "cubic")
N_VOIDS = 6


def load_tile() -> RangeGrid:
    """The SRTM sample tile as a RangeGrid."""
    from matplotlib import cbook

    return read_grid_array(cbook.get_sample_data("jacksboro_fault_dem.npz", asfileobj=False))


def cut_voids(z: np.ndarray, seed: int) -> list[tuple[np.ndarray, float]]:
    """Masks and radii (cells) of ``N_VOIDS`` non-overlapping disks at valid centres."""
    rng = np.random.default_rng(seed)
    H, W = z.shape
    rr, cc = np.mgrid[:H, :W]
    taken = np.zeros((H, W), dtype=bool)
    placed: list[tuple[float, float, float]] = []
    out = []
    tries = 0
    while len(out) < N_VOIDS:
        tries += 1
        if tries > 10_000:
            raise RuntimeError("cannot place the voids")
        r = rng.uniform(0.03, 0.06) * max(H, W)
        cy, cx = rng.uniform(0, H), rng.uniform(0, W)
        if not np.isfinite(z[int(cy), int(cx)]):
            continue
        if min(cy, cx, H - 1 - cy, W - 1 - cx) < r + 2:  # open to the border: no hole
            continue
        if any(np.hypot(cy - y, cx - x) < r + q + 2 for y, x, q in placed):
            continue
        disk = (rr - cy) ** 2 + (cc - cx) ** 2 <= r * r
        placed.append((cy, cx, r))
        taken |= disk
        out.append((disk, r))
    return out


def _gdal(z: np.ndarray, voids: np.ndarray, radius: float) -> np.ndarray:
    from rasterio.fill import fillnodata

    img = np.where(voids, 0.0, z).astype(np.float32)
    return fillnodata(img, mask=(~voids).astype(np.uint8),
                      max_search_distance=float(2 * radius + 2), smoothing_iterations=0
                      ).astype(np.float64)


def _cv(z: np.ndarray, voids: np.ndarray, flag_name: str) -> np.ndarray:
    import cv2

    img = np.where(voids, 0.0, z).astype(np.float32)
    flag = cv2.INPAINT_NS if flag_name == "ns" else cv2.INPAINT_TELEA
    return cv2.inpaint(img, voids.astype(np.uint8), 5, flag).astype(np.float64)


def _griddata(z: np.ndarray, disks: list[tuple[np.ndarray, float]], method: str) -> np.ndarray:
    from scipy import ndimage
    from scipy.interpolate import griddata

    out = z.copy()
    valid = np.isfinite(z)
    for disk, r in disks:
        margin = max(3, int(np.ceil(0.5 * r)))
        near = ndimage.binary_dilation(disk, iterations=margin) & valid
        src = np.argwhere(near)
        dst = np.argwhere(disk)
        out[disk] = griddata(src, z[near], dst, method=method)
    return out


def run_seed(grid: RangeGrid, seed: int, methods: tuple[str, ...]
             ) -> dict[str, tuple[float, float, str]]:
    """``{method: (rms % of range, seconds, note)}`` for one seed's voids."""
    truth = grid.z
    zrange = float(np.nanmax(truth) - np.nanmin(truth))
    disks = cut_voids(truth, seed)
    voids = np.zeros(truth.shape, dtype=bool)
    for d, _ in disks:
        voids |= d
    z = np.where(voids, np.nan, truth)
    holed = RangeGrid(z, "elevation", cell=grid.cell, origin=grid.origin)
    rmax = max(r for _, r in disks)
    res = {}
    for m in methods:
        note = ""
        t0 = time.perf_counter()
        try:
            if m == "ours":
                got = fill_grid(holed, seed=seed)
                filled = got.z_filled
                note = f"fit {got.fit_seconds:.2f}s"
            elif m == "gdal":
                filled = _gdal(z, voids, rmax)
            elif m in ("ns", "telea"):
                filled = _cv(z, voids, m)
            else:
                filled = _griddata(z, disks, m)
        except ImportError as exc:
            res[m] = (float("nan"), float("nan"), f"missing: {exc.name}")
            continue
        sec = time.perf_counter() - t0
        err = filled[voids] - truth[voids]
        if not np.all(np.isfinite(err)):
            note += f" {int((~np.isfinite(err)).sum())} cells unfilled"
            err = err[np.isfinite(err)]
        res[m] = (100.0 * float(np.sqrt(np.mean(err ** 2))) / zrange, sec, note.strip())
    return res


def versions() -> str:
    """Versions of the peers."""
    out = []
    for dist in ("numpy", "scipy", "opencv-python-headless", "rasterio"):
        try:
            out.append(f"{dist} {metadata.version(dist)}")
        except metadata.PackageNotFoundError:
            out.append(f"{dist} missing")
    try:
        import rasterio

        out.append(f"GDAL {rasterio.__gdal_version__}")
    except ImportError:
        pass
    return ", ".join(out)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=list(range(10)))
    ap.add_argument("--methods", nargs="+", default=list(METHODS), choices=METHODS)
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    grid = load_tile()
    methods = tuple(args.methods)
    print(f"tile {grid.shape[0]} x {grid.shape[1]} cells; {versions()}", flush=True)
    rows = []
    wins = 0
    for seed in args.seeds:
        r = run_seed(grid, seed, methods)
        rows.append((seed, r))
        peers = [r[m][0] for m in methods if m != "ours" and np.isfinite(r[m][0])]
        if "ours" in r and peers and r["ours"][0] < min(peers):
            wins += 1
        print(f"seed {seed}: " + "  ".join(f"{m} {v[0]:.3f}% {v[1]:.2f}s" for m, v in r.items()),
              flush=True)
    head = "| seed | " + " | ".join(f"{m} RMS % | {m} s" for m in methods) + " | notes |"
    print()
    print(head)
    print("|" + "---|" * (2 * len(methods) + 2))
    for seed, r in rows:
        cells = " | ".join(f"{r[m][0]:.3f} | {r[m][1]:.2f}" for m in methods)
        notes = "; ".join(f"{m}: {r[m][2]}" for m in methods if r[m][2])
        print(f"| {seed} | {cells} | {notes} |")
    means = " | ".join(f"{np.mean([r[m][0] for _, r in rows]):.3f} | "
                       f"{np.mean([r[m][1] for _, r in rows]):.2f}" for m in methods)
    print(f"| mean | {means} | |")
    if "ours" in methods and len(methods) > 1:
        print(f"\nours lowest RMS on {wins} of {len(rows)} seeds")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
