"""Evaluation: Metro distances, the SOM baseline, comparisons and reports.

>>> from asrbf_mesh.evaluate import metro       # doctest: +SKIP
>>> metro(mesh, scan).rms_pct                   # doctest: +SKIP
"""

from __future__ import annotations

from .metro import Direction, MetroResult, metro
from .som import SomComparison, SomMap, compare_som, network_vertices, som_grid, train_som

__all__ = ["Direction", "MetroResult", "SomComparison", "SomMap", "compare_som", "metro",
           "network_vertices", "som_grid", "train_som"]
