"""Batch polish of a sequentially learned network (beyond the paper).

Sequential learning places neurons well but does not minimize the error of its own network: each
observation corrects one neuron once. With the structure fixed, two batch stages finish the job:

* ``weights``: a0 and every a_k by sparse linear least squares (centres and widths
  fixed; truncated Gaussians make the design matrix sparse);
* ``full``: then damped Gauss-Newton (Levenberg-Marquardt) iterations over all
  parameters (a, log sigma, u) with a sparse Jacobian.

Both add a Tikhonov term pulling the parameters toward the learned ones (``ridge``),
which keeps neurons with little or no data under them -- at borders and over holes --
where learning left them instead of letting them explode.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass, replace

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import cg, spsolve

from . import _network_kernels as _nk
from ._blas import one_blas_thread
from ._piece import _read_only, eval_grid, eval_unit

__all__ = ["PolishResult", "polish_weights", "polish_weights_blocks", "polish_full",
           "design_matrix", "extend_and_solve", "extend_normal", "appended_rows", "GrownNormal",
           "solve_and_drop", "drop_idle"]

_SIGMA_RANGE = (1e-5, 2.0)
_CENTRE_BOX = (-0.25, 1.25)
_CG_ITERATIONS = 300
_RIDGE_FLOOR = 1e-10  # keeps the normal equations regular when a neuron has no data under it
_CHUNK = 1 << 13  # points per block of the weight polish's normal equations
_DIRECT_MAX = 4096  # unknowns up to which the weight polish factorizes (see _solve_spd)


@dataclass(frozen=True)
class PolishResult:
    """Polished parameters (unit cube) and the mean absolute error before and after.

    The weight polish also keeps its normal equations (``ata`` = A'A, a dense array up
    to :data:`DENSE_MAX` columns, else CSR, and ``atz`` = A'z over the columns
    ``[a0, a_1 .. a_K]``, without the ridge), so that neurons can be added later at the
    cost of the rows under them only (:func:`extend_and_solve`).
    """

    a0: float
    centers: np.ndarray
    widths: np.ndarray
    weights: np.ndarray
    ebar_before: float
    ebar_after: float
    iterations: int
    ata: np.ndarray | sp.csr_matrix | None = None
    atz: np.ndarray | None = None
    #: ``z - f`` at the points for the returned weights, when it was measured over
    #: points held in memory and asked for (``polish_weights(keep_residual=True)``,
    #: :func:`solve_and_drop`): the tail refinement starts from it
    residual: np.ndarray | None = None


def design_matrix(xy: np.ndarray, centers: np.ndarray, widths: np.ndarray,
                  weights: np.ndarray, support: float, *, full: bool = False) -> sp.csr_matrix:
    """Sparse Jacobian of the network output at (N, 2) unit-square points.

    Column 0 is the bias a0; then one column per weight (``full=False``) or four per
    neuron, ``(a, log sigma, ux, uy)`` (``full=True``).

    Examples
    --------
    >>> A = design_matrix(np.array([[0.5, 0.5], [0.9, 0.9]]), np.array([[0.5, 0.5]]),
    ...                   np.array([0.1]), np.array([1.0]), 3.5)
    >>> A.toarray().round(4).tolist()
    [[1.0, 1.0], [1.0, 0.0]]
    """
    grid = eval_grid(centers, widths, weights, support)
    indptr, cols, vals = _design_rows(grid, xy, centers, widths, weights, full)
    ncol = 1 + (4 if full else 1) * len(widths)
    return sp.csr_matrix((vals, cols, indptr), shape=(len(indptr) - 1, ncol))


def _design_rows(grid: tuple, xy: np.ndarray, centers: np.ndarray, widths: np.ndarray,
                 weights: np.ndarray, full: bool = False) -> tuple:
    """Return the design matrix's CSR arrays ``(indptr, cols, vals)`` through a grid."""
    support, lo, h, g, start, items, _, _ = grid
    pts = np.ascontiguousarray(xy, dtype=np.float64)
    return _nk.design_rows(pts, centers, widths, weights, support, lo, h, g, start, items,
                           full)


#: Normal equations of up to this many unknowns are summed into a dense matrix by a
#: compiled kernel (32 MB at most); above, scipy's sparse products sum them.
DENSE_MAX = 2049


class _Normal:
    """Normal equations ``A'A``, ``A'(z - A w0)`` summed over blocks of design rows.

    Dense up to :data:`DENSE_MAX` unknowns (:func:`~asrbf_mesh._network_kernels.gram_rows`:
    each row's outer product, no sparse product), sparse above. ``first``: only the
    entries in a column ``>= first`` (the columns of appended neurons).
    """

    def __init__(self, k1: int, w0: np.ndarray, first: int = 0):
        self.k1, self.w0, self.first = k1, np.ascontiguousarray(w0, np.float64), first
        self.dense = np.zeros((k1, k1)) if k1 <= DENSE_MAX else None
        self.sparse = None if self.dense is not None else sp.csr_matrix((k1, k1))
        self.mirrored = False
        self.atr = np.zeros(k1)
        self.abs_sum = 0.0
        # appended columns: their rows of A'A, summed in two halves (two threads) by
        # _normal_under's kernel
        self.parts = (np.zeros((2, k1 - first, k1)), np.zeros((2, k1))) \
            if first and self.dense is not None else None

    def add(self, rows: tuple, z: np.ndarray) -> None:
        indptr, cols, vals = rows
        z = np.ascontiguousarray(z, np.float64)
        if self.dense is not None:
            assert not self.mirrored and self.parts is None, \
                "rows added after matrix(), or to appended columns (gram_new_under sums those)"
            self.abs_sum += _nk.gram_rows(indptr, cols, vals, z, self.w0, self.dense, self.atr)
            return
        A = sp.csr_matrix((vals, cols, indptr), shape=(len(indptr) - 1, self.k1))
        r = z - A @ self.w0
        self.abs_sum += float(np.abs(r).sum())
        f = self.first
        if f:  # only the new columns' rows of A'A, mirrored: not the old block's product
            At = A[:, f:].T.tocsr()
            got = (At @ A).tocoo()  # rows f.., every column
            old = got.col < f
            ata = sp.coo_matrix((np.r_[got.data, got.data[old]],
                                 (np.r_[got.row + f, got.col[old]],
                                  np.r_[got.col, got.row[old] + f])), shape=(self.k1,) * 2)
            atr = np.r_[np.zeros(f), At @ r]
        else:
            At = A.T.tocsr()
            ata, atr = (At @ A).tocoo(), At @ r
        self.sparse = self.sparse + ata.tocsr()
        self.atr += atr

    def matrix(self) -> np.ndarray | sp.csr_matrix:
        """``A'A``, symmetric: a dense array up to :data:`DENSE_MAX` unknowns, else CSR.

        Call it before reading ``atr``: it also adds the halves of the appended columns.
        """
        if self.dense is None:
            return self.sparse.tocsr()
        if not self.mirrored:
            f = self.first
            if f:  # the kernel filled the rows >= first, in two halves
                rows, atr = self.parts
                self.dense[f:] = rows[0] + rows[1]
                self.atr += atr[0] + atr[1]
                self.dense[:f, f:] = self.dense[f:, :f].T
            else:  # the kernel filled the upper triangle
                self.dense += np.triu(self.dense, 1).T
            self.mirrored = True
        return self.dense


def _normal_under(xy: np.ndarray, z: np.ndarray, rows: np.ndarray, centers: np.ndarray,
                  widths: np.ndarray, weights: np.ndarray, support: float,
                  first: int) -> _Normal:
    """``A'A`` and ``A'z`` over the points ``rows``, entries in a column ``>= first`` only."""
    grid = eval_grid(centers, widths, weights, support)
    normal = _Normal(len(widths) + 1, np.zeros(len(widths) + 1), first=first)  # A'z
    if normal.parts is not None:  # appended columns, dense: no design rows stored
        normal.abs_sum = _nk.gram_new_under(
            np.ascontiguousarray(xy, np.float64), np.ascontiguousarray(z, np.float64),
            np.ascontiguousarray(rows, np.int64), *grid, first, *normal.parts)
        return normal
    for sl in _chunks(len(rows)):
        normal.add(_design_rows(grid, xy[rows[sl]], centers, widths, weights), z[rows[sl]])
    return normal


def _predict(xy, a0, centers, widths, weights, support) -> np.ndarray:
    grid = eval_grid(centers, widths, weights, support)
    return eval_unit(grid, xy, a0, centers, widths, weights)[0]


def polish_weights(xy: np.ndarray, z: np.ndarray, a0: float, centers: np.ndarray,
                   widths: np.ndarray, weights: np.ndarray, support: float,
                   ridge: float = 1e-4, *, keep_residual: bool = False) -> PolishResult:
    """Least-squares weights (a0, a_k) with centres and widths fixed.

    Minimizes ``||A w - z||^2 + lam ||w - w_learned||^2`` with
    ``lam = ridge * mean(diag(A'A))``.

    Parameters
    ----------
    xy : (N, 2) float64 array
        Unit-square inputs.
    z : (N,) float64 array
        Unit depths.
    a0, centers, widths, weights
        The learned network (unit cube).
    support : float
        Truncation radius in widths.
    ridge : float
        Relative Tikhonov weight.
    keep_residual : bool
        Keep ``z - f`` of the polished network (its ``residual``; N floats), measured on
        the way to its mean error.

    Returns
    -------
    PolishResult
    """
    return polish_weights_blocks(lambda: ((xy[sl], z[sl]) for sl in _chunks(len(z))), len(z),
                                 a0, centers, widths, weights, support, ridge,
                                 keep_residual=keep_residual)


def polish_weights_blocks(blocks: Callable[[], Iterable[tuple[np.ndarray, np.ndarray]]],
                          n: int, a0: float, centers: np.ndarray, widths: np.ndarray,
                          weights: np.ndarray, support: float,
                          ridge: float = 1e-4, *, keep_residual: bool = False) -> PolishResult:
    """:func:`polish_weights` over points fed in blocks, in two passes over them.

    Parameters
    ----------
    blocks : callable
        ``blocks()`` returns a fresh iterable of ``(xy, z)`` blocks (unit square, unit
        depth) covering the ``n`` points in one fixed order; it is called twice (the
        normal equations, then the error after the solve). Blocks are cut further into
        :data:`_CHUNK` rows; blocks whose sizes are multiples of it sum in the same
        order as :func:`polish_weights` on the whole arrays, so the result is the same
        bit for bit.
    n : int
        Number of points.
    a0, centers, widths, weights, support, ridge, keep_residual
        As :func:`polish_weights` (a kept residual takes N floats: not for streams).
    """
    w0 = np.concatenate([[a0], weights])
    # the normal equations are summed over chunks of points: memory O(K + chunk), never
    # the whole (N, K) design matrix (16 bytes per point and neuron over it)
    grid = eval_grid(centers, widths, weights, support)
    normal = _Normal(len(w0), w0)
    for xy_b, z_b in blocks():
        for sl in _chunks(len(z_b)):
            normal.add(_design_rows(grid, xy_b[sl], centers, widths, weights), z_b[sl])
    before = normal.abs_sum / n
    ata, atr = normal.matrix(), normal.atr
    # solve for the change: (A'A + lam) dw = A'(z - A w0)
    dw = _solve_spd(_ridged(ata, ridge), atr)
    w = w0 + dw
    atz = atr + ata @ w0
    if not np.all(np.isfinite(w)):
        return PolishResult(a0, centers, widths, weights, before, before, 0, ata, atz)
    after = 0.0
    kept = []
    grid = eval_grid(centers, widths, w[1:], support)  # (the grid packs the weights)
    for xy_b, z_b in blocks():
        for sl in _chunks(len(z_b)):
            r = z_b[sl] - eval_unit(grid, xy_b[sl], w[0], centers, widths, w[1:])[0]
            after += float(np.abs(r).sum())
            if keep_residual:
                kept.append(r)
    after /= n
    if after > before:
        return PolishResult(a0, centers, widths, weights, before, before, 0, ata, atz)
    return PolishResult(float(w[0]), centers, widths, w[1:].copy(), before, after, 1, ata,
                        atz, np.concatenate(kept) if keep_residual else None)


def extend_normal(xy: np.ndarray, z: np.ndarray, pr: PolishResult, centers: np.ndarray,
                  widths: np.ndarray, weights: np.ndarray, support: float
                  ) -> tuple[np.ndarray | sp.csr_matrix, np.ndarray]:
    """``pr``'s normal equations ``(A'A, A'z)`` extended by neurons appended to its own.

    ``centers``, ``widths`` and ``weights`` are ``pr``'s neurons followed by the new
    ones. The new columns are summed over the points under the new neurons only (the
    other rows are zero there), so the cost is local.
    """
    if pr.ata is None or pr.atz is None:
        raise ValueError("extending needs the normal equations of a weight polish")
    k_old = pr.ata.shape[0] - 1
    m = len(widths) - k_old
    if m <= 0:
        return pr.ata, pr.atz
    if isinstance(pr.ata, np.ndarray) and len(widths) + 1 <= DENSE_MAX:
        grown = GrownNormal(pr.ata, pr.atz)
        grown.append(*appended_rows(xy, z, centers, widths, weights, support, k_old))
        return grown.matrix(), grown.atz
    rows = rows_under(xy, centers[k_old:], widths[k_old:], support)
    normal = _normal_under(xy, z, rows, centers, widths, weights, support, 1 + k_old)
    ata = normal.matrix()
    if isinstance(ata, np.ndarray):
        ata[:1 + k_old, :1 + k_old] += _dense(pr.ata)
    else:
        old = sp.csr_matrix(pr.ata)  # padded with the new (empty) rows and columns
        old = sp.csr_matrix((old.data, old.indices,
                             np.r_[old.indptr, np.full(m, old.indptr[-1])]),
                            shape=(len(widths) + 1,) * 2)
        ata = (old + ata).tocsr()
    return ata, np.concatenate([pr.atz, normal.atr[1 + k_old:]])


def appended_rows(xy: np.ndarray, z: np.ndarray, centers: np.ndarray, widths: np.ndarray,
                  weights: np.ndarray, support: float, k_old: int
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Rows of ``(A'A, A'z)`` for the neurons after the first ``k_old`` (dense, no bias row).

    ``(m, K + 1)`` and ``(m,)`` for the ``m`` appended neurons, over the points under
    them: what :func:`extend_normal` adds to the normal equations of the first ``k_old``.
    Dense only: up to :data:`DENSE_MAX` unknowns in all.
    """
    if len(widths) + 1 > DENSE_MAX:
        raise ValueError(f"appended_rows: {len(widths) + 1} unknowns, dense only up to "
                         f"{DENSE_MAX}")
    rows = rows_under(xy, centers[k_old:], widths[k_old:], support)
    normal = _normal_under(xy, z, rows, centers, widths, weights, support, 1 + k_old)
    block, atr = normal.parts
    return block[0] + block[1], (atr[0] + atr[1])[1 + k_old:]


class GrownNormal:
    """Dense normal equations grown by appended neurons, assembled once when asked for.

    ``base`` (``A'A`` of ``[a0, a_1 .. a_k]``) is kept as given and each
    :meth:`append` keeps only the new neurons' rows (:func:`appended_rows`), so a round of
    new neurons costs their rows, not a copy of the whole matrix; :meth:`matrix` writes
    the whole ``A'A`` once (the same numbers as :func:`extend_normal`, bit for bit).
    """

    def __init__(self, base: np.ndarray, atz: np.ndarray):
        self.base, self.atz = base, np.asarray(atz, np.float64)
        self.blocks: list[np.ndarray] = []
        self._whole: np.ndarray | None = base

    @property
    def size(self) -> int:
        """Number of unknowns (the bias and every neuron so far)."""
        return len(self.atz)

    def append(self, rows: np.ndarray, atz: np.ndarray) -> None:
        """Add the rows of neurons appended after the current ones."""
        if rows.shape[1] != self.size + len(rows):
            raise ValueError("appended rows must span every column, theirs included")
        self.blocks.append(rows)
        self.atz = np.concatenate([self.atz, atz])
        self._whole = None

    def matrix(self) -> np.ndarray:
        """Return the whole symmetric ``A'A`` (assembled on the first call after an append)."""
        if self._whole is None:
            n, k = self.size, self.base.shape[0]
            out = np.empty((n, n))
            out[:k, :k] = self.base
            for rows in self.blocks:
                m = len(rows)
                out[k:k + m, :k + m] = rows
                out[:k, k:k + m] = rows[:, :k].T
                k += m
            self._whole = out
        return self._whole


def extend_and_solve(xy: np.ndarray, z: np.ndarray, pr: PolishResult, a0: float,
                     centers: np.ndarray, widths: np.ndarray, weights: np.ndarray,
                     support: float, ridge: float = 1e-4) -> PolishResult:
    """Polish the weights again after neurons were appended to ``pr``'s, at a local cost.

    ``centers``, ``widths`` and ``weights`` are ``pr``'s neurons followed by the new ones
    (``a0`` and the weights as they stand now). ``pr``'s normal equations are extended
    by the new neurons' columns (:func:`extend_normal`) and the weights are solved as
    :func:`polish_weights` does, pulled toward the current ones; the result is kept
    when it lowers the mean absolute error.
    """
    ata, atz = extend_normal(xy, z, pr, centers, widths, weights, support)
    w0 = np.concatenate([[a0], weights])
    before = float(np.abs(z - _predict(xy, a0, centers, widths, weights, support)).mean())
    if len(widths) + 1 == pr.ata.shape[0]:  # nothing appended
        return PolishResult(a0, centers, widths, weights, before, before, 0, ata, atz)
    w = w0 + _solve_spd(_ridged(ata, ridge), atz - ata @ w0)
    if not np.all(np.isfinite(w)):
        return PolishResult(a0, centers, widths, weights, before, before, 0, ata, atz)
    after = float(np.abs(z - _predict(xy, w[0], centers, widths, w[1:], support)).mean())
    if after > before:
        return PolishResult(a0, centers, widths, weights, before, before, 0, ata, atz)
    return PolishResult(float(w[0]), centers, widths, w[1:].copy(), before, after, 1, ata,
                        atz)


def _ridged(ata: np.ndarray | sp.spmatrix, ridge: float) -> np.ndarray | sp.spmatrix:
    """``A'A + lam I`` with ``lam = ridge * mean(diag(A'A))`` (a new matrix)."""
    lam = max(ridge, _RIDGE_FLOOR) * float(ata.diagonal().mean())
    if isinstance(ata, np.ndarray):
        out = ata.copy()
        out[np.diag_indices_from(out)] += lam
        return out
    return ata + sp.diags(np.full(ata.shape[0], lam))


def _dense(m: np.ndarray | sp.spmatrix) -> np.ndarray:
    """Return ``m`` as a dense array (itself when it is one)."""
    return m if isinstance(m, np.ndarray) else m.toarray()


def rows_under(xy: np.ndarray, centers: np.ndarray, widths: np.ndarray,
               support: float) -> np.ndarray:
    """Sorted indices of the (N, 2) unit-square points under any of the neurons.

    Under: within the truncated support, by the test the design rows use
    (:func:`~asrbf_mesh._network_kernels.under_any`), so these are exactly the rows
    where the neurons' columns are not zero.
    """
    if len(widths) == 0:
        return np.zeros(0, np.int64)
    support_, lo, h, g, start, items, _, _ = eval_grid(centers, widths, np.zeros(len(widths)),
                                                       support)
    return np.flatnonzero(_nk.under_any(np.ascontiguousarray(xy, dtype=np.float64),
                                        _read_only(centers), _read_only(widths), support_,
                                        lo, h, g, start, items))


def _solve_spd(mat: sp.spmatrix | np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """Solve the symmetric positive definite system ``mat x = rhs``.

    Dense Cholesky (LAPACK, one thread) up to :data:`DENSE_MAX` unknowns: 10 ms at
    K = 954 where SuperLU took 30 ms (the face map's normal equations, 10 % filled);
    sparse LU (SuperLU) up to :data:`_DIRECT_MAX` (or when Cholesky finds the matrix
    not positive definite); above, Jacobi-preconditioned conjugate gradients to a
    relative residual of 1e-12, because the LU factor's fill grows faster than K on
    these 2D neighbourhoods (7.8 million entries, 120 MB, at K = 3,600) while CG needs
    only the matrix (0.5 million entries there; 3,300 iterations, 1.6 s, the same
    solution to 1e-10).
    """
    import scipy.linalg as sla

    n = mat.shape[0]
    if n <= DENSE_MAX:
        # one BLAS thread: see drop_idle
        with one_blas_thread():
            chol, info = sla.lapack.dpotrf(_dense(mat), lower=1)
            if info == 0:
                x, info = sla.lapack.dpotrs(chol, np.asarray(rhs, np.float64), lower=1)
        if info == 0:
            return x
    mat = sp.csr_matrix(mat)
    if n <= _DIRECT_MAX:
        return spsolve(mat.tocsc(), rhs)
    x, _ = cg(mat, rhs, rtol=1e-12, atol=0.0, maxiter=20 * n,
              M=sp.diags(1.0 / mat.diagonal(), format="csr"))
    return x


def _chunks(n: int) -> list[slice]:
    """Row blocks of :data:`_CHUNK` points covering ``range(n)``."""
    return [slice(i, min(i + _CHUNK, n)) for i in range(0, n, _CHUNK)]


def polish_full(xy: np.ndarray, z: np.ndarray, a0: float, centers: np.ndarray,
                widths: np.ndarray, weights: np.ndarray, support: float, *,
                iterations: int = 4, ridge: float = 1e-4) -> PolishResult:
    """Weights by least squares, then Levenberg-Marquardt over every parameter.

    Parameters are ``(a0, a_k, log sigma_k, u_k)``; each iteration solves (inexactly,
    by preconditioned conjugate gradients) the damped normal equations
    ``(J'J + mu D + lam S) dp = J'r - lam S (p - p_learned)`` with
    ``D = diag(J'J)`` and ``S = diag(1, 1, sigma^2... )`` scaled as the EKF prior; a
    step is kept only if it lowers the penalized squared error, otherwise ``mu``
    grows tenfold.

    Returns
    -------
    PolishResult
    """
    first = polish_weights(xy, z, a0, centers, widths, weights, support, ridge)
    k = len(widths)
    a0c = first.a0
    cen = centers.copy()
    wid = widths.copy()
    wts = first.weights.copy()
    ref = np.concatenate([[a0c], np.column_stack([wts, np.log(wid), cen]).ravel()])

    def pack(a0_, w_, s_, c_):
        return np.concatenate([[a0_], np.column_stack([w_, np.log(s_), c_]).ravel()])

    def unpack(p):
        body = p[1:].reshape(k, 4)
        s_ = np.clip(np.exp(body[:, 1]), *_SIGMA_RANGE)
        c_ = np.clip(body[:, 2:4], *_CENTRE_BOX)
        return float(p[0]), body[:, 0].copy(), s_, np.ascontiguousarray(c_)

    # prior scales: weight and log-width O(1), centres O(sigma)
    scale = np.concatenate([[1.0], np.column_stack(
        [np.ones(k), np.ones(k), wid, wid]).ravel()])
    p = pack(a0c, wts, wid, cen)
    r = z - _predict(xy, a0c, cen, wid, wts, support)
    base = None
    mu = 1e-3
    done = 0
    for _ in range(iterations):
        J = design_matrix(xy, cen, wid, wts, support, full=True)
        diag = np.asarray(J.multiply(J).sum(axis=0)).ravel()
        lam = max(ridge, _RIDGE_FLOOR) * float(diag.mean())
        prior = lam / scale**2
        if base is None:
            base = float(r @ r + np.sum(prior * (p - ref) ** 2))
        rhs = J.T @ r - prior * (p - ref)
        jtj = (J.T @ J).tocsr()
        improved = False
        for _try in range(6):
            # inexact Newton step: Jacobi-preconditioned conjugate gradients
            shift = mu * np.maximum(diag, 1e-12) + prior
            mat = jtj + sp.diags(shift, format="csr")
            pre = sp.diags(1.0 / (diag + shift), format="csr")
            dp, _ = cg(mat, rhs, M=pre, maxiter=_CG_ITERATIONS, rtol=1e-6)
            if not np.all(np.isfinite(dp)):
                mu *= 10.0
                continue
            p_new = p + dp
            a0n, wn, sn, cn = unpack(p_new)
            p_new = pack(a0n, wn, sn, cn)
            rn = z - _predict(xy, a0n, cn, sn, wn, support)
            cost = float(rn @ rn + np.sum(prior * (p_new - ref) ** 2))
            if np.isfinite(cost) and cost < base:
                p, r, base = p_new, rn, cost
                a0c, wts, wid, cen = a0n, wn, sn, cn
                mu = max(mu / 3.0, 1e-7)
                improved = True
                break
            mu *= 10.0
        if not improved:
            break
        done += 1
    after = float(np.mean(np.abs(r)))
    return PolishResult(a0c, cen, wid, wts, first.ebar_before, after, 1 + done)


#: :func:`drop_idle` inverts the normal equations densely up to this many neurons.
IDLE_MAX_NEURONS = DENSE_MAX - 1


def solve_and_drop(xy: np.ndarray, z: np.ndarray, ata: np.ndarray | sp.spmatrix,
                   atz: np.ndarray, a0: float, centers: np.ndarray, widths: np.ndarray,
                   weights: np.ndarray, support: float, ridge: float, limit: float, *,
                   base: np.ndarray | None = None, give_back: float = 1.0,
                   extra: float = 0.0, normal: bool = False,
                   at_least: int = 0, memo: dict | None = None, strips: bool = False
                   ) -> tuple[PolishResult, int] | None:
    """Solve the weights from normal equations, then drop the neurons hardly needed.

    The weights minimize ``||A w - z||^2 + lam ||w - w_now||^2`` (``A'A = ata``,
    ``A'z = atz``, ``w_now = (a0, weights)``, ``lam`` as :func:`polish_weights`). Then
    removing neuron ``j`` and solving the other weights again raises that sum by
    ``w_j^2 / (M^-1)_jj`` (``M = A'A + lam I``), the classic backward-elimination test:
    the neurons go one at a time, the one whose removal costs least first, while that
    cost is under ``limit`` (unit depth squared), each removal updating the other
    weights and costs exactly (:func:`~asrbf_mesh._network_kernels.eliminate`: one
    dense inverse of ``M``, then rank-one terms); no design matrix is built again.
    With ``base`` (weights ``(a0, a_1 .. a_K)`` of a reference network, e.g. before
    neurons were appended), the removals together raise the sum by at most
    ``give_back`` times what the solved weights gained over ``base``, plus ``extra``
    (unit depth squared): the result's sum of squared errors stays below the
    reference's when ``give_back < 1`` and ``extra`` is 0. The first ``at_least``
    removals go whatever they cost, within that budget (fewer when it runs out).
    Returns ``(result, neurons dropped)``, the result's ``ebar_after`` and ``residual``
    measured (its ``ebar_before`` NaN; its normal equations, without the dropped
    unknowns, only with ``normal``: their copy took 5 ms at K = 1,500), or None above
    :data:`IDLE_MAX_NEURONS` neurons or when ``M`` is not positive definite.

    ``memo``: a dict kept between calls on the same normal equations, weights and
    ``base`` that differ only in ``give_back``, ``extra`` and ``at_least``: the solve (the
    factorization and inverse, or the tiles' sweeps and inverses) is made by the first
    and taken by the others, whose results are the same numbers as without it.
    ``strips``: sparse equations past :data:`IDLE_MAX_NEURONS` go by strips too (each
    strip's rows made dense, never the whole matrix), instead of None.
    """
    import scipy.linalg as sla

    from ._network_kernels import eliminate

    k = len(widths)
    by_strips = strips and k > TILE_ABOVE and not isinstance(ata, np.ndarray)
    if k > IDLE_MAX_NEURONS and not by_strips or ata.shape[0] != k + 1:
        return None
    ata = ata.tocsr() if by_strips else _dense(ata)
    w = np.concatenate([[a0], weights])
    memo = {} if memo is None else memo
    if k > TILE_ABOVE:
        return _solve_and_drop_tiled(xy, z, ata, atz, w, centers, widths, support, ridge,
                                     limit, base, give_back, extra, normal, at_least, memo)
    if "inv" not in memo:
        # one BLAS thread (:mod:`._blas`): a threaded factorization's spinning workers took the
        # numba kernels' cores (bun000's piecewise fit 0.94-1.07 s with them, 0.63-0.69 without)
        with one_blas_thread():
            chol, info = sla.lapack.dpotrf(_ridged(ata, ridge), lower=1)
            if info == 0:
                step, info = sla.lapack.dpotrs(chol, atz - ata @ w, lower=1)
            if info == 0:
                inv, info = sla.lapack.dpotri(chol, lower=1)  # its lower triangle
        memo["inv"] = None if info != 0 else (inv, w + step)
    if memo["inv"] is None:
        return None
    inv, w = memo["inv"][0], memo["inv"][1].copy()
    budget = np.inf
    if base is not None:  # the gain in the sum of squares, from the normal equations
        if "gain" not in memo:
            memo["gain"] = _sum_squares(ata, atz, base) - _sum_squares(ata, atz, w)
        budget = give_back * max(memo["gain"], 0.0) + extra
    dropped = eliminate(inv, w, float(limit), float(budget), int(at_least))
    return _dropped_result(xy, z, w, dropped, centers, widths, support,
                           (ata, atz) if normal else None)


def _dropped_result(xy: np.ndarray, z: np.ndarray, w: np.ndarray, dropped: np.ndarray,
                    centers: np.ndarray, widths: np.ndarray, support: float,
                    normal: tuple[np.ndarray, np.ndarray] | None = None
                    ) -> tuple[PolishResult, int] | None:
    """Return the network without the unknowns ``dropped`` (1-based), and its residual.

    With ``normal`` (``A'A``, ``A'z``), the result keeps them without the dropped unknowns.
    """
    if not np.all(np.isfinite(w)):
        return None
    keep = np.setdiff1d(np.arange(len(widths)), dropped - 1)
    centers, widths, weights = centers[keep], widths[keep], w[1 + keep]
    res = z - _predict(xy, w[0], centers, widths, weights, support)
    ata = atz = None
    if normal is not None:
        cols = np.concatenate([[0], 1 + keep])
        ata, atz = normal[0][np.ix_(cols, cols)], normal[1][cols]
    return PolishResult(float(w[0]), centers, widths, weights.copy(), float("nan"),
                        float(np.abs(res).mean()), 1, ata, atz, res), len(dropped)


#: :func:`solve_and_drop` above this many neurons solves and drops tile by tile ...
TILE_ABOVE = 600
#: ... in strips of about this many neurons across the longer side of the centres' extent.
TILE_NEURONS = 300
#: Block Gauss-Seidel sweeps over the tiles (before the drop; one more after it).
TILE_SWEEPS = 2


class _Tiles:
    """Block Gauss-Seidel over strips of neurons, on dense ridged normal equations.

    ``tiles``: about :data:`TILE_NEURONS` unknowns each across the longer side of the
    centres' extent, the bias (unknown 0) in every one. :meth:`sweep` steps each tile's
    weights in turn (``w``, updated in place) from the same ridged normal equations as a
    whole solve (``lam = ridge * mean(diag(A'A))``), the others fixed at their latest
    values; ``gains`` sums what each tile's steps took off the sum of squares and
    ``factors`` holds each tile's last Cholesky factor. Each tile's ridged block is
    factored once for the unknowns alive when made.

    Not for the weight polish (2-3 sweeps from the learned weights, 2026-11-29): from
    weights that far off they converge slowly, E-bar 1.0-1.6x the exact polish's on 100 x
    100 grids of sin(k pi x) cos(k pi y) for 5-10 ms saved.
    """

    def __init__(self, ata: np.ndarray, atz: np.ndarray, w: np.ndarray, centers: np.ndarray,
                 ridge: float):
        k = len(centers)
        n_tiles = -(-k // TILE_NEURONS)
        axis = int(np.argmax(np.ptp(centers, axis=0)))
        order = np.argsort(centers[:, axis], kind="stable")
        self.tiles = [np.concatenate([[0], 1 + np.sort(t)])
                      for t in np.array_split(order, n_tiles)]
        self.ata, self.atz, self.w = ata, atz, w
        self.lam = max(ridge, _RIDGE_FLOOR) * float(ata.diagonal().mean())
        self.gains = np.zeros(n_tiles)
        self.factors: list[np.ndarray | None] = [None] * n_tiles
        self._blocks: list[tuple[np.ndarray, np.ndarray, np.ndarray] | None] = [None] * n_tiles

    def sweep(self, alive: np.ndarray) -> bool:
        """One sweep over the tiles' unknowns that are ``alive``; False if a block is singular."""
        import scipy.linalg as sla

        ata, atz, w, lam = self.ata, self.atz, self.w, self.lam
        for t, idx in enumerate(self.tiles):
            idx = idx[alive[idx]]
            rows = ata[idx]  # (sparse equations: the strip's rows, sparse)
            made = self._blocks[t]
            if made is None or not np.array_equal(made[0], idx):
                sub = rows[:, idx]  # (from the rows: a third of np.ix_'s time)
                sub = sub if isinstance(sub, np.ndarray) else sub.toarray()
                sub[np.diag_indices_from(sub)] += lam
                with one_blas_thread():
                    chol, info = sla.lapack.dpotrf(sub, lower=1)
                if info != 0:
                    return False
                made = self._blocks[t] = (idx, sub, chol)
            _, sub, chol = made
            rhs = atz[idx] - rows @ w
            with one_blas_thread():
                step, info = sla.lapack.dpotrs(chol, rhs, lower=1)
            if info != 0:
                return False
            w[idx] += step
            # the sum of squares fell by 2 d'r - d'A'A d (A'A = sub - lam I)
            self.gains[t] += 2.0 * step @ rhs - step @ (sub @ step) + lam * (step @ step)
            self.factors[t] = chol
        return True


def _solve_and_drop_tiled(xy: np.ndarray, z: np.ndarray, ata: np.ndarray, atz: np.ndarray,
                          w: np.ndarray, centers: np.ndarray, widths: np.ndarray,
                          support: float, ridge: float, limit: float,
                          base: np.ndarray | None, give_back: float, extra: float,
                          normal: bool = False, at_least: int = 0, memo: dict | None = None
                          ) -> tuple[PolishResult, int] | None:
    """:func:`solve_and_drop` by strips of neurons: O(K^3 / T^2) instead of O(K^3).

    The weights are solved by block Gauss-Seidel over ``T`` strips of about
    :data:`TILE_NEURONS` neurons (the bias in every block; the other blocks' weights fixed
    at their latest values), :data:`TILE_SWEEPS` sweeps, each block's step from the same
    ridged normal equations as the whole solve. Then each strip drops its neurons by the
    same backward elimination, the other strips' weights fixed, within its share of the
    budget (the whole budget, ``extra`` included, split in proportion to what each strip's
    steps gained; ``at_least`` split in proportion to the strips' neurons); a last sweep
    solves the kept weights again. A strip prices a removal with
    only its own weights free to make up for it, so at least as high as the whole solve
    would (a principal block's inverse has the smaller diagonal): K comes out a little
    higher. On the face map (main piece 880-1,010 neurons after the tails, 3-4 strips; seeds
    0-9): K 720 -> 735 (median; worst seed 767 -> 781), E-bar 0.00188 either way, the
    default reconstruction's 99.9th percentiles (samples in triangles -> mesh, mesh -> scan)
    0.326 / 0.442 -> 0.321 / 0.438 % of the diagonal, the solves and drops of a fit's pieces
    40-60 -> 18-20 ms, the fit 0.41 -> 0.38 s (medians of the fastest of 3).
    """
    import scipy.linalg as sla

    from ._network_kernels import eliminate

    k = len(widths)
    memo = {} if memo is None else memo
    if "tiles" not in memo:
        tiles = _Tiles(ata, atz, w, centers, ridge)
        alive = np.ones(k + 1, dtype=bool)
        solved = all(tiles.sweep(alive) for _ in range(TILE_SWEEPS))
        invs = []
        for factor in tiles.factors if solved else []:
            with one_blas_thread():
                inv, info = sla.lapack.dpotri(factor, lower=1)
            if info != 0:
                solved = False
                break
            invs.append(inv)
        # what a later call starts from: the swept weights, gains, factors and blocks
        memo["tiles"] = (tiles, w.copy(), tiles.gains.copy(), list(tiles.factors),
                         list(tiles._blocks), invs) if solved else None
    if memo["tiles"] is None:
        return None
    tiles, w0, gains, factors, blocks, invs = memo["tiles"]
    w = tiles.w = w0.copy()
    tiles.gains, tiles.factors, tiles._blocks = gains.copy(), list(factors), list(blocks)
    alive = np.ones(k + 1, dtype=bool)
    budget = np.inf
    if base is not None:
        if "gain" not in memo:
            memo["gain"] = _sum_squares(ata, atz, base) - _sum_squares(ata, atz, w)
        budget = give_back * max(memo["gain"], 0.0) + extra
    share = np.maximum(tiles.gains, 0.0)
    share = share / share.sum() if share.sum() > 0 else np.full(len(share), 1.0 / len(share))
    dropped = []
    for idx, inv, part in zip(tiles.tiles, invs, share, strict=True):
        wt = w[idx].copy()
        gone = eliminate(inv, wt, float(limit), float(budget * part if np.isfinite(budget)
                                                      else np.inf),
                         -(-at_least * (len(idx) - 1) // k))
        w[idx] = wt
        dropped.append(idx[gone])
    out = np.sort(np.concatenate(dropped)) if dropped else np.zeros(0, np.int64)
    alive[out] = False
    if len(out) and not tiles.sweep(alive):
        return None
    return _dropped_result(xy, z, w, out, centers, widths, support,
                           (ata, atz) if normal else None)


def _sum_squares(ata: np.ndarray, atz: np.ndarray, w: np.ndarray) -> float:
    """Return ``||A w - z||^2`` less the constant ``z'z``, from the normal equations."""
    return float(w @ (ata @ w) - 2.0 * (w @ atz))


def drop_idle(xy: np.ndarray, z: np.ndarray, pr: PolishResult, support: float,
              ridge: float, limit: float, *,
              tolerance: float = 0.005) -> tuple[PolishResult, int]:
    """Drop neurons the polished network hardly needs; (result, neurons dropped).

    :func:`solve_and_drop` from ``pr``'s normal equations (kept by the weight polish).
    The result is kept when the mean absolute error grows by at most ``tolerance``
    (relative); ``pr`` is returned unchanged when no neuron goes, for a network without
    normal equations, or above :data:`IDLE_MAX_NEURONS` neurons (the test inverts ``M``
    densely).
    """
    if pr.ata is None or pr.atz is None or len(pr.widths) < 2:
        return pr, 0
    got = solve_and_drop(xy, z, pr.ata, pr.atz, pr.a0, pr.centers, pr.widths, pr.weights,
                         support, ridge, limit, normal=True)
    if got is None or got[1] == 0 or got[0].ebar_after > pr.ebar_after * (1.0 + tolerance):
        return pr, 0
    return replace(got[0], ebar_before=pr.ebar_before, iterations=pr.iterations), got[1]
