"""Where the hole fill loses to screened Poisson: offset or roughness? (issue 15)

Run from the repository root:

    python scripts/hole_offsets.py --seeds $(seq 0 9)
    python scripts/hole_offsets.py --seeds $(seq 0 9) --scans views/*.ply

For each scan (default: the face map and, from $ASRBF_BUNNY_DIR, the Stanford bunny
scans) and seed, the scan is punched by the protocol with the parts' borders
(:func:`asrbf_mesh.evaluate._punch_protocol.punch_protocol`, ``border="parts"``, as the
benchmark's tables), filled (``fill_holes``, ``--max-hole-size 20%``) and reconstructed by
screened Poisson (depth 9). Each truth point's distance to both surfaces is signed:
positive where the point lies behind the surface's closest point (the surface is in front,
towards the scanner at +z). Per enclosed hole: the RMS and the mean of those distances,
% of the diagonal. Printed per scan and pooled:

- *below*: the share of holes where our RMS is below Poisson's;
- *lost: offset share*: on the holes we lose, the median of |mean| / RMS for us and for
  Poisson (1: a pure offset, 0: no offset);
- *lost: in front*: the share of those holes where our fill lies in front of the truth;
- *offset removed*: the share below Poisson if each hole's own mean offset were taken out
  of our distances (an oracle: what a perfect per-hole offset correction would give);
- *mean with Poisson*: the share below Poisson of the surface halfway between ours and
  Poisson's (per point, the mean of the two signed distances).

The figures in the record next to ``_hole_patch._CURVED`` come from this script.
"""

from __future__ import annotations

import argparse
import concurrent.futures as cf
import sys
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _bench_common import BUNNIES, BUNNY_DIR, label, table  # noqa: E402


def _signed(truth: np.ndarray, mesh) -> np.ndarray:
    """Distance of each truth point to ``mesh``, positive where the surface is in front."""
    import igl

    d2, _, closest = igl.point_mesh_squared_distance(
        truth, np.asarray(mesh.vertices, np.float64), np.asarray(mesh.faces, np.int64))
    return np.where(closest[:, 2] > truth[:, 2], 1.0, -1.0) * np.sqrt(d2)


def _case(args: tuple) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per enclosed hole of one punched scan: (our, Poisson's) signed distances, % diag."""
    import asrbf_mesh as am
    from asrbf_mesh.evaluate import _meshlab
    from asrbf_mesh.evaluate._punch_protocol import punch_protocol

    path, seed = args
    warnings.simplefilter("ignore")
    scan = am.load_scan(path)
    p = punch_protocol(scan, seed, border="parts")
    ours = am.fill_holes(p.scan, seed=seed, max_hole_size="20%", progress=False).mesh
    so = 100.0 * _signed(p.truth, ours) / p.diagonal
    sp = 100.0 * _signed(p.truth, _meshlab.screened_poisson(p.scan.points, depth=9)) \
        / p.diagonal
    return [(so[p.hole == h], sp[p.hole == h]) for h in np.flatnonzero(p.enclosed)]


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(x ** 2)))


def summary(holes: list[tuple[np.ndarray, np.ndarray]]) -> list[str]:
    """The table row's cells for a list of holes' (ours, Poisson's) signed distances."""
    if not holes:
        return ["0", "", "", "", "", ""]
    ours = np.array([_rms(a) for a, _ in holes])
    pois = np.array([_rms(b) for _, b in holes])
    mo = np.array([a.mean() for a, _ in holes])
    mp = np.array([b.mean() for _, b in holes])
    lost = ours >= pois
    removed = np.sqrt(np.maximum(ours ** 2 - mo ** 2, 0.0))
    halfway = np.array([_rms(0.5 * (a + b)) for a, b in holes])

    def pct(x: np.ndarray) -> str:
        return f"{100.0 * np.mean(x):.1f} %" if len(x) else ""

    ratio = (f"{np.median(np.abs(mo[lost]) / ours[lost]):.2f} / "
             f"{np.median(np.abs(mp[lost]) / pois[lost]):.2f}") if lost.any() else ""
    return [str(len(holes)), pct(~lost), ratio, pct(mo[lost] > 0), pct(removed < pois),
            pct(halfway < pois)]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=list(range(10)))
    ap.add_argument("--scans", nargs="+", default=None,
                    help="scan names (face, bun000, ...) or scan files")
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()
    import asrbf_mesh as am

    paths = {}
    for name in args.scans or ("face", *BUNNIES):
        path = Path(name) if Path(name).suffix else \
            Path(am.face_map_path()) if name == "face" else BUNNY_DIR / f"{name}.ply"
        if path.exists():
            paths[name] = path
        else:
            print(f"(skipping {name}: {path} not found)")
    rows, pooled = [], []
    cases = [(name, seed) for name in paths for seed in args.seeds]
    with cf.ProcessPoolExecutor(args.workers) as ex:
        got = list(ex.map(_case, [(str(paths[n]), s) for n, s in cases]))
    for name in paths:
        holes = [h for (n, _), hs in zip(cases, got, strict=True) if n == name for h in hs]
        pooled += holes
        rows.append([label(name), *summary(holes)])
    rows.append(["pooled", *summary(pooled)])
    print(table(["scan", "holes", "below", "lost: offset share, ours / Poisson",
                 "lost: in front", "offset removed", "mean with Poisson"], rows))


if __name__ == "__main__":
    main()
