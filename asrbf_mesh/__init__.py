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

# numba's default threading layer probes TBB first and warns about old versions;
# prefer OpenMP / workqueue unless the user chose a layer.
if "NUMBA_THREADING_LAYER" not in _os.environ:
    import numba as _numba

    _numba.config.THREADING_LAYER_PRIORITY = ["omp", "workqueue", "tbb"]

from ._config import FitConfig
from ._footprint import Footprint
from ._frame import DuplicatePointsWarning, Frame, HeightField, HeightFieldWarning, to_height_field
from ._holes import FillResult, HoleInfo, fill_holes
from ._io import face_map_path, load_scan, save_mesh
from ._learn import LearnedState, NeuronCapWarning, fit, learn
from ._lod import LodLevel, lod_set
from ._mesh import Mesh, Scan
from ._network import FitInfo, FitLog, Network, NeuronStats
from ._stream import block_order, fit_stream
from ._surface import reconstruct
from ._version import __version__
from .errors import AsrbfError, ConfigError, FitError, NetworkFileError, ScanError

__all__ = [
    "__version__",
    "AsrbfError",
    "ConfigError",
    "DuplicatePointsWarning",
    "FillResult",
    "FitConfig",
    "FitError",
    "FitInfo",
    "FitLog",
    "Footprint",
    "Frame",
    "HeightField",
    "HeightFieldWarning",
    "HoleInfo",
    "LearnedState",
    "LodLevel",
    "Mesh",
    "Network",
    "NetworkFileError",
    "NeuronCapWarning",
    "NeuronStats",
    "Scan",
    "ScanError",
    "face_map_path",
    "fill_holes",
    "fit",
    "block_order",
    "fit_stream",
    "learn",
    "load_scan",
    "lod_set",
    "reconstruct",
    "save_mesh",
    "to_height_field",
]

_LAZY = {
    # the evaluation side (pymeshlab, matplotlib) loads on first use only
    "evaluate": ("asrbf_mesh.evaluate", None),
}


def __getattr__(name: str):
    """Load the evaluation side on first use: ``import asrbf_mesh`` stays free of pymeshlab."""
    if name in _LAZY:
        import importlib

        module, attr = _LAZY[name]
        value = importlib.import_module(module)
        value = value if attr is None else getattr(value, attr)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'asrbf_mesh' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))
