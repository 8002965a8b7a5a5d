"""Compiled evaluation of a fixed Gaussian RBF network (private).

A static grid over the evaluation box holds, per cell, the neurons whose
truncated support (``support * sigma``) meets the cell, in CSR form. Cell
indices are clamped, so border cells also hold every neuron reaching beyond the
box and points outside the box are still evaluated exactly.
"""

from __future__ import annotations

import contextlib
import os

import numpy as np
from numba import get_num_threads, njit, prange, set_num_threads

from . import _jit_cache  # noqa: F401 (first: where numba caches the kernels below)


@njit(cache=True, inline="always")
def _cell(v, lo, h, g):
    c = int(np.floor((v - lo) / h))
    if c < 0:
        return 0
    if c >= g:
        return g - 1
    return c


@njit(cache=True, inline="always")
def _locate(pts, i, lo, h, g):
    """Point i (x, y) and the index of its grid cell."""
    x = pts[i, 0]
    y = pts[i, 1]
    return x, y, _cell(y, lo[1], h, g) * g + _cell(x, lo[0], h, g)


@njit(cache=True, inline="always")
def _offset(x, y, centers, widths, j):
    """Offset (dx, dy) of a point from neuron j, its squared length d2 and sigma_j^2."""
    dx = x - centers[j, 0]
    dy = y - centers[j, 1]
    return dx, dy, dx * dx + dy * dy, widths[j] * widths[j]


@njit(cache=True, nogil=True)
def build_grid(centers, widths, support, lo, h, g):
    """CSR lists ``(start, items)`` of the neurons meeting each of the g x g cells."""
    k = centers.shape[0]
    counts = np.zeros(g * g + 1, np.int64)
    for n in range(2):  # pass 0 counts, pass 1 fills
        if n == 1:
            for c in range(g * g):
                counts[c + 1] += counts[c]
            items = np.empty(counts[g * g], np.int64)
            fill = counts[:-1].copy()
        for j in range(k):
            s = support * widths[j]
            x0 = _cell(centers[j, 0] - s, lo[0], h, g)
            x1 = _cell(centers[j, 0] + s, lo[0], h, g)
            y0 = _cell(centers[j, 1] - s, lo[1], h, g)
            y1 = _cell(centers[j, 1] + s, lo[1], h, g)
            for cy in range(y0, y1 + 1):
                for cx in range(x0, x1 + 1):
                    c = cy * g + cx
                    if n == 0:
                        counts[c + 1] += 1
                    else:
                        items[fill[c]] = j
                        fill[c] += 1
    return counts, items


_FAST = {"reassoc", "contract", "nsz", "arcp"}  # no nnan/ninf: inputs are clamped instead


@njit(cache=True, inline="always", fastmath=_FAST)
def _exp_neg(t):
    """exp(-t) for 0 <= t <= 40 by a degree-11 Taylor polynomial of exp(-t/32), squared 5 times.

    Pure arithmetic, so loops over it vectorize; relative error < 1e-12 on [0, 12.25].
    """
    y = -t * 0.03125
    p = 2.505210838544172e-08
    p = p * y + 2.755731922398589e-07
    p = p * y + 2.7557319223985893e-06
    p = p * y + 2.48015873015873e-05
    p = p * y + 0.0001984126984126984
    p = p * y + 0.001388888888888889
    p = p * y + 0.008333333333333333
    p = p * y + 0.041666666666666664
    p = p * y + 0.16666666666666666
    p = p * y + 0.5
    p = p * y + 1.0
    p = p * y + 1.0
    p = p * p
    p = p * p
    p = p * p
    p = p * p
    return p * p


#: Each cell's packed neuron list is padded to a multiple of this many entries (zero
#: weight, zero 1/sigma^2: they add exactly 0), so the vectorized loop over a list has
#: no scalar remainder: one AVX-512 register of float64 per step.
PAD = 8


@njit(cache=True, nogil=True)
def pack_cells(centers, widths, weights, start, items):
    """Neuron parameters in cell-list order, each list padded to :data:`PAD` entries.

    Returns ``(pstart, packed)``: cell ``c``'s entries are ``packed[:, pstart[c]:pstart[c
    + 1]]``, rows (cx, cy, 1/sigma^2, a), contiguous per cell; padding entries are zeros.
    """
    ncell = start.shape[0] - 1
    pstart = np.zeros(ncell + 1, np.int64)
    for c in range(ncell):
        n = start[c + 1] - start[c]
        pstart[c + 1] = pstart[c] + (n + PAD - 1) // PAD * PAD
    out = np.zeros((4, pstart[ncell]))
    for c in range(ncell):
        q = pstart[c]
        for p in range(start[c], start[c + 1]):
            j = items[p]
            out[0, q] = centers[j, 0]
            out[1, q] = centers[j, 1]
            out[2, q] = 1.0 / (widths[j] * widths[j])
            out[3, q] = weights[j]
            q += 1
    return pstart, out


#: Points are evaluated in blocks of this many (fewer when that would leave a thread
#: idle; up to 16 x more on grids of more cells, so that the counting sort's table costs
#: at most one entry per point). A block's points are visited cell by cell, so each
#: cell's neuron list is read from L1 by every point of the block in that cell. On
#: random points (face map network, K = 1,416, one thread): 6.9 M points/s point by
#: point, 17 M points/s in blocks of 16,384. A block with fewer points than a quarter of
#: the cells is evaluated point by point (a sort would cost more than it saves).
BLOCK = 16384


@njit(cache=True, fastmath=_FAST)
def _cell_sum(x, y, cx, cy, inv, a, supp2):
    """Sum of the truncated Gaussians of one cell's list at (x, y): branch- and gather-free."""
    f = 0.0
    for p in range(cx.shape[0]):
        dx = x - cx[p]
        dy = y - cy[p]
        t = (dx * dx + dy * dy) * inv[p]
        v = a[p] * _exp_neg(min(t, 40.0))
        f += v if t < supp2 else 0.0
    return f


@njit(cache=True, fastmath=_FAST)
def _values_block(pts, b0, b1, out, a0, packed, pstart, supp2, lo, h, g):
    """Evaluate points ``b0:b1`` into ``out``, visiting them cell by cell (counting sort)."""
    px, py, inv, a = packed[0], packed[1], packed[2], packed[3]
    if 4 * (b1 - b0) < g * g:  # few points on a fine grid: one by one
        for i in range(b0, b1):
            x, y, c = _locate(pts, i, lo, h, g)
            s0 = pstart[c]
            s1 = pstart[c + 1]
            out[i] = a0 + _cell_sum(x, y, px[s0:s1], py[s0:s1], inv[s0:s1], a[s0:s1], supp2)
        return
    count = np.zeros(g * g + 1, np.int64)
    cell = np.empty(b1 - b0, np.int64)
    for i in range(b0, b1):
        _, _, c = _locate(pts, i, lo, h, g)
        cell[i - b0] = c
        count[c + 1] += 1
    for c in range(g * g):
        count[c + 1] += count[c]
    order = np.empty(b1 - b0, np.int64)
    for i in range(b1 - b0):
        order[count[cell[i]]] = b0 + i
        count[cell[i]] += 1  # ends as the end of the cell's run
    r = 0
    for c in range(g * g):
        if count[c] == r:
            continue
        s0 = pstart[c]
        s1 = pstart[c + 1]
        X, Y, S, A = px[s0:s1], py[s0:s1], inv[s0:s1], a[s0:s1]
        while r < count[c]:
            i = order[r]
            out[i] = a0 + _cell_sum(pts[i, 0], pts[i, 1], X, Y, S, A, supp2)
            r += 1


#: Below this many points :func:`evaluate_values` runs on one thread: waking the thread
#: pool costs more than it saves, and much more on a loaded machine (1,000 points: 0.16 ms
#: on one thread, 2.0 ms on two with the other core busy). Same values either way.
SERIAL_BELOW = 8192


@njit(cache=True, parallel=True, nogil=True)
def _values_parallel(pts, a0, packed, pstart, support, lo, h, g, threads):
    m = pts.shape[0]
    out = np.empty(m)
    # at least four blocks a thread (a few thousand points still use every thread), and
    # at least one point per cell in a block (the counting sort's table) up to 16 BLOCKs
    n = max(min(BLOCK, (m + 4 * threads - 1) // (4 * threads)), min(g * g, 16 * BLOCK), 1)
    for b in prange((m + n - 1) // n):
        _values_block(pts, b * n, min(m, (b + 1) * n), out, a0, packed, pstart,
                      support * support, lo, h, g)
    return out


def evaluate_values(pts, a0, packed, pstart, support, lo, h, g):
    """Evaluate f (M,) at unit-square points (M, 2) (threads from :data:`SERIAL_BELOW` up)."""
    m = pts.shape[0]
    threads = threads_for(m)
    if threads > 1 and not _forked():
        return _values_parallel(pts, a0, packed, pstart, support, lo, h, g, threads)
    # one thread, or a forked child (see _forked): the same blocks, here or on the pool
    out = np.empty(m)
    if threads == 1:
        n = max(BLOCK, min(g * g, 16 * BLOCK))
    else:
        n = max(min(BLOCK, (m + 4 * threads - 1) // (4 * threads)), min(g * g, 16 * BLOCK), 1)
    in_threads(_values_blocks, (m + n - 1) // n, threads, pts, out, a0, packed, pstart,
               support, lo, h, g, n)
    return out


@njit(cache=True, nogil=True)
def _values_blocks(pts, out, a0, packed, pstart, support, lo, h, g, n, b0, b1):
    """Evaluate blocks ``b0:b1`` of ``n`` points each into ``out``."""
    m = pts.shape[0]
    for b in range(b0, b1):
        _values_block(pts, b * n, min(m, (b + 1) * n), out, a0, packed, pstart,
                      support * support, lo, h, g)


#: The id of the process that imported this module: a process with another id was forked
#: from it (see :func:`_forked`).
_PARENT = os.getpid()


def _forked() -> bool:
    """Whether this process was forked after this module was imported.

    numba's OpenMP layer kills a forked child at its first parallel kernel when the
    parent ran one ("fork() called from a process already using GNU OpenMP"): a forked
    child (``multiprocessing`` on Linux) runs the ``prange`` kernels' work as serial
    kernels on its own pool of Python threads instead (:func:`in_threads`), which gives
    the same bits.
    """
    return os.getpid() != _PARENT


def in_threads(kernel, n: int, threads: int, *args) -> None:
    """Run ``kernel(*args, i0, i1)`` over ``range(n)`` cut in ``threads`` contiguous parts.

    ``kernel`` is a serial ``nogil`` kernel that writes its results into arrays among
    ``args``; the parts after the first run on a pool of Python threads kept for the
    process, the first on this thread. A ``prange`` kernel does the same but costs about
    half a second to a second more to compile (numba's parallel transform), which a
    machine's first run pays. Kernels called over and over on chunks (the design rows of
    the weight polish, the evaluation) keep their ``prange``: OpenMP's waiting threads
    start a part sooner than a pool's (the polish's design rows, 8,192-row chunks of the
    face map, took 32 ms through the pool against 28 ms).
    """
    threads = max(1, min(int(threads), n))
    if threads == 1:
        kernel(*args, 0, n)
        return
    cuts = [n * t // threads for t in range(threads + 1)]
    pool = _pool()
    rest = [pool.submit(kernel, *args, cuts[t], cuts[t + 1]) for t in range(1, threads)]
    try:
        kernel(*args, cuts[0], cuts[1])
    finally:
        for f in rest:
            f.result()


_POOL: dict = {}


def _pool():
    """Return this process's pool of threads for :func:`in_threads` (made on first use).

    One per process id: a child forked after the parent used its pool gets a pool of
    its own (the parent's threads do not exist in the child, and a copied pool would
    wait for them forever).
    """
    pid = os.getpid()
    pool = _POOL.get(pid)
    if pool is None:
        import atexit
        from concurrent.futures import ThreadPoolExecutor

        _POOL.clear()
        pool = _POOL[pid] = ThreadPoolExecutor(max_workers=64,
                                               thread_name_prefix="asrbf-kernel")
        atexit.register(pool.shutdown, wait=False)
    return pool


@njit(cache=True, nogil=True)
def _values_gradient(pts, a0, centers, widths, weights, support, lo, h, g, start, items,
                     out, grad, i0, i1):
    supp2 = support * support
    for i in range(i0, i1):
        x, y, c = _locate(pts, i, lo, h, g)
        f = a0
        gx = 0.0
        gy = 0.0
        for p in range(start[c], start[c + 1]):
            j = items[p]
            dx, dy, d2, s2 = _offset(x, y, centers, widths, j)
            if d2 < supp2 * s2:
                v = weights[j] * np.exp(-d2 / s2)
                f += v
                gx -= 2.0 * v * dx / s2
                gy -= 2.0 * v * dy / s2
        out[i] = f
        grad[i, 0] = gx
        grad[i, 1] = gy


def evaluate_with_gradient(pts, a0, centers, widths, weights, support, lo, h, g, start, items):
    """Evaluate f (M,) and its gradient df/dx, df/dy (M, 2) at unit-square points (M, 2)."""
    m = pts.shape[0]
    out = np.empty(m)
    grad = np.empty((m, 2))
    in_threads(_values_gradient, m, threads_for(m), pts, a0, centers, widths, weights,
               support, lo, h, g, start, items, out, grad)
    return out, grad


def threads_for(m: int) -> int:
    """Threads for ``m`` points: one below :data:`SERIAL_BELOW`, else numba's setting."""
    return 1 if m < SERIAL_BELOW else get_num_threads()


def design_rows(pts, centers, widths, weights, support, lo, h, g, start, items, full):
    """Sparse Jacobian of f at ``pts`` in CSR form ``(indptr, indices, data)``.

    Column 0 is the bias a0 (ones). With ``full=False`` column 1 + k is the weight
    a_k; with ``full=True`` four columns per neuron, (a, log sigma, ux, uy) at
    1 + 4k .. 4 + 4k. A ``prange`` kernel (:func:`_design_rows`); in a forked child the
    same rows counted and filled by serial kernels on a pool of threads (:func:`_forked`).
    """
    if not _forked():
        return _design_rows(pts, centers, widths, weights, support, lo, h, g, start, items,
                            full)
    m = pts.shape[0]
    threads = threads_for(m)
    counts = np.empty(m, np.int64)
    in_threads(_design_counts, m, threads, pts, centers, widths, support, lo, h, g, start,
               items, 4 if full else 1, counts)
    indptr = np.zeros(m + 1, np.int64)
    np.cumsum(counts, out=indptr[1:])
    cols = np.empty(int(indptr[m]), np.int64)
    vals = np.empty(int(indptr[m]))
    in_threads(_design_fill, m, threads, pts, centers, widths, weights, support, lo, h, g,
               start, items, bool(full), indptr, cols, vals)
    return indptr, cols, vals


@njit(cache=True, nogil=True)
def _design_counts(pts, centers, widths, support, lo, h, g, start, items, per, counts,
                   i0, i1):
    supp2 = support * support
    for i in range(i0, i1):
        counts[i] = _design_count(pts, centers, widths, supp2, lo, h, g, start, items, per, i)


@njit(cache=True, inline="always")
def _design_count(pts, centers, widths, supp2, lo, h, g, start, items, per, i):
    """Length of design row ``i``: the bias and ``per`` entries per neuron over the point."""
    x, y, c = _locate(pts, i, lo, h, g)
    cnt = 1
    for p in range(start[c], start[c + 1]):
        _, _, d2, s2 = _offset(x, y, centers, widths, items[p])
        if d2 < supp2 * s2:  # the same test as the fill, to the last bit
            cnt += per
    return cnt


@njit(cache=True, nogil=True)
def _design_fill(pts, centers, widths, weights, support, lo, h, g, start, items, full,
                 indptr, cols, vals, i0, i1):
    supp2 = support * support
    for i in range(i0, i1):
        _design_row(pts, centers, widths, weights, supp2, lo, h, g, start, items, full,
                    indptr, cols, vals, i)


@njit(cache=True, inline="always")
def _design_row(pts, centers, widths, weights, supp2, lo, h, g, start, items, full, indptr,
                cols, vals, i):
    """Fill design row ``i`` into the CSR arrays (its place: ``indptr[i]``)."""
    x, y, c = _locate(pts, i, lo, h, g)
    n = indptr[i]
    cols[n] = 0
    vals[n] = 1.0
    n += 1
    for p in range(start[c], start[c + 1]):
        j = items[p]
        dx, dy, d2, s2 = _offset(x, y, centers, widths, j)
        if d2 < supp2 * s2:
            phi = np.exp(-d2 / s2)
            if full:
                ap = weights[j] * phi
                cols[n] = 4 * j + 1
                cols[n + 1] = 4 * j + 2
                cols[n + 2] = 4 * j + 3
                cols[n + 3] = 4 * j + 4
                vals[n] = phi
                vals[n + 1] = 2.0 * ap * d2 / s2
                vals[n + 2] = 2.0 * ap * dx / s2
                vals[n + 3] = 2.0 * ap * dy / s2
                n += 4
            else:
                cols[n] = j + 1
                vals[n] = phi
                n += 1


@njit(cache=True, parallel=True, nogil=True)
def _design_rows(pts, centers, widths, weights, support, lo, h, g, start, items, full):
    """:func:`design_rows` by a ``prange`` kernel."""
    m = pts.shape[0]
    supp2 = support * support
    per = 4 if full else 1
    counts = np.empty(m, np.int64)
    for i in prange(m):
        counts[i] = _design_count(pts, centers, widths, supp2, lo, h, g, start, items, per, i)
    indptr = np.zeros(m + 1, np.int64)
    for i in range(m):
        indptr[i + 1] = indptr[i] + counts[i]
    nnz = indptr[m]
    cols = np.empty(nnz, np.int64)
    vals = np.empty(nnz)
    for i in prange(m):
        _design_row(pts, centers, widths, weights, supp2, lo, h, g, start, items, full,
                    indptr, cols, vals, i)
    return indptr, cols, vals


@njit(cache=True, nogil=True)
def _under_any(pts, centers, widths, support, lo, h, g, start, items, out, i0, i1):
    supp2 = support * support
    for i in range(i0, i1):
        x, y, c = _locate(pts, i, lo, h, g)
        for p in range(start[c], start[c + 1]):
            _, _, d2, s2 = _offset(x, y, centers, widths, items[p])
            if d2 < supp2 * s2:
                out[i] = True
                break


def under_any(pts, centers, widths, support, lo, h, g, start, items):
    """Whether each point lies in the truncated support of any of the neurons.

    The same test as :func:`design_rows`, to the last bit: a point is under a neuron
    exactly when its design row has that neuron's column.
    """
    m = pts.shape[0]
    out = np.zeros(m, dtype=np.bool_)
    in_threads(_under_any, m, threads_for(m), pts, centers, widths, support, lo, h, g,
               start, items, out)
    return out


@njit(cache=True, inline="always")
def _row_residual(indptr, cols, vals, z, w0, i):
    """Design row i's span ``(a, b)`` in the CSR arrays and its residual ``z_i - A_i w0``."""
    a = indptr[i]
    b = indptr[i + 1]
    r = z[i]
    for p in range(a, b):
        r -= vals[p] * w0[cols[p]]
    return a, b, r


@njit(cache=True, inline="always", fastmath=_FAST)
def _cell_phi(x, y, cx, cy, inv, tt, ee):
    """Scaled squared distances ``tt`` and Gaussians ``ee`` of one packed cell list at (x, y).

    Branch-free over the whole list (padding included), so the loop vectorizes.
    """
    for p in range(cx.shape[0]):
        dx = x - cx[p]
        dy = y - cy[p]
        t = (dx * dx + dy * dy) * inv[p]
        tt[p] = t
        ee[p] = _exp_neg(min(t, 40.0))


@njit(cache=True, fastmath=_FAST)
def _in_support(tt, ee, n, supp2):
    """Zero the Gaussians ``ee[:n]`` outside the truncated support (``tt >= supp2``)."""
    for p in range(n):
        ee[p] = ee[p] if tt[p] < supp2 else 0.0


@njit(cache=True, fastmath=_FAST)
def _add_scaled(out, row, v, ee, n):
    """``out[row, :n] += v * ee[:n]`` (contiguous: the loop vectorizes)."""
    for q in range(n):
        out[row, q] += v * ee[q]


@njit(cache=True, nogil=True)
def _rows_by_cell(pts, rows, lo, h, g):
    """Return the rows sorted by grid cell (stable counting sort) and each cell's run ``count``."""
    m = rows.shape[0]
    ncell = g * g
    cell = np.empty(m, np.int64)
    count = np.zeros(ncell + 1, np.int64)
    for t in range(m):
        _, _, c = _locate(pts, rows[t], lo, h, g)
        cell[t] = c
        count[c + 1] += 1
    for c in range(ncell):
        count[c + 1] += count[c]
    order = np.empty(m, np.int64)
    fill = count[:ncell].copy()
    for t in range(m):
        order[fill[cell[t]]] = rows[t]
        fill[cell[t]] += 1
    return order, count


@njit(cache=True, nogil=True)
def _gram_new_cells(pts, z, order, count, c0, c1, supp2, start, items, pstart, packed,
                    first, part, ap):
    """:func:`gram_new_under` over the cells ``c0:c1``; returns their sum of ``|z|``."""
    px, py, inv = packed[0], packed[1], packed[2]
    longest = 0
    for c in range(pstart.shape[0] - 1):
        longest = max(longest, pstart[c + 1] - pstart[c])
    tt = np.empty(longest)
    ee = np.empty(longest)
    block = np.empty((longest, longest))  # appended neuron x list entry
    bias = np.empty(longest)
    atr = np.empty(longest)
    total = 0.0
    for c in range(c0, c1):
        if count[c] == count[c + 1]:
            continue
        a = start[c]
        n = start[c + 1] - a
        k0 = 0  # the list's first appended neuron
        while k0 < n and items[a + k0] + 1 < first:
            k0 += 1
        nn = n - k0
        if nn == 0:  # no appended neuron meets the cell: zero columns
            for r_ in range(count[c], count[c + 1]):
                total += abs(z[order[r_]])
            continue
        block[:nn, :n] = 0.0
        bias[:nn] = 0.0
        atr[:nn] = 0.0
        s0 = pstart[c]
        s1 = pstart[c + 1]
        for r_ in range(count[c], count[c + 1]):
            i = order[r_]
            _cell_phi(pts[i, 0], pts[i, 1], px[s0:s1], py[s0:s1], inv[s0:s1], tt, ee)
            _in_support(tt, ee, n, supp2)
            r = z[i]
            total += abs(r)
            for b in range(nn):
                v = ee[k0 + b]
                if v != 0.0:
                    atr[b] += v * r
                    bias[b] += v
                    _add_scaled(block, b, v, ee, n)
        for b in range(nn):
            cp = items[a + k0 + b] + 1
            ap[cp] += atr[b]
            row = cp - first
            part[row, 0] += bias[b]
            for q in range(n):
                part[row, items[a + q] + 1] += block[b, q]
    return total


def gram_new_under(pts, z, rows, support, lo, h, g, start, items, pstart, packed, first,
                   parts, atr_parts):
    """Add the rows ``p >= first`` of ``A'A`` (whole) and of ``A'z`` over points ``rows``.

    The normal equations of neurons appended at columns ``first`` on, for the points
    under them; no design matrix is stored (rows under appended neurons often cover most
    of a piece, and their design matrix takes tens of megabytes). The points are visited
    cell by cell of the evaluation grid (``start``, ``items``; ``pstart``, ``packed``:
    :func:`pack_cells`). All points of a cell share its neuron list, whose appended
    neurons are its last entries (the lists are in neuron order), so each point's
    Gaussians over the whole list are made in one vectorized pass (:func:`_exp_neg`, as
    the evaluation does: within 1e-12 relative of :func:`design_rows`' ``exp``; zero
    outside the truncated support) and each appended neuron's products with them are
    summed into a dense block of the cell, added into ``A'A`` once per cell (face map's
    main piece, 74,100 rows, 378 appended neurons, one thread: 18 ms, 45 ms point by
    point with scattered sums). The cells are cut in two fixed halves at the middle
    point, each summed in order into its own ``parts[h]`` (row ``p - first``) and
    ``atr_parts[h]``, the second on a pooled thread when numba may use two (a serial
    kernel on two threads: a ``prange`` over the halves took 2 s longer to compile); the
    caller adds the halves. The cut depends on the rows only, so the sums are the same
    bit for bit on one thread or two. Returns the sum of ``|z|`` over the rows.
    """
    order, count = _rows_by_cell(pts, rows, lo, h, g)
    ncell = g * g
    split = int(np.searchsorted(count[:ncell], len(rows) // 2, side="left"))
    args = (pts, z, order, count)
    tail = (support * support, start, items, pstart, packed, first)
    if get_num_threads() < 2:
        return (_gram_new_cells(*args, 0, split, *tail, parts[0], atr_parts[0])
                + _gram_new_cells(*args, split, ncell, *tail, parts[1], atr_parts[1]))
    second = _pool().submit(_gram_new_cells, *args, split, ncell, *tail, parts[1],
                            atr_parts[1])
    try:
        first_half = _gram_new_cells(*args, 0, split, *tail, parts[0], atr_parts[0])
    finally:
        second_half = second.result()
    return first_half + second_half


@njit(cache=True, nogil=True)
def gram_rows(indptr, cols, vals, z, w0, ata, atr):
    """Add design rows' normal equations into dense ``ata`` (upper triangle) and ``atr``.

    All columns (:func:`gram_new_under` sums those of appended neurons). Rows in CSR
    form ``(indptr, cols, vals)`` (:func:`design_rows`, not full). Adds ``A'A`` into the
    upper triangle of ``ata`` (entry ``[min(p, q), max(p, q)]``) and ``A'(z - A w0)``
    into ``atr``; returns the sum of ``|z - A w0|``. Rows are added one after another in
    order, so blocks of rows give the same sums bit for bit as the rows at once.
    """
    m = indptr.shape[0] - 1
    total = 0.0
    for i in range(m):
        a, b, r = _row_residual(indptr, cols, vals, z, w0, i)
        total += abs(r)
        for p in range(a, b):
            cp = cols[p]
            vp = vals[p]
            atr[cp] += vp * r
            for q in range(p, b):
                cq = cols[q]
                if cp <= cq:
                    ata[cp, cq] += vp * vals[q]
                else:
                    ata[cq, cp] += vp * vals[q]
    return total


@njit(cache=True, nogil=True)
def eliminate(minv, w, limit, budget, at_least=0):
    """Greedy backward elimination of least-squares unknowns, one at a time, exactly.

    ``minv``'s lower triangle holds the (n, n) inverse of a least-squares problem's
    (ridged) normal matrix ``M`` (the upper triangle is not read) and ``w`` is its
    solution (updated in place). Unknown 0 (the bias) always stays. Each step removes
    the unknown ``j`` whose removal raises the objective least, ``w_j^2 / (M^-1)_jj``,
    while that rise is under ``limit`` (whatever it is for the first ``at_least``
    removals) and the rises summed stay within ``budget``;
    the others are solved again by the
    Schur-complement update ``w -= (M^-1)_{:j} w_j / (M^-1)_jj``, and the inverse of the
    remaining matrix is ``M^-1`` minus the removed columns' rank-one terms, kept as rows
    of ``u`` (``O(n r)`` per step after ``r`` removals, never ``O(n^2)``). Ties go to
    the lowest index. Returns the removed indices, in order.
    """
    n = w.shape[0]
    diag = np.empty(n)
    for i in range(n):
        diag[i] = minv[i, i]
    alive = np.ones(n, dtype=np.bool_)
    alive[0] = False
    u = np.empty((max(n - 1, 0), n))
    dropped = np.empty(max(n - 1, 0), dtype=np.int64)
    c = np.empty(n)
    r = 0
    while r < n - 1:
        best = -1
        score = limit if r >= at_least else np.inf
        for j in range(1, n):
            if alive[j] and diag[j] > 0.0:
                s = w[j] * w[j] / diag[j]
                if s < score:
                    score = s
                    best = j
        if best < 0 or score > budget:
            break
        j = best
        alive[j] = False
        for i in range(j):
            c[i] = minv[j, i]
        for i in range(j, n):
            c[i] = minv[i, j]
        for t in range(r):
            f = u[t, j]
            if f != 0.0:
                for i in range(n):
                    c[i] -= f * u[t, i]
        d = c[j]
        if not d > 1e-14 * minv[j, j]:  # lost to rounding: keep the unknown
            continue
        f = w[j] / d
        g = 1.0 / np.sqrt(d)
        for i in range(n):
            w[i] -= f * c[i]
            diag[i] -= c[i] * c[i] / d
            u[r, i] = c[i] * g
        w[j] = 0.0
        dropped[r] = j
        r += 1
        budget -= score
    return dropped[:r].copy()


@njit(cache=True, parallel=True)
def _warm_threads(n):
    out = np.zeros(n)
    for i in prange(n):
        out[i] = i
    return out


@contextlib.contextmanager
def numba_threads(n: int):
    """Run the block with numba's parallel kernels on ``n`` threads (this thread only).

    For work beside other work (a second Python thread): on one thread its kernels
    start no team of their own to compete for the cores the other thread's use.
    """
    threads = get_num_threads()
    set_num_threads(max(1, min(n, threads)))
    try:
        yield
    finally:
        set_num_threads(threads)


def warm_threads() -> None:
    """Run a tiny parallel kernel: numba picks its threading layer on the first one.

    Not in a forked child, which runs no parallel kernel (:func:`_forked`).
    """
    if not _forked():
        _warm_threads(2)
