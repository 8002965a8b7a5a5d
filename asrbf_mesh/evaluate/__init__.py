"""Evaluation: Metro distances, the SOM baseline, comparisons and reports.

>>> from asrbf_mesh.evaluate import metro       # doctest: +SKIP
>>> metro(mesh, scan).rms_pct                   # doctest: +SKIP
"""

from __future__ import annotations

from .metro import Direction, MetroResult, metro

__all__ = ["Direction", "MetroResult", "metro"]
