"""One network per smooth piece of a scan (private prototype of piecewise networks).

A scan seen from one view is cut into pieces that are each a smooth height field
(:func:`~asrbf_mesh.segment`); each piece gets its own network, so no Gaussian has to
bridge an occlusion cliff. All pieces share ONE frame, the whole scan's unit cube
(:func:`~asrbf_mesh.to_height_field` of all points, as :func:`~asrbf_mesh.fit` builds
it): every piece learns with the same absolute thresholds (E, E_omega, D_max, and D_min
from the whole scan's spacing), so nothing is rescaled, and each piece's height field is
the rows of the whole scan's. Pieces flagged small (or with fewer points than learning
needs) get a constant network: no neuron, ``a0`` the mean of their unit depths.

Not exported yet: a later step designs the public type and its file format.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from . import _config
from ._config import FitConfig
from ._frame import HeightField, to_height_field
from ._learn import MIN_POINTS, learn_polished, polish_kind
from ._network import Network
from ._segment import Segmentation, segment
from ._validate import check_bool, check_choice, check_instance, check_points, check_seed
from .errors import ConfigError

__all__ = ["PieceFit", "fit_pieces", "piece_seed"]


@dataclass(frozen=True, eq=False)
class PieceFit:
    """Networks of the pieces of one scan, all in the scan's frame.

    Parameters
    ----------
    segmentation : Segmentation
        The pieces (``labels`` gives each point's piece).
    networks : tuple of Network
        One per piece, index = piece label; the same :class:`~asrbf_mesh.Frame` for all.
    ebar : float
        Mean ``|f - z|`` in the unit cube over all points, each point evaluated by its
        own piece's network.
    n_neurons : int
        Neurons over all pieces.
    n_points : int
        Points of the scan (none is dropped).
    seconds : float
        Wall time of :func:`fit_pieces` (segmentation included when it computed it).
    """

    segmentation: Segmentation
    networks: tuple[Network, ...]
    ebar: float
    n_neurons: int
    n_points: int
    seconds: float


def piece_seed(seed: int, piece: int) -> int:
    """Seed of one piece's learning, derived from the fit's seed and the piece index.

    Examples
    --------
    >>> piece_seed(0, 1) == piece_seed(0, 1) != piece_seed(0, 2)
    True
    """
    return int(np.random.SeedSequence([seed, piece]).generate_state(1, np.uint32)[0])


def fit_pieces(scan: Any, config: FitConfig | None = None, *, seed: int = 0,
               view_axis: str = "z", segmentation: Segmentation | None = None,
               progress: bool | None = False) -> PieceFit:
    """Fit one network per smooth piece of a scan, all in the whole scan's frame.

    Parameters
    ----------
    scan : Scan, Mesh or (N, 3) array_like
        The scan; its triangles (if any) are used by the segmentation.
    config : FitConfig, optional
        Learning parameters, the same for every piece (paper defaults when omitted).
    seed : int
        Piece ``i`` learns with :func:`piece_seed` ``(seed, i)``; the same seed gives the
        same networks bit for bit.
    view_axis : {"z", "x", "y", "pca"}
        Depth direction of the height field (and of the segmentation).
    segmentation : Segmentation, optional
        The pieces; default :func:`~asrbf_mesh.segment` with its defaults. Must cover the
        scan's points and share ``view_axis``.
    progress : bool, optional
        Progress bar of each piece's learning on stderr.

    Returns
    -------
    PieceFit

    Raises
    ------
    ConfigError
        For a bad argument; the message names it.
    ScanError
        Unusable points (NaN, zero x or y extent, ...).
    """
    t0 = time.perf_counter()
    cfg = check_instance(config, "config", FitConfig, allow_none=True) or FitConfig()
    seed = check_seed(seed)
    view_axis = check_choice(view_axis, "view_axis", _config.VIEW_AXES)
    check_instance(segmentation, "segmentation", Segmentation, allow_none=True)
    progress = check_bool(progress, "progress", allow_none=True)
    points = check_points(scan, "points")
    if segmentation is None:
        segmentation = segment(scan, view_axis=view_axis)
    elif segmentation.n_points != len(points):
        raise ConfigError(f"segmentation has {segmentation.n_points:,} points, the scan "
                          f"{len(points):,}")
    elif segmentation.view_axis != view_axis:
        raise ConfigError(f"segmentation was made along view_axis {segmentation.view_axis!r}, "
                          f"not {view_axis!r}")
    hf = to_height_field(points, view_axis=view_axis)  # type: ignore[arg-type]
    polish = polish_kind(hf.fold, cfg.polish)
    networks = []
    absres = np.empty(hf.n_points)
    order = np.argsort(segmentation.labels, kind="stable")
    bounds = np.concatenate([[0], np.cumsum(segmentation.sizes)])
    for i in range(segmentation.n_pieces):
        idx = order[bounds[i]:bounds[i + 1]]
        piece = HeightField(hf.xy[idx], hf.z[idx], hf.frame, hf.spacing, hf.fold)
        net = _fit_piece(piece, cfg, polish, piece_seed(seed, i),
                         bool(segmentation.small[i]), progress)
        absres[idx] = np.abs(piece.z - net.evaluate(piece.xy, unit=True))
        networks.append(net)
    return PieceFit(segmentation, tuple(networks), float(absres.mean()),
                    sum(n.n_neurons for n in networks), hf.n_points,
                    time.perf_counter() - t0)


def _fit_piece(piece: HeightField, cfg: FitConfig, polish: str, seed: int, small: bool,
               progress: bool | None) -> Network:
    """One piece's network: learned and polished, or a constant for a small piece."""
    info = {"n_points": piece.n_points, "seed": seed}
    if small or piece.n_points < MIN_POINTS:
        return Network(float(piece.z.mean()), np.zeros((0, 2)), np.zeros(0), np.zeros(0),
                       piece.frame, cfg, None, {**info, "constant": True})
    learned, _, params, _ = learn_polished(piece, cfg, polish, seed=seed, progress=progress)
    return Network(*params, piece.frame, cfg, learned.log, info)
