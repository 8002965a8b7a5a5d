"""Segmentation of the shipped and benchmark scans into smooth height-field pieces.

Run from the repository root:  python scripts/bench_segment.py [--wall-angle DEG]
[--jump-factor F] [--min-piece-points 30]

For the face map, the Stanford bunny scans (read from the folder named by
$ASRBF_BUNNY_DIR; skipped without it) and ``tests/data/bun000_crop.ply``, segment each
scan twice: with its triangles (``faces``) and as a bare point cloud (``cloud``: faces
dropped, the view-plane triangulation of the cloud instead). Prints one Markdown table:
points, pieces, the largest piece's share, small pieces and the points in them, triangles
cut, and the time of :func:`asrbf_mesh.segment` (best of 3). Without ``--wall-angle`` and
``--jump-factor`` it prints two tables: the package defaults (80 degrees, 5 median edges)
and the prototype's rule (72.5 degrees, 3 median edges).
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _bench_common import (  # noqa: E402
    ROOT,
    best_time,
    machine,
    scans,
    table,
    write_section,
)

import asrbf_mesh as am  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--wall-angle", type=float)
    ap.add_argument("--jump-factor", type=float)
    ap.add_argument("--min-piece-points", type=int, default=30)
    args = ap.parse_args(argv)
    if args.wall_angle is None and args.jump_factor is None:
        settings = [(80.0, 5.0), (72.5, 3.0)]
    else:
        settings = [(80.0 if args.wall_angle is None else args.wall_angle,
                     5.0 if args.jump_factor is None else args.jump_factor)]

    found = scans()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        found["bun000_crop"] = am.load_scan(ROOT / "tests" / "data" / "bun000_crop.ply")
    t0 = time.perf_counter()
    parts = []
    for wall, jump in settings:
        opts = {"wall_angle_deg": wall, "jump_factor": jump,
                "min_piece_points": args.min_piece_points}
        parts.append(f"Wall angle {wall:g}°, jump factor {jump:g}, min piece points "
                     f"{args.min_piece_points}"
                     f"{' (the defaults)' if (wall, jump) == (80.0, 5.0) else ''}:\n\n"
                     + table(HEADERS, _rows(found, opts)))
    head = (f"## Segmentation into smooth pieces (issue 14, first step)\n\n"
            f"_Measured {time.strftime('%Y-%m-%d')} on {machine()}; "
            f"`python scripts/bench_segment.py` ({time.perf_counter() - t0:.0f} s)._\n\n"
            "`am.segment` cuts the triangles seen nearly edge-on (|n·view| < cos(wall angle)) "
            "or with a longest edge over the jump factor × the median edge, when their "
            "depth extent is over the minimum step (default: 1 % of the robust depth "
            "extent, and 2.5 depth quanta where depths come in levels) and a quadratic "
            "through the 16 points around them misses those by over 0.1 of that extent "
            "(RMS; rule 1b: a steep slope of a smooth surface is no wall); connected "
            "components of the rest are the pieces (a point cloud is triangulated in the "
            "view plane first), and a piece wrapped around the end of a cliff is split "
            "(rule 4 of `asrbf_mesh._segment`). What `fit` uses by default "
            "(`--pieces auto`).\n\n")
    body = head + "\n\n".join(parts)
    print(body)
    if len(settings) == 2:
        write_section("segment", body)
    return 0


HEADERS = ["scan", "path", "N", "pieces", "largest piece %", "small pieces",
           "points in small", "cut / triangles", "seconds"]


def _rows(found: dict[str, am.Scan], opts: dict) -> list[list]:
    rows = []
    for name, scan in found.items():
        for source, data in (("faces", scan), ("cloud", scan.points)):
            seg = am.segment(data, **opts)
            seconds = best_time(am.segment, data, **opts)
            d = seg.to_dict()
            rows.append([name, source, d["n_points"], d["n_pieces"],
                         f"{100 * d['largest_fraction']:.1f}", d["n_small"],
                         d["points_in_small"], f"{d['n_cut']:,} / {d['n_triangles']:,}",
                         f"{seconds:.3f}"])
    return rows


if __name__ == "__main__":
    raise SystemExit(main())
