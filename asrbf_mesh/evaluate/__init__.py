"""Evaluation: Metro distances, the SOM baseline, hole and LOD benchmarks, reports.

This side of the package holds everything that needs pymeshlab or matplotlib; the
core (``import asrbf_mesh``) loads neither.

>>> from asrbf_mesh.evaluate import metro       # doctest: +SKIP
>>> metro(mesh, scan).rms_pct                   # doctest: +SKIP
"""

from __future__ import annotations

from ._holes_bench import HOLE_METHODS, HoleRow, hole_benchmark
from ._lod_report import QEM_BASELINES, write_lod_set
from ._metro import Direction, MetroResult, metro
from ._punch import PunchedScan, punch_holes
from ._report import Comparison, compare, load_compare, write_compare, write_summary
from ._som import SomComparison, SomMap, compare_som, network_vertices, som_grid, train_som

__all__ = [
    "HOLE_METHODS",
    "QEM_BASELINES",
    "Comparison",
    "Direction",
    "HoleRow",
    "MetroResult",
    "PunchedScan",
    "SomComparison",
    "SomMap",
    "compare",
    "compare_som",
    "hole_benchmark",
    "load_compare",
    "metro",
    "network_vertices",
    "punch_holes",
    "som_grid",
    "train_som",
    "write_compare",
    "write_lod_set",
    "write_summary",
]
