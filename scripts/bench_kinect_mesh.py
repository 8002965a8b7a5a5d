"""Kinect frames as meshes: segmentation, fit and hole filling of a 640 x 480 depth frame.

Run from the repository root (the frames are not shipped: a folder of TUM RGB-D
``*_depth.png`` files, ``--tum DIR`` or ``$ASRBF_TUM_DIR``):

    ASRBF_TUM_DIR=/path/to/tum-depth python scripts/bench_kinect_mesh.py

Each frame is read with the freiburg2 intrinsics (metric camera coordinates) and meshed
as its range grid (:meth:`asrbf_mesh.RangeGrid.to_scan`): what a user gets who converts
a depth frame to PLY and runs the mesh commands on it (a depth image itself goes through
the grid fill, ``scripts/bench_range.py``). Timed: :func:`asrbf_mesh.segment` (best of
3), :func:`asrbf_mesh.fit` with ``pieces="auto"`` and ``pieces=1`` (the fastest of 5,
alternating), then
:func:`asrbf_mesh.fill_holes` with the piecewise network (one run) and screened Poisson
at depth 9 (one run, the hole benchmark's peer). Then both models with each of
``--seeds`` (default 0 1 2): K, E-bar and the default reconstruction's distances to the
frame's mesh both ways (``scripts/bench_pieces.py``'s table). ``--no-write`` prints only.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _bench_common import machine, table, write_section  # noqa: E402
from bench_pieces import HEADERS as PIECES_HEADERS  # noqa: E402
from bench_pieces import _rows as pieces_rows  # noqa: E402
from bench_range import tum_frames  # noqa: E402

import asrbf_mesh as am  # noqa: E402

#: Fits per model, alternating; each model's fastest is reported.
FIT_REPS = 5
#: Whole-process runs of each command, alternating; every run is reported (min-max).
PROCESS_REPS = 3
VOXEL = 0.01  # m: the voxel grid of the downsampled cloud (Open3D's voxel_down_sample)

_POISSON = """
import sys
from asrbf_mesh._io import load_scan, save_mesh
from asrbf_mesh.evaluate._meshlab import screened_poisson
save_mesh(screened_poisson(load_scan(sys.argv[1]).points, depth=9), sys.argv[2])
"""


def whole_process(scan: am.Scan, folder: Path) -> dict:
    """Wall time of whole processes on the frame's PLY: ``asrbf fill-holes`` and Poisson.

    The frame is written as a binary PLY in float32 OpenCV camera coordinates (+y down,
    +z forward, what Open3D writes). Each of ``asrbf fill-holes`` (the frame filled on
    its pixel lattice), ``asrbf fill-holes --as-mesh`` (filled as any mesh), both again on
    the frame's points alone (a PLY without faces: meshed on its lattice, or triangulated
    in the view plane with ``--as-mesh``), ``asrbf fill-holes`` on the mesh as an ASCII
    PLY rounded to millimetres (off the lattice: filled in the camera's frame), on its
    points averaged per 1 cm voxel (with and without ``--as-mesh``) and a
    Python process reading the PLY, running screened Poisson at depth 9 (the hole benchmark's
    peer) and writing its mesh runs once untimed, then :data:`PROCESS_REPS` times,
    alternating.
    """
    import json
    import subprocess

    src = folder / "frame.ply"
    p = (scan.points * [1.0, -1.0, -1.0]).astype(np.float32)
    with open(src, "wb") as fh:
        fh.write((f"ply\nformat binary_little_endian 1.0\nelement vertex {len(p)}\n"
                  "property float x\nproperty float y\nproperty float z\n"
                  f"element face {len(scan.faces)}\nproperty list uchar int vertex_indices\n"
                  "end_header\n").encode())
        fh.write(p.astype("<f4").tobytes())
        rec = np.zeros(len(scan.faces), dtype=[("n", "u1"), ("v", "<i4", (3,))])
        rec["n"], rec["v"] = 3, scan.faces[:, ::-1]
        fh.write(rec.tobytes())
    rounded = folder / "mm.ply"  # an ASCII export to millimetres: off the pixel lattice
    with open(rounded, "w") as fh:
        fh.write(f"ply\nformat ascii 1.0\nelement vertex {len(p)}\nproperty float x\n"
                 f"property float y\nproperty float z\nelement face {len(scan.faces)}\n"
                 "property list uchar int vertex_indices\nend_header\n")
        np.savetxt(fh, p.astype(np.float64), fmt="%.3f")
        np.savetxt(fh, np.column_stack([np.full(len(scan.faces), 3), scan.faces[:, ::-1]]),
                   fmt="%d")
    cloud = folder / "cloud.ply"  # the frame's points alone (Open3D's point cloud)
    with open(cloud, "wb") as fh:
        fh.write((f"ply\nformat binary_little_endian 1.0\nelement vertex {len(p)}\n"
                  "property float x\nproperty float y\nproperty float z\nend_header\n"
                  ).encode())
        fh.write(p.astype("<f4").tobytes())
    voxels = folder / "voxels.ply"  # Open3D's voxel_down_sample(0.01): off the lattice
    key = np.floor(p.astype(np.float64) / VOXEL).astype(np.int64)
    _, inv = np.unique(key, axis=0, return_inverse=True)
    inv = inv.ravel()
    v = np.zeros((inv.max() + 1, 3))
    np.add.at(v, inv, p.astype(np.float64))
    v /= np.bincount(inv)[:, None]
    with open(voxels, "wb") as fh:
        fh.write((f"ply\nformat binary_little_endian 1.0\nelement vertex {len(v)}\n"
                  "property float x\nproperty float y\nproperty float z\nend_header\n"
                  ).encode())
        fh.write(v.astype("<f4").tobytes())
    exe = Path(sys.executable).parent / "asrbf"  # the installed command, as a user runs it
    asrbf = [str(exe)] if exe.exists() else [sys.executable, "-m", "asrbf_mesh.cli"]
    cmds = {"lattice": asrbf + ["fill-holes", str(src), "-o", str(folder / "a.ply"), "--json"],
            "mesh": asrbf + ["fill-holes", str(src), "-o", str(folder / "m.ply"), "--json",
                             "--as-mesh"],
            "cloud": asrbf + ["fill-holes", str(cloud), "-o", str(folder / "c.ply"), "--json"],
            "cloud_mesh": asrbf + ["fill-holes", str(cloud), "-o", str(folder / "cm.ply"),
                                   "--json", "--as-mesh"],
            "rounded": asrbf + ["fill-holes", str(rounded), "-o", str(folder / "r.ply"),
                                "--json"],
            "voxels": asrbf + ["fill-holes", str(voxels), "-o", str(folder / "v.ply"),
                               "--json"],
            "voxels_mesh": asrbf + ["fill-holes", str(voxels), "-o", str(folder / "vm.ply"),
                                    "--json", "--as-mesh"],
            "poisson": [sys.executable, "-c", _POISSON, str(src), str(folder / "p.ply")]}
    secs: dict[str, list[float]] = {k: [] for k in cmds}
    out: dict = {}
    for cmd in cmds.values():  # one untimed run each: numba's and the OS's caches warm
        subprocess.run(cmd, capture_output=True, check=True)
    for _ in range(PROCESS_REPS):
        for k, cmd in cmds.items():
            t0 = time.perf_counter()
            run = subprocess.run(cmd, capture_output=True, text=True, check=True)
            secs[k].append(time.perf_counter() - t0)
            if k != "poisson":
                out[k] = json.loads(run.stdout)
    return {"secs": secs} | out


def best(fn, runs: int) -> tuple[float, object]:
    """Best wall time of ``runs`` calls, and the last result."""
    secs, out = [], None
    for _ in range(runs):
        t0 = time.perf_counter()
        out = fn()
        secs.append(time.perf_counter() - t0)
    return min(secs), out


def fit_times(scan: am.Scan) -> tuple[float, float, am.Network, am.Network]:
    """Fastest of :data:`FIT_REPS` fits per model, alternating (seed 0): pieces, single."""
    am.fit(scan, progress=False)  # compile / load the kernels outside the clock
    auto_t, one_t = [], []
    for _ in range(FIT_REPS):  # alternating: a slow stretch of the machine hits both
        t, net = best(lambda: am.fit(scan, progress=False), 1)
        auto_t.append(t)
        t, single = best(lambda: am.fit(scan, pieces=1, progress=False), 1)
        one_t.append(t)
    return min(auto_t), min(one_t), net, single


def run_frame(scan: am.Scan) -> dict:
    from asrbf_mesh.evaluate import _meshlab

    seg_s, seg = best(lambda: am.segment(scan), 3)
    auto_s, one_s, net, single = fit_times(scan)
    fill_s, res = best(lambda: am.fill_holes(scan, net, progress=False), 1)
    poisson_s, _ = best(lambda: _meshlab.screened_poisson(scan.points, depth=9), 1)
    return {"n": scan.n_points, "faces": len(scan.faces), "seg_s": seg_s,
            "pieces": seg.n_pieces, "small": int(seg.small.sum()), "cut": seg.n_cut,
            "auto_s": auto_s, "auto_k": net.n_neurons, "auto_e": net.info["ebar"],
            "one_s": one_s, "one_k": single.n_neurons, "one_e": single.info["ebar"],
            "fill_s": fill_s, "found": res.holes_found, "filled": res.holes_filled,
            "added": res.vertices_added, "poisson_s": poisson_s}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tum", type=Path, default=None,
                    help="folder of TUM RGB-D *_depth.png frames [default: $ASRBF_TUM_DIR]")
    ap.add_argument("--no-write", action="store_true", help="print, leave BENCHMARKS.md")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2],
                    help="seeds of the model table (K, E-bar, reconstruction distances)")
    args = ap.parse_args(argv)
    folder = args.tum or (Path(os.environ["ASRBF_TUM_DIR"])
                          if os.environ.get("ASRBF_TUM_DIR") else None)
    if folder is None or not folder.is_dir():
        print("no TUM frames: pass --tum DIR or set ASRBF_TUM_DIR", file=sys.stderr)
        return 2
    import tempfile

    t0 = time.perf_counter()
    rows, model_rows, proc_rows = [], [], []
    with warnings.catch_warnings(), tempfile.TemporaryDirectory() as tmp:
        warnings.simplefilter("ignore")
        for name, grid in tum_frames(folder).items():
            scan = grid.to_scan()
            w = whole_process(scan, Path(tmp))
            lat, mesh = w["lattice"], w["mesh"]

            def span(k: str, w: dict = w) -> str:
                return f"{min(w['secs'][k]):.2f}-{max(w['secs'][k]):.2f}"

            proc_rows.append([name, f"{lat['lattice']['cols']} x {lat['lattice']['rows']}",
                              f"{lat['holes_filled']} of {lat['holes_found']} / "
                              f"{lat['vertices_added']:,}", span("lattice"),
                              f"{mesh['holes_filled']} of {mesh['holes_found']} / "
                              f"{mesh['vertices_added']:,}", span("mesh"),
                              f"{w['cloud']['holes_filled']} of {w['cloud']['holes_found']}",
                              span("cloud"), f"{w['cloud_mesh']['holes_filled']} of "
                              f"{w['cloud_mesh']['holes_found']}", span("cloud_mesh"),
                              f"{w['rounded']['holes_filled']} of "
                              f"{w['rounded']['holes_found']} ({w['rounded']['frame']})",
                              span("rounded"),
                              f"{w['voxels']['holes_filled']} of "
                              f"{w['voxels']['holes_found']} ({w['voxels']['frame']})",
                              span("voxels"), f"{w['voxels_mesh']['holes_filled']} of "
                              f"{w['voxels_mesh']['holes_found']}", span("voxels_mesh"),
                              span("poisson")])
            print(name, w["secs"], flush=True)
            r = run_frame(scan)
            # the same frame as the PLY the processes read (float32, camera coordinates)
            ply_auto, ply_one, ply_net, ply_single = fit_times(am.load_scan(Path(tmp) /
                                                                            "frame.ply"))
            model_rows += pieces_rows(name, scan, args.seeds)
            print(name, r, flush=True)
            rows.append([name, f"{r['n']:,}", f"{r['pieces']:,} ({r['small']:,} small)",
                         f"{r['cut']:,} / {r['faces']:,}", f"{r['seg_s']:.2f}",
                         f"{r['auto_k']:,} / {r['auto_e']:.5f} / {r['auto_s']:.2f}",
                         f"{r['one_k']:,} / {r['one_e']:.5f} / {r['one_s']:.2f}",
                         f"{r['auto_s'] / r['one_s']:.2f}",
                         f"{ply_net.n_neurons:,} / {ply_auto:.2f}; {ply_single.n_neurons:,} / "
                         f"{ply_one:.2f}; {ply_auto / ply_one:.2f}",
                         f"{r['filled']} of {r['found']} / {r['added']:,} / {r['fill_s']:.1f}",
                         f"{r['poisson_s']:.1f}"])
    head = ["frame", "points", "pieces", "cut / triangles", "segment s",
            "pieces: K / E̅ / fit s", "single: K / E̅ / fit s", "fit time ratio",
            "as its PLY: pieces K / s; single K / s; ratio",
            "fill-holes: filled / vertices added / s", "Poisson s"]
    body = ("## Kinect frames as meshes (metric camera coordinates)\n\n"
            f"_Measured {time.strftime('%Y-%m-%d')} on {machine()}; `ASRBF_TUM_DIR=... python "
            f"scripts/bench_kinect_mesh.py` ({time.perf_counter() - t0:.0f} s)._\n\n"
            "Each TUM frame read with its intrinsics and meshed as its range grid (what a "
            "user converting a frame to PLY runs the mesh commands on). Segment: best of 3; "
            f"fits: the fastest of {FIT_REPS} per model, the two models alternating, seed 0 "
            "(E̅ in the unit cube); *as its PLY*: the same fits of the frame written as "
            "the PLY of the whole processes below (float32 camera coordinates, as Open3D "
            "writes it); fill-holes: one run with the piecewise "
            "network, every natural hole (no size limit); screened Poisson at depth 9, one "
            "run.\n\n" + table(head, rows) + "\n\n"
            f"The issue 14 figures on the frames, seeds {', '.join(map(str, args.seeds))} "
            "(the columns of the [piecewise model's table](#piecewise-model-vs-the-single-"
            "network-issue-14), `scripts/bench_pieces.py`'s measure: the "
            "default reconstruction against the frame's mesh, both ways, % of the "
            "diagonal; each cell the median over the seeds (worst seed)):\n\n"
            + table(PIECES_HEADERS, model_rows) + "\n\n"
            "Whole processes on the frame written as a PLY (float32, OpenCV camera "
            "coordinates, as Open3D writes it; wall time of "
            f"{PROCESS_REPS} runs each after an untimed one, alternating, min-max, reading "
            "and writing included): `asrbf fill-holes frame.ply` recognises the frame's "
            "pixel lattice and fills it as its depth image (enclosed no-data cells; the "
            "shadows beside depth edges from their far side); `--as-mesh` fills it as any "
            "mesh (every "
            "enclosed gap of its footprint in the view plane, the depth edges' shadows too); "
            "*points only*: the same commands on the frame's points alone (a PLY of "
            "float32 vertices and no faces, as Open3D's `create_from_depth_image` makes "
            "it): recognised by its lattice and meshed as its depth image before the fill, "
            "or `--as-mesh` triangulated and filled in the view plane; *mm*: the frame's "
            "mesh as an ASCII PLY rounded to millimetres (off the pixel lattice), filled in "
            "the camera's projective frame (`frame`: where the fill ran); *1 cm voxels*: "
            "the frame's points averaged per 1 cm voxel (Open3D's `voxel_down_sample`), a "
            "float32 PLY of points alone, off the lattice: meshed in the camera's image and "
            "filled there, or `--as-mesh` triangulated and filled in the view plane; "
            "screened Poisson (depth 9): a Python process reading the PLY, "
            "reconstructing and writing the surface.\n\n"
            + table(["frame", "lattice", "fill-holes: holes filled / vertices added",
                     "fill-holes s", "--as-mesh: holes filled / vertices added",
                     "--as-mesh s", "points only: holes filled", "points only s",
                     "points only --as-mesh: holes filled", "points only --as-mesh s",
                     "mm: holes filled (frame)", "mm s", "1 cm voxels: holes filled (frame)",
                     "1 cm voxels s", "1 cm voxels --as-mesh: holes filled",
                     "1 cm voxels --as-mesh s", "Poisson s"], proc_rows) + "\n")
    print(body)
    if not args.no_write:
        write_section("kinect-mesh", body)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
