"""Peer hole-filling methods for the per-hole benchmark (``bench_holes_protocol.py``).

Each peer is ``peer(scan) -> Mesh``: it takes a punched range scan (points + faces, a
height field ``z = f(x, y)`` with holes) and returns the scan with its holes filled (or a
reconstruction), ready for :func:`asrbf_mesh.evaluate._punch_protocol.score_holes`.
A peer never takes the process down: its native work runs in a forked child process, so
a crash (SIGSEGV, abort), a Python exception or a time-out returns the scan unchanged;
``REASONS[name]`` then holds why (``None`` after a clean run; for ``tps`` it lists the
holes it skipped).

Boundary loops are ``boundary_cycles`` split at repeated (pinch) vertices into simple
loops; the longest loop of each connected part is its outer border, ``L`` (edges) the
length of the longest of all (the scan's outer border).

- ``meshfix``: pymeshfix ``MeshFix(v, f).fill_holes(n_edges=L - 1, refine=True)``, i.e.
  TMesh's ``fill_small_boundaries(nbe=L - 1, refine=True)``, with ``L`` the number of
  edges of the outer border: MeshFix fills every loop of at most ``nbe`` edges (measured:
  a 4-edge loop is filled with ``nbe=4``, not 3) by triangulating it, then refining the
  patch to the rim's edge length, so the outer border stays open. Nothing else runs: no
  ``repair()`` (which would also drop every component but the largest and run
  ``clean()``'s self-intersection removal). MeshFix's loader may still split or drop bad
  faces of the input (non-manifold edges); the output is its vertex and face arrays.
- ``close-holes``: pymeshlab ``meshing_close_holes(maxholesize=L, selected=False,
  newfaceselected=False, selfintersection=True, refinehole=False,
  refineholeedgelen=3 %)`` on a fresh MeshSet: MeshLab's ear-cutting closes every loop of
  fewer than ``maxholesize`` edges (measured: a 4-edge loop needs ``maxholesize=5``), so
  all loops but the outer border; ``selfintersection=True``, the filter's default,
  rejects ears that would make the fill self-intersect (the package's own adapter
  ``_meshlab.close_holes`` turns it off: it left holes open). Every parameter is passed
  explicitly (pymeshlab remembers a filter's values between calls). If the filter
  refuses the mesh (not two-manifold), the non-manifold edges and vertices are repaired
  first (faces removed, vertices split) and the filter run again; ``REASONS`` says so.
- ``vtk``: pyvista ``PolyData.fill_holes(hole_size)`` (``vtkFillHolesFilter``), then
  ``triangulate()`` (the filter adds one polygon per hole). VTK fills a loop when the
  radius of its bounding sphere (``vtkSphere::ComputeBoundingSphere`` of the loop's
  points) is at most ``HoleSize``. Any sphere holding the outer border has a radius of at
  least half the border's largest bounding-box extent ``E``, so ``hole_size = 0.99 E / 2``
  leaves the outer border open and fills every loop smaller than that (the punched disks
  have radii of 3 to 6 % of the scan's xy extent).
- ``tps``: a thin-plate-spline height field, in the scan's own xy (the view plane). For
  every boundary loop that is not an outer border: new vertices on the
  square grid of the scan's median xy spacing ``h`` strictly inside the loop's xy polygon
  and at least ``h / 2`` from its edges; their z from ``scipy.interpolate.RBFInterpolator
  (kernel="thin_plate_spline", degree=1, smoothing=0)`` fitted on the scan points within
  ``6 h`` (xy) of a rim vertex (an even subsample of at most 2,000 of them); then a
  ``scipy.spatial.Delaunay`` triangulation of rim + new vertices in xy, keeping the
  triangles whose centroid is inside the rim polygon (``matplotlib.path.Path``). The rim
  keeps its own vertices (the fill joins them; a rim edge that Delaunay does not
  reproduce leaves a sliver gap). A loop that cannot be filled (fewer than 3 distinct xy
  rim points, no triangle kept, a failed spline) is skipped.

Run ``python scripts/_hole_peers.py`` from the repository root: the face map, seeds 0 and
1, RMS per enclosed hole and seconds for each peer and for screened Poisson (depth 9).
"""

from __future__ import annotations

import multiprocessing as mp
import time
import traceback
from collections.abc import Callable

import numpy as np

from asrbf_mesh._hole_loops import boundary_cycles, split_loops
from asrbf_mesh._mesh import Mesh, Scan

__all__ = ["PEERS", "REASONS", "meshfix", "meshlab_close_holes", "vtk_fill_holes",
           "tps_height_field"]

TIMEOUT = 600.0  # seconds a peer may run before it is killed (scan returned unchanged)
REASONS: dict[str, str | None] = {}


# --------------------------------------------------------------------------- isolation


def _child(fn: Callable, v: np.ndarray, f: np.ndarray, conn) -> None:
    try:
        out = fn(v, f)
        conn.send(("ok", out))
    except BaseException as exc:  # noqa: BLE001 - everything goes back to the parent
        tb = traceback.format_exc(limit=3).strip().splitlines()
        conn.send(("error", f"{type(exc).__name__}: {exc} [{tb[-3] if len(tb) > 2 else ''}]"))
    finally:
        conn.close()


def _isolated(name: str, fn: Callable, scan: Scan) -> Mesh:
    """Run ``fn(vertices, faces) -> (vertices, faces, reason)`` in a forked child.

    A crash, an exception, a time-out or a bad result returns ``scan`` as a Mesh and
    records why in ``REASONS[name]``.
    """
    unchanged = scan.to_mesh()
    v = np.array(scan.points, dtype=np.float64)
    f = np.array(scan.faces, dtype=np.int64)
    ctx = mp.get_context("fork")
    recv, send = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_child, args=(fn, v, f, send), daemon=True)
    proc.start()
    send.close()
    msg = None
    answered = False
    try:
        answered = recv.poll(TIMEOUT)
        if answered:
            msg = recv.recv()
    except (EOFError, OSError):
        msg = None  # the child died before it could answer (EOF on the pipe)
    finally:
        recv.close()
    if not answered:
        proc.kill()
        proc.join()
        REASONS[name] = f"timed out after {TIMEOUT:.0f} s"
        return unchanged
    proc.join(60.0)
    if proc.is_alive():  # answered (or hung up) but does not exit
        proc.kill()
        proc.join()
    if msg is None:
        REASONS[name] = f"crashed (exit code {proc.exitcode})"
        return unchanged
    if msg[0] != "ok":
        REASONS[name] = f"raised {msg[1]}"
        return unchanged
    out_v, out_f, reason = msg[1]
    try:
        mesh = Mesh(np.asarray(out_v, dtype=np.float64),
                    np.asarray(out_f, dtype=np.int64).reshape(-1, 3))
    except Exception as exc:  # noqa: BLE001 - a malformed result counts as a failure
        REASONS[name] = f"bad output: {exc}"
        return unchanged
    if mesh.n_faces == 0:
        REASONS[name] = "empty output"
        return unchanged
    REASONS[name] = reason
    return mesh


def _simple(cycle: np.ndarray) -> list[np.ndarray]:
    """Split a boundary cycle at its repeated (pinch) vertices into simple cycles.

    ``boundary_cycles`` walks through a pinch vertex (a disk that touches the border at
    one vertex), so one cycle can hold the outer border and a hole; split, the hole is a
    loop of its own, as MeshFix, MeshLab and libigl see it.
    """
    out: list[np.ndarray] = []
    stack: list[int] = []
    where: dict[int, int] = {}
    for x in map(int, cycle):
        if x in where:
            i = where[x]
            sub = stack[i:]
            if len(sub) >= 3:
                out.append(np.array(sub, dtype=np.int64))
            for y in stack[i + 1:]:
                del where[y]
            del stack[i + 1:]
        else:
            where[x] = len(stack)
            stack.append(x)
    if len(stack) >= 3:
        out.append(np.array(stack, dtype=np.int64))
    return out


def _loops(f: np.ndarray, n_vertices: int) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """(outer borders, holes): simple boundary loops; the longest of each part is outer."""
    return split_loops(f, n_vertices, [s for c in boundary_cycles(f) for s in _simple(c)])


def _longest_loop(f: np.ndarray) -> np.ndarray | None:
    """The longest simple boundary loop (the scan's outer border)."""
    outer, _ = _loops(f, int(f.max()) + 1)
    return max(outer, key=len) if outer else None


# --------------------------------------------------------------------------- meshfix


def _meshfix(v: np.ndarray, f: np.ndarray):
    import pymeshfix

    outer = _longest_loop(f)
    if outer is None:
        return v, f, "no boundary loop"
    nbe = len(outer) - 1  # MeshFix fills the loops of at most nbe edges; 0 would fill all
    if nbe < 3:
        return v, f, "no loop shorter than the outer border"
    mf = pymeshfix.MeshFix(v, f.astype(np.int32))
    n = mf.fill_holes(n_edges=int(nbe), refine=True)
    pts, faces = mf.points, mf.faces
    return np.asarray(pts), np.asarray(faces), f"filled {n} loops (nbe={nbe})"


def meshfix(scan: Scan) -> Mesh:
    """pymeshfix ``fill_small_boundaries(nbe=L, refine=True)`` (module text)."""
    return _isolated("meshfix", _meshfix, scan)


# --------------------------------------------------------------------------- MeshLab


def _close_holes(v: np.ndarray, f: np.ndarray):
    import pymeshlab

    outer = _longest_loop(f)
    if outer is None:
        return v, f, "no boundary loop"
    size = len(outer)  # MeshLab closes the loops of fewer than maxholesize edges
    params = dict(maxholesize=int(size), selected=False, newfaceselected=False,
                  selfintersection=True, refinehole=False,
                  refineholeedgelen=pymeshlab.PercentageValue(3.0))

    def run(repair: bool):
        ms = pymeshlab.MeshSet()
        ms.add_mesh(pymeshlab.Mesh(vertex_matrix=v, face_matrix=f.astype(np.int32)))
        if repair:
            ms.meshing_remove_duplicate_faces()
            ms.meshing_repair_non_manifold_edges(method="Remove Faces")
            ms.meshing_repair_non_manifold_vertices(vertdispratio=0.0)
        ms.meshing_close_holes(**params)
        m = ms.current_mesh()
        if not m.is_compact():
            m.compact()
        return np.array(m.vertex_matrix()), np.array(m.face_matrix(), dtype=np.int64)

    try:
        out_v, out_f = run(False)
        reason = f"maxholesize={size}"
    except pymeshlab.PyMeshLabException as exc:
        out_v, out_f = run(True)
        reason = f"maxholesize={size}; repaired non-manifold first ({str(exc)[:80]})"
    return out_v, out_f, reason


def meshlab_close_holes(scan: Scan) -> Mesh:
    """pymeshlab ``meshing_close_holes(maxholesize=L)`` (module text)."""
    return _isolated("close-holes", _close_holes, scan)


# --------------------------------------------------------------------------- VTK


def _vtk(v: np.ndarray, f: np.ndarray):
    import pyvista as pv

    outer = _longest_loop(f)
    if outer is None:
        return v, f, "no boundary loop"
    extent = float(np.ptp(v[outer], axis=0).max())
    hole_size = 0.99 * 0.5 * extent
    cells = np.column_stack([np.full(len(f), 3), f]).ravel()
    poly = pv.PolyData(v, cells)
    out = poly.fill_holes(hole_size).triangulate()
    faces = np.asarray(out.faces).reshape(-1, 4)
    if not np.all(faces[:, 0] == 3):
        raise RuntimeError("non-triangle cells after triangulate()")
    return np.asarray(out.points, dtype=np.float64), faces[:, 1:], f"hole_size={hole_size:.4g}"


def vtk_fill_holes(scan: Scan) -> Mesh:
    """pyvista ``fill_holes(0.99 * E / 2)`` then ``triangulate()`` (module text)."""
    return _isolated("vtk", _vtk, scan)


# --------------------------------------------------------------------------- TPS


def _tps(v: np.ndarray, f: np.ndarray):
    from matplotlib.path import Path
    from scipy.interpolate import RBFInterpolator
    from scipy.spatial import Delaunay, cKDTree

    from asrbf_mesh._frame import sampling_spacing

    used = np.unique(f)
    xy_all = v[:, :2]
    h = float(sampling_spacing(xy_all[used]))
    tree = cKDTree(xy_all[used])
    new_v: list[np.ndarray] = []
    new_f: list[np.ndarray] = []
    n_total = len(v)
    skipped: list[str] = []
    _, loops = _loops(f, len(v))
    for k, loop in enumerate(loops):
        try:
            rim_xy = xy_all[loop]
            if len(np.unique(rim_xy, axis=0)) < 3:
                skipped.append(f"loop {k} ({len(loop)} v): rim points coincide in xy")
                continue
            poly = Path(np.vstack([rim_xy, rim_xy[:1]]), closed=True)
            lo, hi = rim_xy.min(0), rim_xy.max(0)
            gx = np.arange(lo[0] + 0.5 * h, hi[0], h)
            gy = np.arange(lo[1] + 0.5 * h, hi[1], h)
            g = np.stack(np.meshgrid(gx, gy), -1).reshape(-1, 2)
            if len(g):
                g = g[poly.contains_points(g)]
            if len(g):
                g = g[_seg_dist(g, rim_xy) >= 0.5 * h]
            if len(g):
                near = np.unique(np.concatenate(tree.query_ball_point(rim_xy, 6.0 * h)))
                data = v[used[near]]
                if len(data) > 2000:  # an even subsample, no randomness
                    data = data[:: int(np.ceil(len(data) / 2000))]
                spline = RBFInterpolator(data[:, :2], data[:, 2], kernel="thin_plate_spline",
                                         degree=1, smoothing=0.0)
                z = spline(g)
                if not np.all(np.isfinite(z)):
                    skipped.append(f"loop {k} ({len(loop)} v): spline not finite")
                    continue
            else:
                z = np.zeros(0)
            pts = np.vstack([rim_xy, g])
            tri = Delaunay(pts).simplices
            keep = poly.contains_points(pts[tri].mean(axis=1))
            tri = tri[keep]
            if len(tri) == 0:
                skipped.append(f"loop {k} ({len(loop)} v): no triangle inside the rim")
                continue
            ids = np.concatenate([loop, n_total + np.arange(len(g))])
            new_v.append(np.column_stack([g, z]))
            new_f.append(ids[tri])
            n_total += len(g)
        except Exception as exc:  # noqa: BLE001 - a hole it cannot fill is skipped
            skipped.append(f"loop {k} ({len(loop)} v): {type(exc).__name__}: {exc}")
    out_v = np.vstack([v, *new_v]) if new_v else v
    out_f = np.vstack([f, *new_f]) if new_f else f
    reason = (f"filled {len(new_f)} of {len(loops)} loops"
              + (f"; skipped: {'; '.join(skipped[:5])}" if skipped else ""))
    return out_v, out_f, reason


def _seg_dist(p: np.ndarray, rim: np.ndarray) -> np.ndarray:
    """Distance of (M, 2) points to the closed polygon ``rim`` (n, 2)."""
    a, b = rim, np.roll(rim, -1, axis=0)
    ab = b - a
    den = np.maximum((ab**2).sum(1), 1e-300)
    out = np.full(len(p), np.inf)
    for s in range(0, len(p), 2048):  # chunks: (m, n) temporaries stay small
        q = p[s:s + 2048, None, :]
        t = np.clip(((q - a) * ab).sum(-1) / den, 0.0, 1.0)
        d = np.linalg.norm(q - (a + t[..., None] * ab), axis=-1)
        out[s:s + 2048] = d.min(axis=1)
    return out


def tps_height_field(scan: Scan) -> Mesh:
    """Thin-plate-spline height field over each hole, in the scan's xy (module text)."""
    return _isolated("tps", _tps, scan)


PEERS: dict[str, Callable[[Scan], Mesh]] = {
    "meshfix": meshfix,
    "close-holes": meshlab_close_holes,
    "vtk": vtk_fill_holes,
    "tps": tps_height_field,
}


# --------------------------------------------------------------------------- main


def _poisson_run(v: np.ndarray, f: np.ndarray):
    from asrbf_mesh.evaluate import _meshlab

    m = _meshlab.screened_poisson(v, depth=9)  # every point, as bench_holes_protocol.py
    return m.vertices, m.faces, None


def _poisson(scan: Scan) -> Mesh:
    """Screened Poisson (depth 9) of the punched scan's points, for comparison."""
    return _isolated("poisson", _poisson_run, scan)


def main() -> int:
    import warnings

    from scipy.spatial import cKDTree

    import asrbf_mesh as am
    from asrbf_mesh.evaluate._punch_protocol import punch_protocol, score_holes

    warnings.simplefilter("ignore")
    scan = am.load_scan(am.face_map_path())
    methods = {**PEERS, "poisson": _poisson}
    for seed in (0, 1):
        p = punch_protocol(scan, seed)
        holes = np.flatnonzero(p.enclosed)
        outer0, rest0 = _loops(p.scan.faces, p.scan.n_points)
        print(f"face seed {seed}: {len(holes)} enclosed holes "
              f"(truth points {[int(np.sum(p.hole == h)) for h in holes]}); "
              f"border {max(map(len, outer0))} v, {len(rest0)} other loops", flush=True)
        border0 = cKDTree(p.scan.points[max(outer0, key=len)])
        notch = [i for i, h in enumerate(holes)
                 if border0.query(p.truth[p.hole == h])[0].min() <= 0.004 * p.diagonal]
        if notch:  # libigl splits the border at pinch vertices; the protocol takes one piece
            print(f"  (holes {notch} of these touch the outer border: notches the protocol "
                  "counts as enclosed)", flush=True)
        for name, fn in methods.items():
            t0 = time.perf_counter()
            mesh = fn(p.scan)
            secs = time.perf_counter() - t0
            rms, pooled = score_holes(p, mesh)
            per = " ".join(f"{r:.3f}" for r in rms[holes])
            inner = [h for i, h in enumerate(holes) if i not in notch]
            w = np.array([np.sum(p.hole == h) for h in inner], dtype=float)
            pooled_in = float(np.sqrt(np.sum(w * rms[inner] ** 2) / max(w.sum(), 1.0)))
            outer, rest = _loops(mesh.faces, mesh.n_vertices)
            border = max(map(len, outer)) if outer else 0
            print(f"  {name:12s} {secs:6.1f} s  pooled {pooled:.3f} % (no notch "
                  f"{pooled_in:.3f} %)  per hole [{per}] %  "
                  f"({mesh.n_vertices} v, {mesh.n_faces} f; border {border} v, "
                  f"{len(rest)} other loops open; {REASONS.get(name)})", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
