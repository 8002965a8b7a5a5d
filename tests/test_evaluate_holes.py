"""The ground-truth hole benchmark of the evaluation module, on a synthetic scan."""

from __future__ import annotations

import numpy as np
import pytest
from test_holes import franke, grid_scan

from asrbf_mesh.errors import ConfigError, ScanError
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


def test_punch_holes_lives_on_the_evaluation_side() -> None:
    import asrbf_mesh as am
    from asrbf_mesh import evaluate

    assert "punch_holes" in evaluate.__all__ and "PunchedScan" in evaluate.__all__
    assert "punch_holes" not in am.__all__ and not hasattr(am, "punch_holes")
    p = evaluate.punch_holes(grid_scan(franke), count=2, seed=4)
    assert isinstance(p, evaluate.PunchedScan) and len(p.radii) == 2
    assert p.scan.n_points + len(p.truth) == grid_scan(franke).n_points


@pytest.mark.parametrize(("kwargs", "error", "match"), [
    ({"count": 0}, ConfigError, "^count must be an integer >= 1, got 0$"),
    ({"seed": 1.5}, ConfigError, "^seed must be an integer >= 0"),
    ({"radius_rel": 0.05}, ConfigError, r"^radius_rel must be two numbers \(low, high\)"),
    ({"radius_rel": (0.06, 0.03)}, ConfigError, r"^radius_rel\[1\] must be a finite number >="),
    ({"count": 400}, ScanError, "^scan: could place only [0-9]+ of 400 interior disks$"),
])
def test_punch_holes_checks_its_parameters(kwargs, error, match) -> None:
    from asrbf_mesh.evaluate import punch_holes

    with pytest.raises(error, match=match):
        punch_holes(grid_scan(franke, nx=20, ny=15), max_tries=200, **kwargs)
