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

from . import evaluate
from ._version import __version__
from .config import FitConfig
from .errors import AsrbfError, ConfigError, FitError, NetworkFileError, ScanError
from .footprint import Footprint
from .frame import DuplicatePointsWarning, Frame, HeightField, HeightFieldWarning, to_height_field
from .holes import FillResult, HoleInfo, fill_holes, punch_holes
from .io import Scan, face_map_path, load_scan, save_mesh
from .learn import NeuronCapWarning, fit, learn
from .lod import LodLevel, lod_set, write_lod_set
from .mesh import Mesh
from .network import FitLog, Network, NeuronStats
from .stream import fit_stream
from .surface import reconstruct

__all__ = [
    "__version__",
    "evaluate",
    "AsrbfError",
    "ConfigError",
    "DuplicatePointsWarning",
    "FillResult",
    "FitConfig",
    "FitError",
    "FitLog",
    "Footprint",
    "Frame",
    "HeightField",
    "HeightFieldWarning",
    "HoleInfo",
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
    "fit_stream",
    "learn",
    "load_scan",
    "lod_set",
    "punch_holes",
    "reconstruct",
    "save_mesh",
    "to_height_field",
    "write_lod_set",
]
