"""Range scans of the Stanford bunny from views the real scans do not have.

Run from the repository root (the bunny scans are not shipped: ``--bunny DIR`` or
``$ASRBF_BUNNY_DIR``, the folder with ``bun000.ply`` ... and ``bun.conf``):

    ASRBF_BUNNY_DIR=/path/to/stanford-bunny python scripts/synth_views.py --out views/

The four real scans are registered by ``bun.conf`` (each point ``R(q)^T p + t``, scipy's
scalar-last quaternion; checked: bun045 and bun090 then lie within 0.3-0.4 mm (median) of
bun000 where they overlap, bun180 of bun090), their
points and normals (each oriented toward its own scanner) merged and meshed by screened
Poisson (depth 10). That surface is then scanned the way the Cyberware scanner saw the
real ones: a z-buffer on a grid at the real scans' spacing (median nearest-neighbour
distance of bun000), looking along -z after a rotation of the model (about the vertical
axis for the turntable views, about x for views from above and below); pixels where the
surface is seen at a grazing angle (|n . view| under ``--grazing``) are dropped, as the
scanner's triangulation loses them, and so are those the laser, ``--shadow`` degrees
beside the camera about the vertical axis, does not reach (its own z-buffer: the shadows
next to occlusion cliffs that make a real scan's gaps and fragments); depths get
Gaussian noise along the view of the real scans' level (``--noise``, scan units;
measured by :func:`noise_level` on bun000); the grid is triangulated as the scanner's
meshes are (two triangles per 2 x 2 cell of valid pixels, dropped where an edge is
longer than ``--max-edge`` spacings).

With ``--mesh PATH ...`` other closed models are scanned the same way instead (three views
each, ``<stem>0.ply`` ... ``<stem>2.ply``; loop-subdivided, centred, 1.2 times bun000's
extent, at its spacing and noise): pymeshlab ships a few (``cow.obj``, ``bone.ply``,
``airplane.obj`` in its ``tests/sample_meshes``), scans of shapes the bunny has not.
``--view-set second`` scans from a second set of angles (the bunny's ``nv060`` ...
``nv_yx``, a model's ``<stem>a`` ... ``<stem>c``), a check on views no setting was tuned on.

Each view is written as ``<out>/<name>.ply`` (binary, the scan's own frame). These scans
are benchmark inputs the project's tuning never saw: ``bench_holes_protocol.py --scans``
and ``bench_pieces.py --scans`` read them. The surface is Poisson's, smoother than a real
bunny's between the real scans' samples, so the figures check the methods on new
geometry (occlusions, steep walls, folds seen from new angles), not on new detail.
"""

from __future__ import annotations

import argparse
import os
import sys
import warnings
from pathlib import Path

import numpy as np
from numba import njit
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

sys.path.insert(0, str(Path(__file__).resolve().parent))

import asrbf_mesh as am  # noqa: E402

#: The views: name -> (rotation axis, degrees). Turntable views about the vertical axis
#: (y) between and beyond the real 0, 45, 90 and 180; tilted views from above and below.
VIEWS = {
    "syn022": ("y", 22.5), "syn135": ("y", 135.0), "syn225": ("y", 225.0),
    "syn270": ("y", 270.0), "syn315": ("y", 315.0),
    "syn_top": ("x", 40.0), "syn_chin": ("x", -30.0), "syn_back_top": ("yx", (180.0, 35.0)),
}


#: The views of another model (``--mesh``): name suffix -> (rotation axis, degrees).
MESH_VIEWS = {"0": ("y", 30.0), "1": ("x", 50.0), "2": ("yx", (200.0, -25.0))}

#: ``--view-set second``: angles none of the views above has, for a check on scans that
#: no tuning saw (the bunny's seven, three per model named ``<stem>a`` ... ``<stem>c``).
VIEWS_SECOND = {
    "nv060": ("y", 60.0), "nv100": ("y", 100.0), "nv160": ("y", 160.0),
    "nv200": ("y", 200.0), "nv_top70": ("x", 70.0), "nv_below": ("x", -55.0),
    "nv_yx": ("yx", (250.0, 25.0)),
}
MESH_VIEWS_SECOND = {"a": ("y", 120.0), "b": ("x", -60.0), "c": ("yx", (80.0, 40.0))}


def model_surface(path: Path, extent: float, subdivide: int = 3) -> am.Mesh:
    """A closed model (any format pymeshlab reads) as a smooth surface the bunny's size.

    Loop-subdivided ``subdivide`` times (pymeshlab's sample meshes are coarse: their
    flat facets would make piecewise planar scans), centred, its largest extent scaled to
    ``extent``.
    """
    import pymeshlab

    ms = pymeshlab.MeshSet()
    ms.load_new_mesh(str(path))
    if subdivide:
        ms.meshing_surface_subdivision_loop(iterations=subdivide,
                                            threshold=pymeshlab.PercentageValue(0))
    m = ms.current_mesh()
    v, f = m.vertex_matrix().astype(np.float64), m.face_matrix().astype(np.int64)
    v = (v - v.mean(axis=0)) / float(np.ptp(v, axis=0).max()) * extent
    return am.Mesh(v, f)


def read_conf(folder: Path) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """``bun.conf``: scan file -> (rotation matrix, translation); a point maps to ``p @ R + t``."""
    out = {}
    for line in (folder / "bun.conf").read_text().splitlines():
        f = line.split()
        if f and f[0] == "bmesh":
            t = np.array(f[2:5], dtype=float)
            q = np.array(f[5:9], dtype=float)  # qi qj qk qr (scalar last)
            out[f[1]] = (Rotation.from_quat(q).as_matrix(), t)
    return out


def merged_surface(folder: Path, depth: int = 10) -> am.Mesh:
    """The four scans registered, merged with oriented normals, meshed by screened Poisson."""
    import pymeshlab

    pts, nrm = [], []
    for name, (R, t) in read_conf(folder).items():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            scan = am.load_scan(folder / name)
        used = np.unique(scan.faces)
        v, f = scan.points, scan.faces
        fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
        vn = np.zeros_like(v)
        for k in range(3):
            np.add.at(vn, f[:, k], fn)
        vn /= np.maximum(np.linalg.norm(vn, axis=1, keepdims=True), 1e-300)
        vn[vn[:, 2] < 0] *= -1  # toward the scanner, which looks along -z
        pts.append(v[used] @ R + t)
        nrm.append(vn[used] @ R)
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=np.vstack(pts), v_normals_matrix=np.vstack(nrm)))
    ms.generate_surface_reconstruction_screened_poisson(depth=depth, preclean=True)
    m = ms.current_mesh()
    return am.Mesh(m.vertex_matrix().astype(np.float64), m.face_matrix().astype(np.int64))


@njit(cache=True)
def _zbuffer(v: np.ndarray, f: np.ndarray, x0: float, y0: float, h: float, nx: int,
             ny: int) -> tuple[np.ndarray, np.ndarray]:
    """Largest z per grid node (x0 + i h, y0 + j h) over the triangles; -inf where none."""
    zb = np.full((ny, nx), -np.inf)
    fid = np.full((ny, nx), -1, np.int64)
    for t in range(f.shape[0]):
        a, b, c = v[f[t, 0]], v[f[t, 1]], v[f[t, 2]]
        det = (b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1])
        if abs(det) < 1e-30:
            continue
        i0 = max(int(np.ceil((min(a[0], b[0], c[0]) - x0) / h)), 0)
        i1 = min(int(np.floor((max(a[0], b[0], c[0]) - x0) / h)), nx - 1)
        j0 = max(int(np.ceil((min(a[1], b[1], c[1]) - y0) / h)), 0)
        j1 = min(int(np.floor((max(a[1], b[1], c[1]) - y0) / h)), ny - 1)
        for j in range(j0, j1 + 1):
            y = y0 + j * h
            for i in range(i0, i1 + 1):
                x = x0 + i * h
                l1 = ((x - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (y - a[1])) / det
                l2 = ((b[0] - a[0]) * (y - a[1]) - (x - a[0]) * (b[1] - a[1])) / det
                if l1 < 0 or l2 < 0 or l1 + l2 > 1:
                    continue
                z = a[2] + l1 * (b[2] - a[2]) + l2 * (c[2] - a[2])
                if z > zb[j, i]:
                    zb[j, i] = z
                    fid[j, i] = t
    return zb, fid


def noise_level(scan: am.Scan, k: int = 16) -> float:
    """Robust std of the scan's depths about local planes of ``k`` neighbours (scan units)."""
    p = scan.points[np.unique(scan.faces)]
    rng = np.random.default_rng(0)
    pick = rng.choice(len(p), min(4000, len(p)), replace=False)
    _, nb = cKDTree(p[:, :2]).query(p[pick, :2], k=k)
    res = []
    for row in nb:
        q = p[row]
        A = np.c_[q[:, :2] - q[0, :2], np.ones(k)]
        coef, *_ = np.linalg.lstsq(A, q[:, 2], rcond=None)
        res.append(q[0, 2] - A[0] @ coef)
    res = np.asarray(res)
    return float(1.4826 * np.median(np.abs(res - np.median(res))) * np.sqrt(k / (k - 3)))


def view_rotation(axis: str, deg) -> np.ndarray:
    """The rotation taking the model into a view's frame."""
    if axis == "yx":
        return Rotation.from_euler("yx", deg, degrees=True).as_matrix()
    return Rotation.from_euler(axis, deg, degrees=True).as_matrix()


def _render(v: np.ndarray, f: np.ndarray, spacing: float):
    """z-buffer of the mesh (v, f) seen along -z: (depths, face ids, x0, y0)."""
    lo, hi = v[:, :2].min(0), v[:, :2].max(0)
    nx = int((hi[0] - lo[0]) / spacing) + 1
    ny = int((hi[1] - lo[1]) / spacing) + 1
    zb, fid = _zbuffer(np.ascontiguousarray(v), np.ascontiguousarray(f), lo[0], lo[1],
                       spacing, nx, ny)
    return zb, fid, lo


def _lit(surface: am.Mesh, R2: np.ndarray, world: np.ndarray, spacing: float) -> np.ndarray:
    """Whether each point (model frame) is seen from the view ``R2`` (the light source)."""
    v = surface.vertices @ R2.T
    zb, _, lo = _render(v, surface.faces, spacing)
    p = world @ R2.T
    i = np.clip(np.round((p[:, 0] - lo[0]) / spacing).astype(np.int64), 0, zb.shape[1] - 1)
    j = np.clip(np.round((p[:, 1] - lo[1]) / spacing).astype(np.int64), 0, zb.shape[0] - 1)
    return p[:, 2] >= zb[j, i] - 3.0 * spacing


def scan_view(surface: am.Mesh, R: np.ndarray, spacing: float, noise: float,
              grazing: float, max_edge: float, seed: int, shadow: float = 0.0) -> am.Scan:
    """A range scan of ``surface`` rotated by ``R``, seen along -z (module text)."""
    v = surface.vertices @ R.T
    f = surface.faces
    zb, fid, lo = _render(v, f, spacing)
    fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    fn /= np.maximum(np.linalg.norm(fn, axis=1, keepdims=True), 1e-300)
    ok = fid >= 0
    ok[ok] = np.abs(fn[fid[ok], 2]) >= grazing
    if shadow:  # triangulation: the laser sees the point from beside the camera too
        jj, ii = np.nonzero(ok)
        view_pts = np.c_[lo[0] + ii * spacing, lo[1] + jj * spacing, zb[jj, ii]]
        R2 = Rotation.from_euler("y", shadow, degrees=True).as_matrix() @ R
        ok[jj, ii] = _lit(surface, R2, view_pts @ R, spacing)
    rng = np.random.default_rng(seed)
    z = zb + rng.normal(0.0, noise, zb.shape)
    jj, ii = np.nonzero(ok)
    index = np.full(ok.shape, -1, np.int64)
    index[jj, ii] = np.arange(len(jj))
    pts = np.c_[lo[0] + ii * spacing, lo[1] + jj * spacing, z[jj, ii]]
    tris = []
    a, b = index[:-1, :-1], index[:-1, 1:]
    c, d = index[1:, :-1], index[1:, 1:]
    for t in (np.stack([a, b, d], -1), np.stack([a, d, c], -1)):
        t = t.reshape(-1, 3)
        t = t[(t >= 0).all(1)]
        e = np.stack([pts[t[:, 1]] - pts[t[:, 0]], pts[t[:, 2]] - pts[t[:, 1]],
                      pts[t[:, 0]] - pts[t[:, 2]]], 1)
        t = t[np.linalg.norm(e, axis=2).max(1) <= max_edge * spacing]
        tris.append(t)
    faces = np.vstack(tris)
    used = np.unique(faces)
    remap = np.full(len(pts), -1, np.int64)
    remap[used] = np.arange(len(used))
    return am.Scan(pts[used], remap[faces])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--bunny", type=Path, default=os.environ.get("ASRBF_BUNNY_DIR"))
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--noise", type=float, default=None,
                    help="depth noise std, scan units (default: bun000's, measured)")
    ap.add_argument("--grazing", type=float, default=0.2)
    ap.add_argument("--max-edge", type=float, default=4.0)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--shadow", type=float, default=20.0,
                    help="degrees between the camera and the laser (0: no shadows)")
    ap.add_argument("--mesh", type=Path, nargs="+", metavar="PATH",
                    help="scan these closed models instead of the bunny (e.g. pymeshlab's "
                         "sample meshes: cow.obj, bone.ply, airplane.obj), three views each "
                         "(<stem>0-2.ply), loop-subdivided, 1.2x bun000's extent, at its "
                         "spacing and noise")
    ap.add_argument("--view-set", choices=("first", "second"), default="first",
                    help="the views (default) or a second set at other angles "
                         "(nv060 ... nv_yx; <stem>a-c with --mesh)")
    args = ap.parse_args(argv)
    second = args.view_set == "second"
    if args.bunny is None or not (Path(args.bunny) / "bun.conf").exists():
        ap.exit(2, "needs the bunny scans: --bunny DIR or $ASRBF_BUNNY_DIR (with bun.conf)\n")
    folder = Path(args.bunny)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ref = am.load_scan(folder / "bun000.ply")
    used = ref.points[np.unique(ref.faces)]
    spacing = float(np.median(cKDTree(used[:, :2]).query(used[:, :2], k=2)[0][:, 1]))
    noise = noise_level(ref) if args.noise is None else args.noise
    if args.mesh:
        extent = 1.2 * float(np.ptp(used, axis=0).max())
        mesh_views = MESH_VIEWS_SECOND if second else MESH_VIEWS
        jobs = [(model_surface(m, extent), {m.stem + k: v for k, v in mesh_views.items()})
                for m in args.mesh]
    else:
        jobs = [(merged_surface(folder), VIEWS_SECOND if second else VIEWS)]
    print(f"spacing {spacing:.3g}, noise {noise:.3g} (scan units)")
    args.out.mkdir(parents=True, exist_ok=True)
    for surface, views in jobs:
        print(f"surface: {len(surface.vertices):,} vertices")
        for i, (name, (axis, deg)) in enumerate(views.items()):
            scan = scan_view(surface, view_rotation(axis, deg), spacing, noise, args.grazing,
                             args.max_edge, args.seed + i, args.shadow)
            path = args.out / f"{name}.ply"
            am.save_mesh(am.Mesh(scan.points, scan.faces), path)
            print(f"{path}: {scan.n_points:,} points, {len(scan.faces):,} faces")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
