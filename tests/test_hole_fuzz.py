"""A short crash campaign of hole filling (the long one: scripts/bench_holes_protocol.py).

Every case runs in a child process, so a crash of a native library (SIGSEGV, abort) fails
the test with its exit code instead of killing the test run.
"""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

CHILD = textwrap.dedent("""
    import json, sys, warnings
    import numpy as np
    import asrbf_mesh as am
    from asrbf_mesh.evaluate._punch_protocol import punch_protocol, score_holes
    warnings.simplefilter("ignore")
    kind, seed = sys.argv[1], int(sys.argv[2])
    if kind == "face":
        p = punch_protocol(am.load_scan(am.face_map_path()), seed)
        scan = p.scan
    else:
        from asrbf_mesh.evaluate._synthetic_holes import synthetic_holes
        scan = synthetic_holes(kind, seed)
    res = am.fill_holes(scan, seed=seed, progress=False)
    def uses(F):
        e = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
        return np.unique(e, axis=0, return_counts=True)[1]
    F = res.mesh.faces
    print(json.dumps({"found": res.holes_found, "filled": res.holes_filled,
                      "reasons": [h.reason for h in res.holes if not h.filled],
                      "finite": bool(np.isfinite(res.mesh.vertices).all()),
                      "repeated": int(np.sum((F[:, 0] == F[:, 1]) | (F[:, 1] == F[:, 2])
                                             | (F[:, 0] == F[:, 2]))),
                      "kept": bool(np.array_equal(res.mesh.vertices[:scan.n_points],
                                                  scan.points)),
                      "edge_faces": int(uses(F).max()),
                      "scan_edge_faces": int(uses(scan.faces).max())}))
""")


@pytest.mark.parametrize("kind, seed", [("face", 0), ("face", 6), ("cliff", 1), ("spiral", 1),
                                        ("nested", 0), ("fold", 0), ("fold", 2),
                                        ("cylinder", 0), ("random", 7)])
def test_fill_holes_never_crashes_and_reports_every_hole(kind: str, seed: int) -> None:
    proc = subprocess.run([sys.executable, "-c", CHILD, kind, str(seed)],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, f"exit {proc.returncode}: {proc.stderr[-2000:]}"
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert out["finite"]
    assert out["found"] >= 1
    # the scan kept; no triangle with a vertex twice, no edge with more faces than the
    # scan's own edges have (2 on these scans; a non-manifold scan may have more)
    assert out["kept"] and out["repeated"] == 0
    assert out["edge_faces"] <= max(2, out["scan_edge_faces"])
    # every hole is filled or reported with its reason
    assert len(out["reasons"]) == out["found"] - out["filled"]
    assert all(isinstance(r, str) and r for r in out["reasons"])


DEFECT_CHILD = textwrap.dedent("""
    import json, sys, warnings
    import numpy as np
    import asrbf_mesh as am
    sys.path.insert(0, sys.argv[2])
    from bench_mesh_defects import crop, spoil  # the benchmark's crop, holes and defects
    warnings.simplefilter("ignore")
    P, F = spoil(sys.argv[1], *crop(), 0)
    res = am.fill_holes(am.Scan(P, F), seed=0, progress=False)
    print(json.dumps({"found": res.holes_found, "filled": res.holes_filled,
                      "reasons": [h.reason for h in res.holes if not h.filled],
                      "finite": bool(np.isfinite(res.mesh.vertices).all()),
                      "kept": bool(np.array_equal(res.mesh.vertices[:len(P)], P))}))
""")
SCRIPTS = str(Path(__file__).resolve().parents[1] / "scripts")


@pytest.mark.parametrize("kind", ["rounded-1.25", "copies", "turned", "repeated", "fins",
                                  "cracks", "unwelded"])
def test_fill_holes_takes_mesh_defects_without_crash(kind: str) -> None:
    # rounded: points at one xy made the residual spline's system singular (LinAlgError
    # out of fill_holes); copies, fins, turned and repeated faces hid or spoiled the holes
    proc = subprocess.run([sys.executable, "-c", DEFECT_CHILD, kind, SCRIPTS],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, f"exit {proc.returncode}: {proc.stderr[-2000:]}"
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert out["finite"] and out["kept"] and out["found"] >= 5
    assert len(out["reasons"]) == out["found"] - out["filled"]
    assert all(isinstance(r, str) and r for r in out["reasons"])
    if kind == "unwelded":  # every face its own corners: a patch shares no rim edge
        assert all("rim edges could not be closed" in r for r in out["reasons"])
    elif kind != "rounded-1.25":  # mended (or zero-width holes): every hole filled but
        # where a fill would overlap a cracked face (its corners copies: cracks seed 0, 2)
        assert all("would cross the scan" in r for r in out["reasons"])
        assert out["filled"] >= out["found"] - 3


TRIANGULATE_CHILD = textwrap.dedent("""
    import json, sys
    import numpy as np
    from asrbf_mesh._triangle import delaunay, triangulate
    rng = np.random.default_rng(int(sys.argv[1]))
    out = []
    for case in range(300):
        n = int(rng.integers(1, 12))
        kind = case % 6
        if kind == 0:  # all on one line: triangle crashes (SIGSEGV)
            t = rng.random(n)
            p = np.c_[t, 2 * t + 1]
        elif kind == 1:  # exact copies joined by segments: triangle loops forever
            p = rng.random((n, 2))
            p = np.vstack([p, p[: n // 2]])
        elif kind == 2:  # copies 1e-15 apart: the same
            p = rng.random((n, 2))
            p = np.vstack([p, p[: n // 2] + 1e-15])
        elif kind == 3:  # a lattice: collinear, overlapping segments
            p = np.array([[i, j] for i in range(3) for j in range(3)], float)
        elif kind == 4:  # one point many times
            p = np.repeat(rng.random((1, 2)), n, axis=0)
        else:
            p = rng.random((n, 2))
        m = len(p)
        seg = rng.integers(0, m, size=(int(rng.integers(0, 2 * m + 1)), 2))
        if case % 12 == 5:  # a staircase on a lattice of inexact steps closed by its
            # chord, which passes within rounding of some corners: triangle looped forever
            base = rng.integers(0, 2, size=int(rng.integers(3, 12)))
            steps = np.tile(base, int(rng.integers(2, 6)))  # the chord meets its corners
            ij = np.cumsum(np.c_[steps, 1 - steps], axis=0)
            p = rng.uniform(-0.1, 0.1, 2) + rng.uniform(1e-4, 1e-3, 2) * ij
            m = len(p)
            seg = np.column_stack([np.arange(m), (np.arange(m) + 1) % m])
        if case % 4 == 0:
            seg = seg[:0]  # no segment with the p switch: an IndexError in triangle's wrapper
        tris, extra = triangulate(p, seg, ["pYQ", "pcYQ", "pQ"][case % 3])
        assert tris.ndim == 2 and tris.shape[1] == 3
        assert len(tris) == 0 or tris.max() < m + len(extra)
        out.append(len(tris))
        d = delaunay(p)  # a bare cloud's triangulation goes through the same door
        assert d.ndim == 2 and d.shape[1] == 3 and (len(d) == 0 or d.max() < m)
    print(json.dumps(out))
""")


@pytest.mark.parametrize("seed", [0, 1])
def test_triangulate_takes_degenerate_input_without_crash_or_hang(seed: int) -> None:
    proc = subprocess.run([sys.executable, "-c", TRIANGULATE_CHILD, str(seed)],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, f"exit {proc.returncode}: {proc.stderr[-2000:]}"
    counts = json.loads(proc.stdout.strip().splitlines()[-1])
    assert len(counts) == 300 and sum(c > 0 for c in counts) > 50  # most cases triangulate


def test_triangulate_refuses_points_off_the_segments() -> None:
    import numpy as np

    from asrbf_mesh._triangle import triangulate

    p = np.array([[0.0, 0], [1, 0], [0, 1]])
    with pytest.raises(ValueError):
        triangulate(p, np.array([[0, 3]]), "pQ")
    with pytest.raises(ValueError):
        triangulate(np.array([[0.0, 0], [1, np.nan], [0, 1]]), np.zeros((0, 2), int), "pQ")
    tris, extra = triangulate(np.vstack([p, p[:1]]), np.array([[0, 1], [1, 2], [2, 3]]), "pQ")
    assert len(tris) == 1 and set(tris[0].tolist()) == {0, 1, 2} and len(extra) == 0
    # read-only arrays (triangle's wrapper raises on them) are taken as any others
    q, s = np.vstack([p, [[1.0, 1.0]]]), np.array([[0, 1], [1, 3], [3, 2], [2, 0]])
    q.flags.writeable = s.flags.writeable = False
    assert len(triangulate(q, s, "pQ")[0]) == 2


def test_triangles_own_messages_stay_off_stdout(capfd) -> None:
    # a staircase rim closed by a diagonal through its corners (a loop of a synthetic
    # bunny view, punch seed 8): triangle prints "Internal error in
    # segmentintersection()" with C's printf before its wrapper raises; on stdout that
    # broke `asrbf fill-holes --json`
    import numpy as np

    from asrbf_mesh._triangle import triangulate

    x = [-0.0003222006709305558, -0.0008222901838575089, -0.001322379696784469,
         -0.001822469209711429, -0.002322558722638389, -0.002822648235565342,
         -0.003322737748492302, -0.003822827261419262]
    y = [0.06580634202622537, 0.06630643153915233, 0.06680652105207929,
         0.06730661056500625, 0.06780670007793321, 0.06830678959086017,
         0.06880687910378713, 0.06930696861671409]
    steps = [(0, 0), (1, 0), (2, 0), (2, 1), (2, 2), (3, 2), (3, 3), (3, 4), (4, 4), (4, 5),
             (5, 5), (5, 6), (6, 6), (6, 7), (7, 7)]
    pts = np.array([[x[i], y[j]] for i, j in steps])
    seg = np.column_stack([np.arange(15), (np.arange(15) + 1) % 15])
    print("before", flush=True)
    tris, extra = triangulate(pts, seg, "pQ")
    print("after", flush=True)
    out = capfd.readouterr().out
    assert out == "before\nafter\n"
    # the diagonal is split at the corners it passes through (within rounding) before
    # triangle sees it: the eight triangles between it and the stairs, nothing added
    assert len(tris) == 8 and len(extra) == 0
    # and what native code prints meanwhile goes nowhere
    import ctypes

    from asrbf_mesh._triangle import _native_stdout_muted

    with _native_stdout_muted():
        ctypes.CDLL(None).printf(b"Internal error in segmentintersection()\n")
    print("done", flush=True)
    assert capfd.readouterr().out == "done\n"


def test_delaunay_of_a_grid_and_of_copies() -> None:
    # a regular grid (cocircular everywhere: qhull took 1.2 s on 300 x 300) gives two
    # counter-clockwise triangles per cell; copies of a point are in no triangle but the
    # first copy's; points on a line give none
    import numpy as np

    from asrbf_mesh._footprint import signed_areas
    from asrbf_mesh._triangle import delaunay

    g = np.linspace(0.0, 1.0, 30)
    xy = np.array([[x, y] for y in g for x in g])
    tris = delaunay(xy)
    assert len(tris) == 2 * 29 * 29
    assert (signed_areas(xy, tris) > 0).all()
    dup = np.vstack([xy, xy[:5]])
    tris = delaunay(dup)
    assert len(tris) == 2 * 29 * 29 and tris.max() < len(xy)
    assert len(delaunay(np.c_[g, 2 * g])) == 0


def test_synthetic_holed_scans_are_reproducible_and_holed() -> None:
    import numpy as np

    from asrbf_mesh._hole_loops import boundary_cycles
    from asrbf_mesh.evaluate._synthetic_holes import SYNTHETIC_KINDS, synthetic_holes

    for kind in SYNTHETIC_KINDS:
        a, b = synthetic_holes(kind, 3), synthetic_holes(kind, 3)
        assert np.array_equal(a.points, b.points) and np.array_equal(a.faces, b.faces)
        assert not np.array_equal(a.points, synthetic_holes(kind, 4).points)
        # the outer border and at least one more loop over seeds 0-4 (a hole, or a notch)
        assert max(len(boundary_cycles(synthetic_holes(kind, s).faces)) for s in range(5)) >= 2
    with pytest.raises(ValueError, match="unknown kind"):
        synthetic_holes("donut", 0)


# The rim of a fold's layer closed by its chord (a synthetic bunny view punched with seed
# 69, fill_layers): a 46-point staircase whose chord passes within rounding (2e-18) of two
# of its corners without being on them for triangle's exact tests; triangle inserted the
# chord's crossings next to those corners and looped forever. The points, bit for bit
# (float64, little-endian, zlib, base64); the segments join them in order and close.
CHORD_HANG = (
    "eNpdzF1MUlEAAGAXhcNktTVmP1qNWJOlKU3JqXWClRkWabM0NiynzkVZEk2Wm8WiWZRFoiPCzU3XSC6X+4O2"
    "GS5OaRYL05BexB6wWBRsZMFaI1y9cbYev5dvNppuIbwk/LCZv5TjwkHWTl8b9wEJez7LN2F/cXBGPlhslJLw"
    "IG6oEYrs4En/uRUWm4TJK290kzfs4LunaLrLQ8CxfcmX0lfICqYg4V9DgBJG2r0fOgJy51r2tB4mgKbUU9tS"
    "SUD/Q7MidhvZcHZu+PpbAriVxuwFJgEl/NWLazPJlFf9LNlgOobsdLZV8fQkWG9tDB6dtsPL2mEt9R6ZY4nI"
    "t7KolNszmJ1BPvLMxe1GTIKc6yt1tJ+nQH0gD3+hRR7K+q0qEtvhzb0nZ4U9FPgmnSobSUMWdN9nZEM85avP"
    "T3v0XciTcV4foxyHgYFL4SROgYy8ZZk6YUv5RNMENzKObDZ3hxvUNliedoc59Y4Cn7w1jvliGzQ1P+bqohTY"
    "xcrprIhjKasOfBU5HRiMu137j6+jwYR6lLVbicHq/AUZp5AGDPKad6gAg7beWMdiNQ2qvhx5xIlaYfovdt+Q"
    "kgb9OZxGHW6FTbJcstWADF1iT/4oDT7WBnJXFFa4ZYc8FPPRgNdjW27nW6H6lprhjCP7Ir3bNBwHuDDVMR4M"
    "jcCCarysQoh8d+x1XWadAzxNiDT1FuQVAbtypnkEhjYuqebVyOKuP3qTCXlwiYM3PENOHCp08/zo+9+nMEkw"
    "nHCAf4T0gUE="
)

CHORD_CHILD = textwrap.dedent("""
    import base64, json, sys, zlib
    import numpy as np
    from asrbf_mesh._triangle import triangulate
    p = np.frombuffer(zlib.decompress(base64.b64decode(sys.argv[1])), "<f8").reshape(-1, 2)
    p = p.copy()  # writable, as a fill's arrays are
    seg = np.column_stack([np.arange(len(p)), (np.arange(len(p)) + 1) % len(p)])
    tris, extra = triangulate(p, seg, "pQ")
    print(json.dumps([len(p), len(tris), len(extra)]))
""")


def test_a_chord_within_rounding_of_corners_does_not_hang_triangle() -> None:
    proc = subprocess.run([sys.executable, "-c", CHORD_CHILD, "".join(CHORD_HANG)],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, f"exit {proc.returncode}: {proc.stderr[-2000:]}"
    n, n_tris, n_extra = json.loads(proc.stdout.strip().splitlines()[-1])
    # the chord is split at the two corners; it still crosses the stairs once: triangle
    # adds that crossing (what tells the caller the polygon is not simple)
    assert n == 46 and n_tris > 0 and n_extra == 1
