"""Learning one network per smooth piece of a scan, all in the whole scan's frame.

A scan seen from one view is cut into pieces that are each a smooth height field
(:func:`~asrbf_mesh.segment`); each piece gets its own network, so no Gaussian has to
bridge an occlusion cliff. All pieces share ONE frame, the whole scan's unit cube: every
piece learns with the same absolute thresholds (E, E_omega, D_max, and D_min from the
whole scan's spacing), so nothing is rescaled, and each piece's height field is the rows
of the whole scan's. A piece with fewer than ``Segmentation.min_piece_points`` points (or
fewer than learning needs) is a constant: no neuron, ``a0`` the mean of its unit depths.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ._config import FitConfig
from ._frame import HeightField
from ._learn import MIN_POINTS, auto_d_min, learn_polished
from ._piece import Piece
from ._piece_map import PieceMap
from ._segment import Segmentation
from ._validate import progress as progress_bar

__all__ = ["PiecesLearned", "learn_pieces", "piece_seed"]


def piece_seed(seed: int, piece: int) -> int:
    """Seed of one piece's learning, derived from the fit's seed and the piece index.

    Examples
    --------
    >>> piece_seed(0, 1) == piece_seed(0, 1) != piece_seed(0, 2)
    True
    """
    return int(np.random.SeedSequence([seed, piece]).generate_state(1, np.uint32)[0])


@dataclass(frozen=True, eq=False)
class PiecesLearned:
    """The pieces of a fit and the figures :func:`~asrbf_mesh.fit` reports over all points.

    ``absres`` is each point's |f - z| in the unit cube (each point evaluated by its own
    piece), ``ebar_sequential`` its mean before the polish; ``steps``,
    ``learn_seconds`` and ``polish_seconds`` are summed over the pieces.
    """

    pieces: tuple[Piece, ...]
    piece_map: PieceMap
    absres: np.ndarray
    ebar_sequential: float
    steps: int
    d_min: float
    learn_seconds: float
    polish_seconds: float


def learn_pieces(hf: HeightField, segmentation: Segmentation, cfg: FitConfig, polish: str, *,
                 seed: int, progress: bool | None = None) -> PiecesLearned:
    """Learn every piece of ``segmentation`` (rows of ``hf``) with piece seeds of ``seed``.

    Pieces are learned one after another (largest first for the progress bar's sake,
    each with :func:`piece_seed` of its own index, so the order does not change a bit).
    """
    absres = np.empty(hf.n_points)
    polish_gain = 0.0  # sum over points of |f - z| before the polish minus after it
    order = np.argsort(segmentation.labels, kind="stable")
    bounds = np.concatenate([[0], np.cumsum(segmentation.sizes)])
    pieces: list[Piece | None] = [None] * segmentation.n_pieces
    steps, learn_s, polish_s, d_min = 0, 0.0, 0.0, float("nan")
    sizes = segmentation.sizes
    learned_points = int(sizes[~segmentation.small & (sizes >= MIN_POINTS)].sum())
    tick = progress_bar(learned_points * cfg.passes, progress, "learning pieces", unit="step")
    for i in np.argsort(-segmentation.sizes, kind="stable"):
        idx = order[bounds[i]:bounds[i + 1]]
        sub = HeightField(hf.xy[idx], hf.z[idx], hf.frame, hf.spacing, hf.fold)
        info: dict[str, Any] = {"n_points": sub.n_points, "seed": piece_seed(seed, int(i))}
        if segmentation.small[i] or sub.n_points < MIN_POINTS:
            piece = Piece(float(sub.z.mean()), np.zeros((0, 2)), np.zeros(0), np.zeros(0),
                          None, {**info, "constant": True})
            seq = None
        else:
            learned, pr, params, seconds = learn_polished(sub, cfg, polish, seed=info["seed"],
                                                          progress=False)
            piece = Piece(*params, learned.log, info)
            seq = None if pr is None else pr.ebar_before * sub.n_points
            steps += learned.steps
            learn_s += learned.seconds
            polish_s += seconds
            d_min = learned.d_min
            if tick:
                tick(learned.steps)
        res = np.abs(sub.z - piece.eval_unit(sub.xy, cfg.support)[0])
        absres[idx] = res
        if seq is not None:
            polish_gain += seq - float(res.sum())
        piece.info["ebar"] = float(res.mean())
        pieces[i] = piece
    if np.isnan(d_min):  # every piece is a constant: report the rule's D_min all the same
        d_min = min(cfg.d_min if cfg.d_min is not None
                    else auto_d_min(hf.spacing, cfg.error_threshold), cfg.d_max)
    pm = PieceMap.of_points(hf.xy, segmentation.labels, hf.spacing)
    return PiecesLearned(tuple(pieces), pm, absres,  # type: ignore[arg-type]
                         float(absres.mean()) + polish_gain / hf.n_points, steps, d_min,
                         learn_s, polish_s)
