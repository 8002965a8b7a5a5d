"""Learning one network per smooth piece of a scan, all in the whole scan's frame.

A scan seen from one view is cut into pieces that are each a smooth height field
(:func:`~asrbf_mesh.segment`); each piece gets its own network, so no Gaussian has to
bridge an occlusion cliff. All pieces share ONE frame, the whole scan's unit cube: every
piece learns with the same absolute thresholds (E, E_omega, D_max, and D_min from the
whole scan's spacing), so nothing is rescaled, and each piece's height field is the rows
of the whole scan's. A piece with fewer than ``Segmentation.min_piece_points`` points (or
fewer than learning needs) gets a small network instead of learning (:func:`small_piece`):
up to three wide neurons on its three mutually farthest points, weights by least squares,
as few as fit its points within E (one neuron, a ramp across the fragment, fits most
fragments of a grazing flank), which takes a tilted or bent fragment (a constant misses a
steep one by its whole slope); one point, or points on a line, stay a constant.

After the polish, each learned piece's tails are refined (:func:`refine_tails`): its
points whose error across the surface still exceeds ``TAIL_FACTOR`` x E (and three times
the piece's robust noise scale) get neurons, a few at a time, and the weights are solved
again. Sequential learning leaves those points behind where neurons cannot come closer
than D_min: small steep features, the rims of pieces. Measured with
``scripts/bench_pieces.py`` (seeds 0-2, BENCHMARKS "pieces"): the 99.9th percentile of
the distances between the scan and its default reconstruction, both ways, fell from
0.57-0.82 % of the diagonal to 0.34-0.57 %, and E-bar fell on every scan. Then the
neurons the piece hardly needs are dropped (greedy backward elimination, within a share
of what the tails gained): sequential learning places neurons by novelty, not by need,
and the tails add more than they keep. With both, K and E-bar fell below the single
network's on all five scans (face map: 696 neurons and E-bar 0.00191 against 781 and
0.00198, medians of seeds 0-2), the 99.9th percentiles at 0.33-0.55 %.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from itertools import combinations
from typing import Any

import numpy as np

from ._config import FitConfig
from ._frame import HeightField
from ._grid_knn import point_grid, spread
from ._learn import MIN_POINTS, auto_d_min, learn_polished
from ._piece import Piece
from ._piece_map import PieceMap
from ._polish import (
    DENSE_MAX,
    GrownNormal,
    _ridged,
    appended_rows,
    drop_idle,
    extend_and_solve,
    extend_normal,
    polish_weights,
    solve_and_drop,
)
from ._segment import Segmentation, depth_quanta
from ._tail_shapes import DataShapes, across, past_border
from ._validate import progress as progress_bar

__all__ = ["PiecesLearned", "learn_pieces", "parallel_pieces", "piece_seed",
           "refine_tails", "small_piece"]

#: Tail refinement: points whose error exceeds this multiple of E get neurons.
TAIL_FACTOR = 0.6
#: Tail refinement: at most this many rounds of insertion and weight solving.
TAIL_ROUNDS = 2
#: Tail refinement: the threshold is at least this many robust noise scales of the piece.
TAIL_NOISE = 3.0
#: Tail refinement: where depths come in levels (a depth camera's quanta), the threshold
#: is at least this many quanta at the point's depth: a smooth surface through steps one
#: quantum high misses them by up to half a quantum, plus the camera's own noise (about
#: a quantum). Measured on the two Kinect frames (``scripts/bench_kinect_mesh.py``, seed 0):
#: K 421 -> 327 and 305 -> 259 (the single network's: 362 and 296), E-bar 0.00137 ->
#: 0.00140 and 0.00131 -> 0.00133 (single: 0.00289, 0.00277); 1 quantum gave 348 and
#: 274, 2 quanta 325 and 257.
TAIL_QUANTA = 1.5
#: Tail refinement: where depths come in levels, a point gets a neuron only when at least
#: this many of its 8 nearest points of the piece miss the same side by the threshold
#: too: a depth camera's lone misses (a flying pixel at an edge, speckle) are its noise,
#: not a feature the surface lacks. Measured on the Kinect frames (seeds 2 and 5 of
#: desk2, 0 of desk): K 275 -> 259, 265 -> 252, 327 -> 316, E-bar within 0.00002, the
#: 99.9th percentiles of the default reconstruction within 0.01 % of the diagonal.
TAIL_SUPPORT = 3
#: The same support is asked of a piece of at least ``NOISY_MIN_POINTS`` points whose
#: first round finds more than ``NOISY_MISSES`` of its points above the threshold, fewer
#: than ``NOISY_SUPPORT`` of them supported, 90 % of them within ``NOISY_SPREAD`` times
#: the threshold (or fewer than ``NOISY_LONE`` supported): misses that many, that lone
#: and that small are the piece's noise (a Gaussian's tail beyond the threshold: 1.5-1.6
#: times it at its 90th percentile; a ridge two samples wide that learning left behind,
#: 17 % of its grid's points, 47 % supported: 3.0, and it keeps its tails). The
#: threshold (0.6 E, or three robust noise scales, the MAD taken of the errors' absolute
#: values: about 1.8 sigma of Gaussian noise) is within reach of noise near E: on 100 x
#: 100 grids of sin(x) cos(y), (x^2 - y^2) and a saddle with noise of 0.35-1.2 % of
#: their depth range, 7-8.5 % of the points missed by it, 9-31 % of those supported, and
#: the tails chased them: K 1.1-2.0x the single network's (1,498 -> 2,466 on [0, 1]^2
#: with noise 0.01, and 0.0080 off the true surface against 0.0052), the fit 1.7-4.3x
#: its time (``scripts/bench_pieces_synthetic.py``, the last four surfaces). The dev
#: scans' and the synthetic views' pieces of 1,000 points or more: 0.9-4.5 % missing in
#: the first round (31-95 % supported, 0 % on a piece of 1,116 points with 14 misses):
#: the same networks there, bit for bit.
NOISY_MIN_POINTS = 1000
#: See ``NOISY_MIN_POINTS``.
NOISY_MISSES = 0.05
#: See ``NOISY_MIN_POINTS``.
NOISY_SUPPORT = 0.5
#: See ``NOISY_MIN_POINTS``.
NOISY_SPREAD = 2.0
#: ... or fewer than this share supported, however far they miss: 8 Gaussian bumps with
#: noise 0.01 had 13 % of their points missing, 4 % of those supported, but the bumps'
#: flanks took their 90th percentile past twice the threshold; the tails chased the
#: noise (K 1,431 -> 2,559, 1.37x farther from the true surface) on seeds 0 and 2.
NOISY_LONE = 0.2
#: Tail refinement: neurons whose learned |weight| is under this multiple of E are dropped
#: before the polish of a piece of several (it saves 5-10 % of the face map's fit). A
#: scan of one piece keeps them all (:func:`~asrbf_mesh._fit.fit`): it learns as the
#: single network does, and its tails then never leave it worse. Dropped there, they
#: raised E-bar on smooth surfaces with little noise, where many weak neurons carry the
#: fine shape together: a 300 x 300 grid of z = sin(4x) cos(3y), noise 0.0005, E-bar
#: 0.00091 (single network) -> 0.00106. Without the drop in pieces too, the face map's
#: main piece (seed 8: 1,399 neurons learned) kept 1,040 and fitted in 1.8x the single
#: network's time.
TAIL_PRUNE = 0.3
#: Tail refinement of a scan of one piece (``no_more``): its tails' neurons are paid for by
#: as many dropped, the cheapest first, whatever each costs, while the removals together
#: give back at most this share of what the tails gained (else the polished network).
NET_GIVE_BACK = 0.75
#: Tail refinement, after the rounds: neurons whose removal (the other weights solved
#: again) raises the sum of squared errors by less than this many E^2 are dropped
#: (:func:`~asrbf_mesh._polish.solve_and_drop`).
IDLE_RSS = 12.0
#: Tail refinement: the neurons dropped may together give back at most this share of
#: what the tails gained in the sum of squared errors.
IDLE_GIVE_BACK = 0.25
#: Tail refinement: where depths come in levels, the neurons dropped may also give back
#: this share of the polished piece's sum of squared errors (most of it the camera's
#: quantization and noise, which no neuron should fit), whether tails were added or not:
#: a piece where no point needed a tail kept every idle neuron. Measured on the Kinect
#: frames with ``TAIL_SUPPORT`` (seeds 2 and 5 of desk2, 0 and 2 of desk): K 259 -> 241,
#: 252 -> 225, 316 -> 275, 309 -> 270; E-bar up by 0.00001 or less; the 99.9th
#: percentiles of the default reconstruction up by 0.00-0.04 % of the diagonal (desk
#: 0.51 and 0.48 %).
IDLE_NOISE_SHARE = 0.1
#: Tail refinement: after the drop, points above this multiple of the threshold get neurons.
REFILL_FACTOR = 1.5
#: Tail refinement of a scan of one piece: when the drop raised the mean error above the
#: polished network's (its sum of squares still below), the drops are made again within
#: these shares of the first budget, in turn, until the mean error falls.
RETRY_SHARES = (0.25, 0.0625)
#: Tail refinement: the result is kept unless its mean error exceeds the polished
#: network's by more than this fraction (the budget keeps its sum of squared errors below
#: the polished network's, but the mean error may still rise a little). Was 1.0 (a guard
#: against a numerical breakdown only). On 100 x 100 grids of one piece, z = sin(k pi x)
#: cos(k pi y) without noise, where no tail is added and the drop alone decides: k = 2
#: drops 1,370 -> 894 neurons for E-bar +0.15 %, kept from 0.01 on; k = 3 1,501 -> 1,039
#: for +1.2 %, kept from 0.05 on (the polished network, the single network's, below).
IDLE_TOLERANCE = 0.01
#: The same where depths come in levels: there the drop gives back a share of the
#: polished sum on purpose (``IDLE_NOISE_SHARE``), and the mean error may rise by it.
IDLE_TOLERANCE_LEVELS = 1.0
#: Tail refinement: points sampled for the noise scale.
_NOISE_SAMPLE = 4096
#: Tail refinement: candidates looked at per round, worst first.
_TAIL_CANDIDATES = 4096


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
                 seed: int, progress: bool | None = None,
                 loose: np.ndarray | None = None) -> PiecesLearned:
    """Learn every piece of ``segmentation`` (rows of ``hf``) with piece seeds of ``seed``.

    ``loose`` marks the rows in no scan triangle (their tails: :func:`refine_tails`).

    Each piece learns with :func:`piece_seed` of its own index and nothing of the
    others, so neither the order nor the thread changes a bit. Largest first; on two
    threads or more (and a numba threading layer that lets two Python threads launch
    parallel kernels, :func:`parallel_pieces`) two pieces learn at once: while the
    largest learns, the next ones do.
    """
    from concurrent.futures import ThreadPoolExecutor

    absres = np.empty(hf.n_points)
    polish_gain = 0.0  # sum over points of |f - z| before the polish minus after it
    order = np.argsort(segmentation.labels, kind="stable")
    bounds = np.concatenate([[0], np.cumsum(segmentation.sizes)])
    pieces: list[Piece | None] = [None] * segmentation.n_pieces
    steps, learn_s, polish_s, d_min = 0, 0.0, 0.0, float("nan")
    sizes = segmentation.sizes
    learned = ~segmentation.small & (sizes >= MIN_POINTS)
    tick = progress_bar(int(sizes[learned].sum()) * cfg.passes, progress, "learning pieces",
                        unit="step")

    quanta = depth_quanta(hf.z)  # a depth camera's levels, for the tails' threshold

    def sub_of(i: int) -> tuple[np.ndarray, HeightField]:
        idx = order[bounds[i]:bounds[i + 1]]
        return idx, HeightField(hf.xy[idx], hf.z[idx], hf.frame, hf.spacing, hf.fold)

    def one(i: int, shapes: DataShapes | None = None) -> tuple:
        # (the largest piece's points made once, for its shapes and its learning)
        idx, sub = sub_of(i) if shapes is None else (order[bounds[i]:bounds[i + 1]],
                                                     shapes.sub)
        return (idx, *_learn_piece(sub, bool(segmentation.small[i]), cfg,
                                   polish, piece_seed(seed, i), tick,
                                   None if quanta is None else quanta.at(hf.z[idx]),
                                   None if loose is None else loose[idx], shapes))

    big_first = [int(i) for i in np.argsort(-sizes, kind="stable")]
    if int(learned.sum()) >= 2 and parallel_pieces():
        from ._network_kernels import numba_threads

        main = big_first[0]
        # the largest piece's data shapes (its tails'), measured once the other pieces
        # are done, while it still learns
        shapes = DataShapes(sub_of(main)[1]) if learned[main] and polish != "none" else None

        def beside(i: int) -> tuple:
            # the other pieces learn on one numba thread (the setting is per thread):
            # their parallel kernels would take cores from the largest piece's
            if i == main:
                return one(i, shapes)
            with numba_threads(1):
                return one(i)

        with ThreadPoolExecutor(max_workers=2) as pool:
            # the piece map first, beside the largest piece; then the others. Queued after
            # them all, it ran alone at the end where many pieces share the work (a Kinect
            # frame: the pieces done at 0.26-0.30 s, then the map until 0.45-0.52 s)
            pm = pool.submit(PieceMap.of_points, hf.xy, segmentation.labels, hf.spacing)
            mapped = pool.map(beside, big_first)
            measuring = pool.submit(shapes.run) if shapes is not None else None
            results = list(mapped)
            if measuring is not None:
                shapes.take()  # (its tails took what it had: stop it, if still running)
            pm = pm.result()
    else:
        results = [one(i) for i in big_first]
        pm = PieceMap.of_points(hf.xy, segmentation.labels, hf.spacing)
    for i, (idx, piece, res, seq, learned_piece, seconds) in zip(big_first, results, strict=True):
        absres[idx] = res
        if seq is not None:
            polish_gain += seq - float(res.sum())
        if learned_piece is not None:
            steps += learned_piece.steps
            learn_s += learned_piece.seconds
            polish_s += seconds
            d_min = learned_piece.d_min
        pieces[i] = piece
    if np.isnan(d_min):  # every piece is a constant: report the rule's D_min all the same
        d_min = min(cfg.d_min if cfg.d_min is not None
                    else auto_d_min(hf.spacing, cfg.error_threshold), cfg.d_max)
    return PiecesLearned(tuple(pieces), pm, absres,  # type: ignore[arg-type]
                         float(absres.mean()) + polish_gain / hf.n_points, steps, d_min,
                         learn_s, polish_s)


def _learn_piece(sub: HeightField, small: bool, cfg: FitConfig, polish: str, seed: int,
                 tick: Any, quantum: np.ndarray | None = None,
                 loose: np.ndarray | None = None, shapes: DataShapes | None = None) -> tuple:
    """Learn, polish and refine one piece (``shapes``: its tails', :func:`refine_tails`).

    Returns ``(piece, |f - z| per point, |f - z| summed before the polish, learning
    result, polish seconds)``. A small piece (or one too small to learn) gets
    :func:`small_piece`; then the sum and the learning result are None.
    """
    info: dict[str, Any] = {"n_points": sub.n_points, "seed": seed}
    seq, learned, seconds = None, None, 0.0
    if small or sub.n_points < MIN_POINTS:
        piece = small_piece(sub, cfg, info, constant=polish == "none")
    else:
        learned, pr, params, seconds = learn_polished(
            sub, cfg, polish, seed=seed, progress=False,
            prune_below=TAIL_PRUNE * cfg.error_threshold, keep_residual=polish != "none")
        if polish != "none":
            tr = time.perf_counter()
            params, info["tail_neurons"] = refine_tails(sub, cfg, *params, learned.d_min, pr,
                                                        quantum, loose=loose, shapes=shapes)
            info["weak_pruned"] = len(learned.widths) + info["tail_neurons"] - len(params[2])
            seconds += time.perf_counter() - tr
        piece = Piece(*params, learned.log, info)
        seq = None if pr is None else pr.ebar_before * sub.n_points
        if tick:
            tick(learned.steps)
    res = np.abs(sub.z - piece.eval_unit(sub.xy, cfg.support)[0])
    piece.info["ebar"] = float(res.mean())
    return piece, res, seq, learned, seconds


def parallel_pieces() -> bool:
    """Whether pieces may learn on two threads at once.

    When numba runs on two threads or more (a batch worker pinned to one does not) and
    its threading layer is OpenMP or TBB: those let several Python threads launch
    parallel kernels at once; the workqueue layer does not (it aborts the process). A
    forked child launches none (:func:`~asrbf_mesh._network_kernels._forked`): yes.
    """
    import numba

    from . import _network_kernels as _nk

    if numba.get_num_threads() < 2:
        return False
    if _nk._forked():
        return True
    try:
        layer = numba.threading_layer()
    except ValueError:  # no parallel kernel has run yet: run one
        _nk.warm_threads()
        layer = numba.threading_layer()
    return layer in ("omp", "tbb")


def small_piece(sub: HeightField, cfg: FitConfig, info: dict[str, Any], *,
                constant: bool = False) -> Piece:
    """Fit a fragment too small to learn: up to three wide neurons, as few as fit, or a constant.

    The candidate neurons sit on the three mutually farthest points (the first point,
    the point farthest from it, the point farthest from both), each as wide as the
    diagonal of the fragment's bounding box. One neuron, then two, then three are
    tried (each choice of the candidates; a0 and the weights by least squares,
    ridge-regularized toward the constant mean as the weight polish is), and the first
    count whose best choice fits every point within E is taken (the growth criterion of
    learning: a point within E asks for no neuron), else the best of three. A fit is
    kept only when it lowers the fragment's mean error: one point, or points on a line
    where least squares cannot tell a slope, and fragments the constant already fits
    within E stay the constant mean. As few neurons as fit (:data:`SMALL_NEURONS`):
    one neuron, a ramp across the fragment, fits most fragments of a grazing flank.
    """
    xy, z = sub.xy, sub.z
    mean = float(z.mean())
    const = Piece(mean, np.zeros((0, 2)), np.zeros(0), np.zeros(0), None,
                  {**info, "constant": True})
    cap = SMALL_NEURONS if cfg.max_neurons is None else min(SMALL_NEURONS, cfg.max_neurons)
    if (constant or sub.n_points < 3 or np.abs(z - mean).max() <= cfg.error_threshold
            or cap < 1):
        return const
    picks = [0]
    dist = np.linalg.norm(xy - xy[0], axis=1)
    for _ in range(2):
        picks.append(int(np.argmax(dist)))
        dist = np.minimum(dist, np.linalg.norm(xy - xy[picks[-1]], axis=1))
    width = float(np.linalg.norm(np.ptp(xy, axis=0)))  # the fragment's extent, in O(n)
    if len(np.unique(picks)) < 3 or not width > 0:
        return const
    centres = xy[picks]
    d2 = ((xy[:, None, :] - centres[None, :, :]) ** 2).sum(axis=2)
    # the network's basis, truncated as its evaluation is (a fragment lies within one width):
    # the columns of the weight polish's design matrix (:func:`~asrbf_mesh._polish.design_matrix`),
    # made here in numpy: 12 us for a fragment of 20 points, through its grid 101 us
    cols = np.where(d2 <= (cfg.support * width) ** 2, np.exp(-d2 / width ** 2), 0.0)
    best: tuple[float, tuple[int, ...], np.ndarray] | None = None
    floor = float(np.abs(z - mean).mean())
    for k in range(1, cap + 1):
        fits = [_small_fit(cols[:, list(s)], z, mean, cfg.polish_ridge) + (s,)
                for s in combinations(range(3), k)]
        fits = [f for f in fits if np.isfinite(f[0])]
        if not fits:
            continue
        err, worst, w, s = min(fits, key=lambda f: f[0])
        if err < floor and (best is None or err < best[0]):
            best = (err, s, w)
            if worst <= SMALL_FIT * cfg.error_threshold:
                break
    if best is None:
        return const
    _, s, w = best
    sel = list(s)
    return Piece(float(w[0]), centres[sel], np.full(len(sel), width), w[1:], None,
                 {**info, "constant": False})


#: :func:`small_piece`: the most neurons a fragment gets.
SMALL_NEURONS = 3
#: :func:`small_piece`: fewer neurons do when they fit every point within this multiple of
#: E. Views of a loop-subdivided cube (74-128 fragments each; they motivated the rule),
#: seeds 0-9: 0.6 (the tails' threshold) and 0.3 left K's medians 2-8 % higher, E-bar the
#: same to 0.00001, and fewer K with a lower E-bar than the single network on 10 and 11
#: of the 30 fits against 12 at 1.0.
SMALL_FIT = 1.0


def _small_fit(cols: np.ndarray, z: np.ndarray, mean: float,
               ridge: float) -> tuple[float, float, np.ndarray]:
    """Least-squares ``(a0, a_k)`` over basis columns ``cols``: (mean |error|, max, w).

    Minimizes ``||A w - z||^2 + lam ||w - (mean, 0, ..)||^2``, ``A = [1, cols]``, ``lam =
    ridge * mean(diag(A'A))`` (:func:`~asrbf_mesh._polish._ridged`), as the weight polish
    does (:func:`~asrbf_mesh._polish.polish_weights`); NaN errors for a singular system.
    """
    a = np.column_stack([np.ones(len(z)), cols])
    w0 = np.zeros(a.shape[1])
    w0[0] = mean
    try:
        w = w0 + np.linalg.solve(_ridged(a.T @ a, ridge), a.T @ (z - a @ w0))
    except np.linalg.LinAlgError:
        return np.nan, np.nan, w0
    if not np.all(np.isfinite(w)):
        return np.nan, np.nan, w0
    r = np.abs(z - a @ w)
    return float(r.mean()), float(r.max()), w


def refine_tails(sub: HeightField, cfg: FitConfig, a0: float, centers: np.ndarray,
                 widths: np.ndarray, weights: np.ndarray, d_min: float,
                 polished: Any = None, quantum: np.ndarray | None = None, *,
                 no_more: bool = False, loose: np.ndarray | None = None,
                 shapes: DataShapes | None = None
                 ) -> tuple[tuple[float, np.ndarray, np.ndarray, np.ndarray], int]:
    """Add neurons where a polished piece still misses its points; (parameters, added).

    Each round takes the points whose error across the surface (the depth error times
    the cosine of the slope, in physical proportions; at the piece's border where the
    perpendicular onto the surface would land past it, the whole depth error, unless
    the point is ``loose``, in no scan triangle: :func:`~asrbf_mesh._tail_shapes.across`)
    exceeds ``max(TAIL_FACTOR E, TAIL_NOISE x 1.4826 MAD)`` (MAD over a sample of the
    points: the piece's noise), and where the depths come in levels, ``TAIL_QUANTA`` x
    ``quantum`` (the depth quantum at each point,
    :func:`~asrbf_mesh._segment.depth_quanta`), worst first and
    no two closer than D_min (with levels, or where the first round's misses are many,
    lone and small (:data:`NOISY_MIN_POINTS`), only points where ``TAIL_SUPPORT`` of the 8 nearest
    miss on the same side too: :func:`_supported`); each becomes
    a neuron ``u = x, sigma = max(psi ||x - u_near||, D_min / 2)`` (the growth rule of
    learning; for a point past its border ``u`` half ``sigma`` further out) whose
    weight is solved by least squares over the points under it, the other neurons
    fixed (one global solve costs as much as the polish; these cost a fraction). Each
    round extends the weight polish's normal equations (``polished``, its
    :class:`~asrbf_mesh._polish.PolishResult`) by the new neurons' columns, over the
    points under them (:func:`~asrbf_mesh._polish.extend_normal`), and takes that solve
    from them (:func:`_appended_weights`). Stops when no point is left above the
    threshold, after ``TAIL_ROUNDS`` or at the neuron cap (``max_neurons``).

    Then all the weights are solved together once, from those extended normal
    equations, and the neurons
    the network hardly needs are dropped one at a time, the cheapest first, while a
    removal raises the sum of squared errors by less than ``IDLE_RSS`` x E^2 (twelve
    points off by E) and the removals together give back at most ``IDLE_GIVE_BACK`` of
    what the new neurons gained (:func:`~asrbf_mesh._polish.solve_and_drop`), and where
    depths come in levels, ``IDLE_NOISE_SHARE`` of the polished sum besides. When
    neurons were dropped, one last round (its weights local) takes the points left
    above ``REFILL_FACTOR`` x the threshold. The result is kept unless its mean error
    exceeds the polished network's by more than ``IDLE_TOLERANCE`` (with levels,
    ``IDLE_TOLERANCE_LEVELS``). After the full polish (no normal equations) a weight
    polish solves them and :func:`~asrbf_mesh._polish.drop_idle` drops. A piece whose
    weight polish had too many neurons for dense normal equations
    (:data:`~asrbf_mesh._polish.DENSE_MAX`) is kept as polished, with no tails: a second
    sparse solve would cost as much as the polish, and no piece's tails grow it to that
    many; but a scan of one piece (``no_more``) gets its tails, solved and dropped strip
    by strip from the sparse equations (``solve_and_drop(strips=True)``): on the SRTM
    tile (138,632 points), seeds 0-2, the single network's K 6,552, 6,578, 6,546 and E-bar
    0.0085 became 6,523, 6,563, 6,520 and 0.0073, in 1.09-1.13x its time.

    With ``no_more`` (a scan of one piece) the tails must pay for themselves: when the
    drop leaves as many neurons as the polished network had, a second drop takes the
    cheapest whatever each costs, within ``NET_GIVE_BACK`` of the tails' gain, until one
    fewer is left; the last round stays under that count, and the result is kept only
    with fewer neurons and (without depth levels) a lower mean error than the polished
    network, which is returned otherwise; a drop that raised the mean error is first made
    again within smaller shares of its budgets (:data:`RETRY_SHARES`).

    ``shapes``: a :class:`DataShapes` of ``sub`` running beside the learning: the shapes it
    measured are taken, the rest measured point by point as the rounds need them.
    """
    from scipy.spatial import cKDTree

    # too many neurons for dense normal equations (the polish solved sparse ones by
    # conjugate gradients): a second such solve for the tails, with no drop after it,
    # took an SRTM tile (138,632 points, 6,552 neurons) to 2.3x the single fit's time
    # and 8,373 neurons. A piece of several keeps its polished network; a scan of one
    # piece solves and drops strip by strip from the sparse equations (below)
    sparse = polished is not None and polished.ata is not None \
        and not isinstance(polished.ata, np.ndarray)
    if sparse and not no_more:
        return (a0, centers, widths, weights), 0
    scale = np.asarray(sub.frame.scale, dtype=np.float64)
    grid, shape = None, None
    limit: float | np.ndarray = 0.0
    supported = quantum is not None  # a tail needs neighbours that miss too (below)
    # the normal equations of the neurons so far, while they are the polish's extended
    # (dense); the new neurons' weights come from them (:func:`_appended_weights`)
    normal = GrownNormal(polished.ata, polished.atz) if polished is not None \
        and isinstance(polished.ata, np.ndarray) \
        and polished.ata.shape[0] == len(widths) + 1 else None
    k_entry = len(widths)
    if no_more and normal is None and not sparse:  # no drop: more neurons, never fewer
        return (a0, centers, widths, weights), 0
    room: int | None = None  # at most this many neurons after a round (the refill's)

    def one_round(a0, centers, widths, weights, factor=1.0, res=None):
        """Neurons for the worst points: (centers, widths, weights, how many added).

        ``res`` is ``z - f`` of this network when known (measured by the solve before).
        """
        nonlocal grid, shape, limit, normal, supported
        piece = Piece(a0, centers, widths, weights)
        if res is None:
            res = sub.z - piece.eval_unit(sub.xy, cfg.support)[0]
        first = grid is None
        if first:  # the first round: the piece's noise scale, once
            got = shapes.take() if shapes is not None else None
            if got is not None:
                grid, shape = got
            else:
                grid, shape = point_grid(sub.xy), np.full((sub.n_points, 3), np.nan)
            sample = np.arange(0, len(res), max(1, len(res) // _NOISE_SAMPLE))
            floor = TAIL_FACTOR * cfg.error_threshold
            if quantum is not None:
                floor = max(floor, TAIL_QUANTA * float(quantum.min()))
            # the MAD of nonnegative errors is at most their upper median, and the error
            # across is at most the depth error: when even the depth errors' upper
            # median cannot raise the threshold, the errors across are not measured
            upper = float(np.partition(np.abs(res[sample]), len(sample) // 2)[len(sample) // 2])
            mad = 0.0
            if TAIL_NOISE * 1.4826 * upper > floor:
                some = across(piece, sub, res, sample, scale, cfg.support, grid, shape,
                               loose)
                mad = float(np.median(np.abs(some - np.median(some))))
            limit = max(TAIL_FACTOR * cfg.error_threshold, TAIL_NOISE * 1.4826 * mad)
            if quantum is not None:
                limit = np.maximum(limit, TAIL_QUANTA * quantum)
        above = factor * limit
        worst = np.flatnonzero(np.abs(res) > above)  # the error across is at most |res|
        off = across(piece, sub, res, worst, scale, cfg.support, grid, shape, loose)
        keep = off > (above[worst] if isinstance(above, np.ndarray) else above)
        worst, off = worst[keep], off[keep]
        if supported and len(worst):
            keep = _supported(sub.xy, res, worst, above, grid)
            worst, off = worst[keep], off[keep]
        elif first and sub.n_points >= NOISY_MIN_POINTS and quantum is None \
                and len(worst) > NOISY_MISSES * sub.n_points:
            # many misses, mostly lone and near the threshold: the piece's noise, not
            # features it lacks
            keep = _supported(sub.xy, res, worst, above, grid)
            share = float(keep.mean())
            if share < NOISY_LONE or (share < NOISY_SUPPORT and np.percentile(off, 90)
                                      < NOISY_SPREAD * float(np.max(above))):
                supported = True
                worst, off = worst[keep], off[keep]
        worst = worst[np.argsort(-off, kind="stable")][:_TAIL_CANDIDATES]
        picked = worst[spread(sub.xy[worst], d_min)]
        if cfg.max_neurons is not None:  # the neuron cap holds here too
            picked = picked[:max(cfg.max_neurons - len(widths), 0)]
        if normal is not None:  # dense normal equations for the drop (below) to use
            picked = picked[:max(DENSE_MAX - 2 - len(widths), 0)]
        if room is not None:
            picked = picked[:max(room - len(widths), 0)]
        if len(picked) == 0:
            return centers, widths, weights, 0
        new = sub.xy[picked]
        near = np.linalg.norm(new - centers[cKDTree(centers).query(new)[1]], axis=1)
        sigma = np.maximum(cfg.psi * near, 0.5 * d_min)
        # a neuron for a point past its border stands half its width further out: its
        # flank, not its peak, follows the surface turning away there
        past = past_border(piece.eval_unit(new, cfg.support, True)[1], res[picked],
                            shape[picked, 1:], scale, None if loose is None else loose[picked])
        if past.any():
            out = shape[picked[past], 1:] / scale[:2]
            new = new.copy()
            new[past] += (0.5 * sigma[past] / np.linalg.norm(out, axis=1))[:, None] * out
        grown_c, grown_w = np.vstack([centers, new]), np.r_[widths, sigma]
        if normal is not None and factor == 1.0:
            # the new rows of the normal equations, over the points under the new
            # neurons: the last solve needs them, and they hold the local solve's
            rows, atz = appended_rows(sub.xy, sub.z, grown_c, grown_w,
                                      np.r_[weights, np.zeros(len(sigma))], cfg.support,
                                      len(widths))
            normal.append(rows, atz)
            a_new = _appended_weights(rows, atz, a0, weights, cfg.polish_ridge)
        else:
            a_new = _local_weights(sub.xy, res, new, sigma, cfg)
        return grown_c, grown_w, np.r_[weights, a_new], len(picked)

    tolerance = IDLE_TOLERANCE if quantum is None else IDLE_TOLERANCE_LEVELS
    added = 0
    # the polish measured its network's residual: the first round starts from it
    res = polished.residual if polished is not None and polished.weights is weights else None
    for _ in range(TAIL_ROUNDS):
        if len(widths) == 0:
            break
        centers, widths, weights, n = one_round(a0, centers, widths, weights, res=res)
        res = None
        if n == 0:
            break
        added += n
    idle = IDLE_RSS * cfg.error_threshold ** 2
    if normal is not None or sparse:
        # the polish's normal equations extended by the new neurons' columns, solved,
        # and the neurons the network hardly needs dropped, from one dense inverse (or
        # strip by strip)
        base = np.concatenate([[polished.a0], polished.weights, np.zeros(added)])
        kept = (polished.a0, polished.centers, polished.widths, polished.weights), 0
        extra = _noise_budget(polished, quantum)
        if no_more and added == 0 and extra == 0.0:
            # no tail and no noise to give back: the drop's budget is a quarter of what
            # solving the polished weights again gains (next to nothing), and what it
            # drops would have to lower E-bar: the solve (a tenth of a one-piece fit)
            # would return the polished network
            return kept
        ata, atz = (normal.matrix(), normal.atz) if normal is not None else extend_normal(
            sub.xy, sub.z, polished, centers, widths, weights, cfg.support)
        args = (sub.xy, sub.z, ata, atz, a0, centers, widths, weights, cfg.support,
                cfg.polish_ridge, idle)
        memo: dict = {}  # the drops after the first take its solve

        def drop(share: float):
            """Drop within ``share`` of the budgets, then refill: (parameters, added).

            Or "unsolved" (no drop could be made), "kept" (too few dropped: a smaller
            drop cannot pay either), None (the mean error rose).
            """
            nonlocal room
            got = solve_and_drop(*args, base=base, give_back=IDLE_GIVE_BACK * share,
                                 extra=extra, memo=memo, strips=True)
            if no_more and added and got is not None and len(got[0].widths) >= k_entry:
                # the idle neurons did not pay for the tails: the cheapest go until they have
                got = solve_and_drop(*args, base=base, give_back=NET_GIVE_BACK * share,
                                     extra=extra, at_least=len(widths) - k_entry + 1,
                                     memo=memo, strips=True)
            if got is None:
                return "unsolved"
            pr, dropped = got
            if added + dropped == 0 or no_more and len(pr.widths) >= k_entry:
                return "kept"  # nothing changed, or the tails did not pay
            if pr.ebar_after > polished.ebar_after * (1.0 + tolerance):
                return None
            out, n = (pr.a0, pr.centers, pr.widths, pr.weights), 0
            if dropped and len(pr.widths) and TAIL_ROUNDS:
                # a last round for the points the dropped neurons left above the threshold
                room = k_entry - 1 if no_more else None
                c, w, a, n = one_round(pr.a0, pr.centers, pr.widths, pr.weights,
                                       REFILL_FACTOR, pr.residual)
                out = (pr.a0, c, w, a)
            # (where depths come in levels the drop gives back noise on purpose: as above)
            if no_more and quantum is None and np.abs(
                    sub.z - Piece(*out).eval_unit(sub.xy, cfg.support)[0]
            ).mean() >= polished.ebar_after:
                return None
            return out, added + n

        # a scan of one piece whose drop raised the mean error (its sum of squares falls,
        # the mean of |error| may rise): the drop again within smaller shares of its
        # budget, fewer and cheaper neurons, until one pays (:data:`RETRY_SHARES`)
        for share in (1.0, *RETRY_SHARES) if no_more else (1.0,):
            made = drop(share)
            if made == "unsolved" and share == 1.0:
                break  # (below)
            if made is None:
                continue
            return kept if isinstance(made, str) else made
        else:
            return kept  # the polished network was better
        if added == 0:
            return (a0, centers, widths, weights), 0
        pr = extend_and_solve(sub.xy, sub.z, polished, a0, centers, widths, weights,
                              cfg.support, cfg.polish_ridge)
    elif added == 0:
        return (a0, centers, widths, weights), 0
    elif polished is not None and polished.ata is not None \
            and polished.ata.shape[0] == len(widths) - added + 1:
        pr = extend_and_solve(sub.xy, sub.z, polished, a0, centers, widths, weights,
                              cfg.support, cfg.polish_ridge)
    else:
        pr = polish_weights(sub.xy, sub.z, a0, centers, widths, weights, cfg.support,
                            cfg.polish_ridge)
    pr, _ = drop_idle(sub.xy, sub.z, pr, cfg.support, cfg.polish_ridge, idle,
                      tolerance=tolerance)
    return (pr.a0, pr.centers, pr.widths, pr.weights), added


def _appended_weights(rows: np.ndarray, atz: np.ndarray, a0: float, weights: np.ndarray,
                      ridge: float) -> np.ndarray:
    """Least-squares weights of the neurons appended after ``weights``, the others fixed.

    From the appended neurons' rows of the extended normal equations (``rows``: columns
    ``[a0, weights, appended]``; ``atz``: theirs, :func:`~asrbf_mesh._polish.appended_rows`):
    the appended block ``B = A_n'A_n`` and ``A_n'r = A_n'z - A_n'A_o (a0, weights)``,
    ``r`` the residual under the old neurons; ridged as the polish. The same solution as
    :func:`_local_weights` on that residual, without a pass over the points.
    """
    from ._polish import _ridged, _solve_spd

    k = len(weights) + 1
    rhs = atz - rows[:, :k] @ np.concatenate([[a0], weights])
    a = _solve_spd(_ridged(np.ascontiguousarray(rows[:, k:]), ridge), rhs)
    return np.where(np.isfinite(a), a, 0.0)


def _local_weights(xy: np.ndarray, res: np.ndarray, centers: np.ndarray, sigma: np.ndarray,
                   cfg: FitConfig) -> np.ndarray:
    """Least-squares weights of new neurons for the residual under them (ridge as the polish)."""
    from ._polish import _normal_under, _ridged, _solve_spd, rows_under

    rows = rows_under(xy, centers, sigma, cfg.support)
    if len(rows) == 0:
        return np.zeros(len(sigma))
    normal = _normal_under(xy, res, rows, centers, sigma, np.ones(len(sigma)), cfg.support,
                           1)  # the new neurons' columns, no bias
    ata = normal.matrix()[1:, 1:]
    a = _solve_spd(_ridged(ata, cfg.polish_ridge), normal.atr[1:])
    return np.where(np.isfinite(a), a, 0.0)


def _noise_budget(polished: Any, quantum: np.ndarray | None) -> float:
    """Return what the idle neurons' drop may give back besides the tails' share.

    ``IDLE_NOISE_SHARE`` of the polished piece's sum of squared errors where depths come
    in levels (``quantum`` given), else 0.
    """
    if quantum is None or polished.residual is None:
        return 0.0
    return IDLE_NOISE_SHARE * float(polished.residual @ polished.residual)


def _supported(xy: np.ndarray, res: np.ndarray, at: np.ndarray,
               above: float | np.ndarray, grid: tuple) -> np.ndarray:
    """Whether at least ``TAIL_SUPPORT`` of each point's 8 nearest miss on its side too."""
    from ._grid_knn import knn

    k = min(9, len(xy))
    _, nb = knn(xy, at, k, grid)
    lim = above[nb] if isinstance(above, np.ndarray) else above
    side = res[nb] * np.sign(res[at])[:, None]
    return (side > lim).sum(axis=1) - 1 >= TAIL_SUPPORT
