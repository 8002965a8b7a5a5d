"""asrbf-mesh: adaptive sequential learning Gaussian RBF networks for range scans.

Fit a holed, noisy range scan (a height field ``z = f(x, y)``) with a compact
Gaussian RBF network learned sequentially (growth by novelty, NEKF updates,
pruning), then resample, reconstruct and repair surfaces from it.

Examples
--------
>>> import asrbf_mesh as am
>>> scan = am.load_scan(am.face_map_path())        # doctest: +SKIP
>>> net = am.fit(scan, seed=0)                      # doctest: +SKIP
>>> mesh = am.reconstruct(net, footprint=scan)      # doctest: +SKIP
"""

from __future__ import annotations

import os as _os
import sys as _sys
from typing import TYPE_CHECKING

from ._version import __version__
from .errors import AsrbfError, ConfigError, FitError, NetworkFileError, ScanError

# numba's default threading layer probes TBB first and warns about old versions;
# prefer OpenMP / workqueue unless the user chose a layer (read when numba loads).
if "NUMBA_THREADING_LAYER" not in _os.environ:
    if "numba" in _sys.modules:
        _sys.modules["numba"].config.THREADING_LAYER_PRIORITY = ["omp", "workqueue", "tbb"]
    else:
        _os.environ.setdefault("NUMBA_THREADING_LAYER_PRIORITY", "omp workqueue tbb")

# Public name -> the private module that defines it. Names load on first use (PEP 562), so
# ``import asrbf_mesh`` and ``asrbf --help`` do not pay for numba, scipy or the kernels.
_EXPORTS: dict[str, str] = {
    "FitConfig": "_config",
    "Footprint": "_footprint",
    "DuplicatePointsWarning": "_frame",
    "Frame": "_frame",
    "HeightField": "_frame",
    "HeightFieldWarning": "_frame",
    "to_height_field": "_frame",
    "FillResult": "_holes",
    "HoleInfo": "_holes",
    "fill_holes": "_holes",
    "GridFillResult": "_grid_fill",
    "GridHoleInfo": "_grid_fill",
    "fill_grid": "_grid_fill",
    "RangeGrid": "_range",
    "read_range": "_range",
    "write_like": "_range_write",
    "LasMeta": "_lidar",
    "read_las": "_lidar",
    "face_map_path": "_io",
    "load_scan": "_io",
    "save_mesh": "_io",
    "LearnedState": "_learn",
    "NeuronCapWarning": "_learn",
    "OutlierWarning": "_outliers",
    "isolated_points": "_outliers",
    "fit": "_fit",
    "learn": "_learn",
    "LodLevel": "_lod",
    "lod_set": "_lod",
    "Mesh": "_mesh",
    "Scan": "_mesh",
    "FitInfo": "_network",
    "FitLog": "_network",
    "Network": "_network",
    "Piece": "_piece",
    "PieceMap": "_piece_map",
    "NeuronStats": "_network",
    "block_order": "_stream",
    "fit_stream": "_stream",
    "Segmentation": "_segment",
    "segment": "_segment",
    "reconstruct": "_surface",
    # the evaluation side (pymeshlab, matplotlib): a subpackage, loaded on first use
    "evaluate": "",
}

__all__ = ["__version__", "AsrbfError", "ConfigError", "FitError", "NetworkFileError",
           "ScanError", *sorted(n for n in _EXPORTS if n != "evaluate")]

if TYPE_CHECKING:  # what static tools see; at run time __getattr__ imports on demand
    from ._config import FitConfig
    from ._fit import fit
    from ._footprint import Footprint
    from ._frame import (
        DuplicatePointsWarning,
        Frame,
        HeightField,
        HeightFieldWarning,
        to_height_field,
    )
    from ._grid_fill import GridFillResult, GridHoleInfo, fill_grid
    from ._holes import FillResult, HoleInfo, fill_holes
    from ._io import face_map_path, load_scan, save_mesh
    from ._learn import LearnedState, NeuronCapWarning, learn
    from ._lidar import LasMeta, read_las
    from ._lod import LodLevel, lod_set
    from ._mesh import Mesh, Scan
    from ._network import FitInfo, FitLog, Network, NeuronStats
    from ._outliers import OutlierWarning, isolated_points
    from ._piece import Piece
    from ._piece_map import PieceMap
    from ._range import RangeGrid, read_range
    from ._range_write import write_like
    from ._segment import Segmentation, segment
    from ._stream import block_order, fit_stream
    from ._surface import reconstruct


def __getattr__(name: str):
    """Import a public name from its private module on first use (PEP 562)."""
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'asrbf_mesh' has no attribute {name!r}")
    import importlib

    if module:
        value = getattr(importlib.import_module(f"{__name__}.{module}"), name)
    else:
        value = importlib.import_module(f"{__name__}.{name}")
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_EXPORTS))
