"""The ground-truth hole benchmark of the evaluation module, on a synthetic scan."""

from __future__ import annotations

import numpy as np
from test_holes import franke, grid_scan

from asrbf_mesh.evaluate._holes_bench import HOLE_METHODS, hole_benchmark


def test_hole_benchmark_rows_on_a_smooth_surface() -> None:
    scan = grid_scan(franke)
    seen = []
    rows = hole_benchmark(scan, count=3, seed=1, on_step=seen.append)
    assert [r.method for r in rows] == list(HOLE_METHODS) == seen
    n = rows[0].truth_points
    assert n > 50 and all(r.truth_points == n for r in rows)
    for r in rows:
        assert np.isfinite([r.mean_pct, r.rms_pct, r.max_pct, r.seconds]).all()
        assert 0 <= r.mean_pct <= r.rms_pct <= r.max_pct
    ours = rows[0]
    assert ours.closed == "3/3"
    # on a smooth analytic surface the fill is far below 1 % of the diagonal, and below
    # MeshLab's flat Close Holes
    assert ours.rms_pct < 0.1 and ours.rms_pct < rows[2].rms_pct
