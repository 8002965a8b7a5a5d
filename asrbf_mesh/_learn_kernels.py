"""Compiled kernels of the adaptive sequential learning (private).

Everything here runs in numba ``nopython`` mode with ``cache=True``. The public
entry point is :func:`run_steps`; :mod:`asrbf_mesh._learn` owns the state arrays
and calls it chunk by chunk (to show progress and to grow the arrays).

Neurons live in *slots*. A pruned neuron frees its slot (``alive[s] = 0``) and
the slot goes on a free stack to be reused; the final network is the alive
slots in slot order. Two spatial structures index the alive slots, both as
doubly linked lists per grid cell:

* the *centre grid*: one uniform grid over the centre box, for the nearest
  neuron and the neighbourhood queries (ring search, exact);
* the *support levels*: a pyramid of grids over the unit square, level ``l``
  with ``G0 >> l`` cells per axis; a neuron is stored at the finest level whose
  cell is at least as large as its truncated support ``support * sigma``, so
  the neurons whose support contains ``x`` are all in the 3 x 3 cells around
  ``x`` at each level. Cell indices are clamped to the grid, which keeps the
  3 x 3 rule exact for points and centres outside the unit square.

Parameter block of a neuron: ``W[s] = (a, sigma, ux, uy)``. The EKF works on
``(a, log sigma, ux, uy)`` so widths stay positive; its covariance block
``P[s]`` is 4 x 4 (decoupled EKF), the bias ``a0`` has a scalar variance.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from . import _jit_cache  # noqa: F401 (first: where numba caches the kernels below)
from ._learn_cells import FEW_NEURONS, _cell_of, _d2_to, _link, _nearest_few, _unlink
from ._learn_heap import _heap_pop, _heap_push_checked

# --- indices into the configuration arrays -------------------------------------------------
# float configuration ``cf``
CF_E = 0  # E, local error threshold (criterion 2)
CF_EW = 1  # E_omega, windowed RMS threshold (criterion 3)
CF_DMAX = 2
CF_DMIN = 3
CF_GAMMA = 4
CF_PSI = 5
CF_PRUNE = 6  # P, contribution ratio threshold
CF_R = 7  # measurement noise variance
CF_Q = 8  # process noise (relative)
CF_P0 = 9  # prior variance (relative)
CF_SUPPORT = 10  # truncation radius in widths
CF_NBR = 11  # neighbourhood radius factor (times D)
CF_GD = 12  # gradient descent rate
CF_SMIN = 13  # width clamp
CF_SMAX = 14
CF_BOXLO = 15  # centre box
CF_BOXHI = 16
CF_LOCAL = 17  # a neuron wider than this many D takes a scaled NEKF step (0: off)
CF_SIZE = 18

# integer configuration ``ci``
CI_WINDOW = 0  # omega, RMS window
CI_PWIN = 1  # pruning window
CI_PRUNE = 2  # 0 none, 1 literal (paper), 2 support
CI_UPDATE = 3  # 0 nekf, 1 nekf-neighbourhood, 2 gekf, 3 gd
CI_DECAY = 4  # 0 observation index, 1 neuron count (eq. 4 literally)
CI_MAXNB = 5  # neighbourhood cap
CI_MAXK = 6  # neuron cap
CI_LOGSTRIDE = 7
CI_GC = 8  # centre grid cells per axis
CI_G0 = 9  # finest support level cells per axis
CI_NLEV = 10
CI_SIZE = 11

PRUNE_NONE, PRUNE_LITERAL, PRUNE_SUPPORT = 0, 1, 2
UPDATE_NEKF, UPDATE_NEKF_NB, UPDATE_GEKF, UPDATE_GD = 0, 1, 2, 3
DECAY_OBSERVATION, DECAY_NEURONS = 0, 1

# float state ``fs``
FS_A0 = 0
FS_P00 = 1
FS_WSUM = 2  # running sum of squared residuals in the window
FS_SIZE = 3

# int state ``st``
ST_T = 0  # global step counter (observations consumed)
ST_K = 1  # alive neurons
ST_SLOTS = 2  # high-water mark of used slots
ST_NFREE = 3  # free stack size
ST_HEAP = 4  # heap size
ST_ADDED = 5
ST_PRUNED = 6
ST_RESET = 7  # covariance blocks reset by the numerical guard
ST_DIVERGED = 8  # neurons removed by the numerical guard
ST_NLOG = 9
ST_WPOS = 10
ST_WCOUNT = 11
ST_CAPPED = 12  # insertions the neuron cap (max_neurons) refused
ST_SIZE = 13

# status returned by run_steps
DONE, NEED_SLOTS, NEED_LOG = 0, 1, 2


# --- the grids' cells ----------------------------------------------------------------------


@njit(cache=True, inline="always")
def _centre_cell(ux, uy, cf, ci):
    gc = ci[CI_GC]
    lo = cf[CF_BOXLO]
    h = (cf[CF_BOXHI] - lo) / gc
    return _cell_of(uy, lo, h, gc) * gc + _cell_of(ux, lo, h, gc)


@njit(cache=True, inline="always")
def _level_cell(ux, uy, sigma, cf, ci, lev_off):
    """Global cell index of a neuron in the support pyramid, and its level."""
    s = cf[CF_SUPPORT] * sigma
    nlev = ci[CI_NLEV]
    g = ci[CI_G0]
    lev = 0
    while lev < nlev - 1 and 1.0 / g < s:
        lev += 1
        g = g >> 1
    ix = _cell_of(ux, 0.0, 1.0 / g, g)
    iy = _cell_of(uy, 0.0, 1.0 / g, g)
    return lev_off[lev] + iy * g + ix, lev


@njit(cache=True)
def _index_neuron(s, W, cf, ci, c_head, c_nxt, c_prv, c_cell, l_head, l_nxt, l_prv, l_cell,
                  l_lev, lev_off, lev_count):
    _link(c_head, c_nxt, c_prv, c_cell, s, _centre_cell(W[s, 2], W[s, 3], cf, ci))
    c, lev = _level_cell(W[s, 2], W[s, 3], W[s, 1], cf, ci, lev_off)
    _link(l_head, l_nxt, l_prv, l_cell, s, c)
    l_lev[s] = lev
    lev_count[lev] += 1


@njit(cache=True)
def _unindex_neuron(s, c_head, c_nxt, c_prv, c_cell, l_head, l_nxt, l_prv, l_cell, l_lev,
                    lev_count):
    _unlink(c_head, c_nxt, c_prv, c_cell, s)
    _unlink(l_head, l_nxt, l_prv, l_cell, s)
    lev_count[l_lev[s]] -= 1


@njit(cache=True, inline="always")
def _reindex_neuron(s, W, cf, ci, c_head, c_nxt, c_prv, c_cell, l_head, l_nxt, l_prv, l_cell,
                    l_lev, lev_off, lev_count):
    """Move a neuron whose centre or width changed to its new cells (if they changed)."""
    c = _centre_cell(W[s, 2], W[s, 3], cf, ci)
    if c != c_cell[s]:
        _unlink(c_head, c_nxt, c_prv, c_cell, s)
        _link(c_head, c_nxt, c_prv, c_cell, s, c)
    c, lev = _level_cell(W[s, 2], W[s, 3], W[s, 1], cf, ci, lev_off)
    if c != l_cell[s]:
        _unlink(l_head, l_nxt, l_prv, l_cell, s)
        _link(l_head, l_nxt, l_prv, l_cell, s, c)
        lev_count[l_lev[s]] -= 1
        lev_count[lev] += 1
        l_lev[s] = lev


# --- queries ------------------------------------------------------------------------------


@njit(cache=True, inline="always")
def _support_query(x, y, W, cf, ci, l_head, l_nxt, lev_off, lev_count, out_idx, out_phi,
                   out_d2, out_pi):
    """Evaluate the network at (x, y): f without a0, sum |Pi_k|, and the support list.

    Returns ``(f, sum_abs, m, near, near_d2)``; ``out_*[:m]`` hold slot, phi, squared
    distance and |Pi_k| = |a_k phi_k| of every neuron whose truncated support contains
    the point. ``near`` (-1 if none) is the closest centre among the neurons looked at,
    ``near_d2`` its squared distance: every neuron stored at level ``l`` whose centre lies
    within that level's cell size of the point is looked at, so when ``near_d2`` is below
    the finest cell size squared, ``near`` is the nearest centre of all (see
    :func:`run_steps`).
    """
    supp2 = cf[CF_SUPPORT] * cf[CF_SUPPORT]
    # pass 1 walks the cells' lists and keeps the neurons whose support holds the point,
    # without a branch (a candidate is written, and kept by counting it): most neurons in
    # the 3 x 3 cells are outside their support, and the kept ones come at random, a
    # mispredicted branch each; pass 2 evaluates the kept ones in the same order
    m = 0
    best = np.inf
    bk = -1
    g = ci[CI_G0]
    for lev in range(ci[CI_NLEV]):
        if lev_count[lev] > 0:
            h = 1.0 / g
            ix = _cell_of(x, 0.0, h, g)
            iy = _cell_of(y, 0.0, h, g)
            for jy in range(max(iy - 1, 0), min(iy + 2, g)):
                for jx in range(max(ix - 1, 0), min(ix + 2, g)):
                    s = l_head[lev_off[lev] + jy * g + jx]
                    while s >= 0:
                        dx = x - W[s, 2]
                        dy = y - W[s, 3]
                        d2 = dx * dx + dy * dy
                        sig = W[s, 1]
                        out_idx[m] = s
                        out_d2[m] = d2
                        m += d2 < supp2 * sig * sig
                        if d2 < best:
                            best = d2
                            bk = s
                        s = l_nxt[s]
        g = g >> 1
    f = 0.0
    sabs = 0.0
    for u in range(m):
        s = out_idx[u]
        sig = W[s, 1]
        phi = np.exp(-out_d2[u] / (sig * sig))
        p = W[s, 0] * phi
        f += p
        sabs += abs(p)
        out_phi[u] = phi
        out_pi[u] = abs(p)
    return f, sabs, m, bk, best


@njit(cache=True, inline="always")
def _nearest(x, y, W, cf, ci, c_head, c_nxt):
    """Exact nearest alive centre by ring search; returns (slot, distance) or (-1, inf)."""
    gc = ci[CI_GC]
    lo = cf[CF_BOXLO]
    h = (cf[CF_BOXHI] - lo) / gc
    cx = _cell_of(x, lo, h, gc)
    cy = _cell_of(y, lo, h, gc)
    best = np.inf
    bk = -1
    for r in range(gc):
        for jy in range(cy - r, cy + r + 1):
            if jy < 0 or jy >= gc:
                continue
            edge = jy == cy - r or jy == cy + r
            step = 1 if edge else 2 * r
            jx = cx - r
            while jx <= cx + r:
                if 0 <= jx < gc:
                    s = c_head[jy * gc + jx]
                    while s >= 0:
                        d2 = _d2_to(x, y, W, s)
                        if d2 < best:
                            best = d2
                            bk = s
                        s = c_nxt[s]
                if step == 0:
                    break
                jx += step
        if bk >= 0 and np.sqrt(best) <= r * h:
            break
    return bk, np.sqrt(best)


@njit(cache=True, inline="always")
def _within(x, y, radius, W, cf, ci, c_head, c_nxt, out_idx, out_d2):
    """All alive centres within ``radius`` of (x, y); returns their count."""
    gc = ci[CI_GC]
    lo = cf[CF_BOXLO]
    h = (cf[CF_BOXHI] - lo) / gc
    r2 = radius * radius
    x0 = _cell_of(x - radius, lo, h, gc)
    x1 = _cell_of(x + radius, lo, h, gc)
    y0 = _cell_of(y - radius, lo, h, gc)
    y1 = _cell_of(y + radius, lo, h, gc)
    m = 0
    for jy in range(y0, y1 + 1):
        for jx in range(x0, x1 + 1):
            s = c_head[jy * gc + jx]
            while s >= 0:
                dx = x - W[s, 2]
                dy = y - W[s, 3]
                d2 = dx * dx + dy * dy
                if d2 <= r2:
                    out_idx[m] = s
                    out_d2[m] = d2
                    m += 1
                s = c_nxt[s]
    return m


# --- EKF helpers --------------------------------------------------------------------------


@njit(cache=True, inline="always")
def _grad(W, s, x, y, phi, d2, out):
    """Gradient of f at (x, y) w.r.t. (a, log sigma, ux, uy) of neuron ``s``."""
    a = W[s, 0]
    sig = W[s, 1]
    inv2 = 1.0 / (sig * sig)
    ap = a * phi
    out[0] = phi
    out[1] = 2.0 * ap * d2 * inv2
    out[2] = 2.0 * ap * (x - W[s, 2]) * inv2
    out[3] = 2.0 * ap * (y - W[s, 3]) * inv2


@njit(cache=True)
def _reset_block(P, s, sig, p0):
    for i in range(4):
        for j in range(4):
            P[s, i, j] = 0.0
    P[s, 0, 0] = p0
    P[s, 1, 1] = p0
    P[s, 2, 2] = p0 * sig * sig
    P[s, 3, 3] = p0 * sig * sig


@njit(cache=True, inline="always")
def _apply_step(W, s, dw, cf):
    """Apply a parameter step in (a, log sigma, ux, uy) with the width and box guards."""
    W[s, 0] += dw[0]
    ds = dw[1]
    if ds > 1.0:
        ds = 1.0
    elif ds < -1.0:
        ds = -1.0
    sig = W[s, 1] * np.exp(ds)
    W[s, 1] = min(max(sig, cf[CF_SMIN]), cf[CF_SMAX])
    W[s, 2] = min(max(W[s, 2] + dw[2], cf[CF_BOXLO]), cf[CF_BOXHI])
    W[s, 3] = min(max(W[s, 3] + dw[3], cf[CF_BOXLO]), cf[CF_BOXHI])


@njit(cache=True, inline="always")
def _block_finite(W, P, s):
    for i in range(4):
        if not np.isfinite(W[s, i]):
            return False
        for j in range(4):
            if not np.isfinite(P[s, i, j]):
                return False
    return True


@njit(cache=True, inline="always")
def _block_healthy(P, s, limit):
    """Diagonal positive and bounded (covariance of a well-behaved neuron)."""
    for i in range(4):
        d = P[s, i, i]
        if not (d > 0.0) or d > limit:
            return False
    return True


# --- neuron lifecycle ---------------------------------------------------------------------


@njit(cache=True)
def _remove(s, alive, gen, free, st, c_head, c_nxt, c_prv, c_cell, l_head, l_nxt, l_prv, l_cell,
            l_lev, lev_count, Pg, nparam_full):
    _unindex_neuron(s, c_head, c_nxt, c_prv, c_cell, l_head, l_nxt, l_prv, l_cell, l_lev,
                    lev_count)
    alive[s] = 0
    gen[s] += 1
    free[st[ST_NFREE]] = s
    st[ST_NFREE] += 1
    st[ST_K] -= 1
    if nparam_full > 0:  # GEKF: forget the slot's covariance rows and columns
        b = 1 + 4 * s
        for i in range(4):
            for j in range(nparam_full):
                Pg[b + i, j] = 0.0
                Pg[j, b + i] = 0.0


# --- the learning loop --------------------------------------------------------------------


def _make_run_steps(update: int, prune_mode: int, decay: int):
    """Compile-on-demand :func:`run_steps` for one updater, pruning rule and decay.

    The three choices are constants of the closure, so numba prunes the branches of the
    others before it compiles: a command compiles only the path it runs (the default
    path compiles in about 5 s where all of them took 8 s), and each variant is cached on
    its own (numba keys a closure's cache entry by its constants).
    """

    @njit(cache=True, nogil=True)
    def run_steps(X, Z, order, t_end, cf, ci, fs, st, W, P, alive, gen, free, last_active, miss,
                  hk, hs, hg, c_head, c_nxt, c_prv, c_cell, l_head, l_nxt, l_prv, l_cell, l_lev,
                  lev_off, lev_count, wbuf, Pg, log_t, log_k, log_rms, log_sig, log_amp, start):
        """Run Algorithm 1 on observations ``order[start:]`` until ``st[ST_T] == t_end``.

        Parameters are the state arrays owned by ``asrbf_mesh._learn._State``. Returns
        ``(status, position)``: ``DONE`` when the chunk is consumed, ``NEED_SLOTS`` when
        every slot is used and the next step may add a neuron (grow ``W`` etc. and call
        again from ``position``: the step has not started), ``NEED_LOG`` when the log arrays
        are full.
        """
        cap = W.shape[0]
        nparam_full = Pg.shape[0] if update == UPDATE_GEKF else 0
        sup_idx = np.empty(cap, np.int64)
        sup_phi = np.empty(cap)
        sup_d2 = np.empty(cap)
        sup_pi = np.empty(cap)
        nb_idx = np.empty(cap, np.int64)
        nb_d2 = np.empty(cap)
        nb_phi = np.empty(cap)
        g = np.empty(4)
        pb = np.empty(4)
        dw = np.empty(4)
        gk_idx = np.empty(cap, np.int64)  # GEKF: alive slots
        gb = np.empty(nparam_full if nparam_full > 0 else 1)
        gpb = np.empty(nparam_full if nparam_full > 0 else 1)

        E = cf[CF_E]
        EW = cf[CF_EW]
        R = cf[CF_R]
        q = cf[CF_Q]
        p0 = cf[CF_P0]
        window = ci[CI_WINDOW]
        pwin = ci[CI_PWIN]
        stride = ci[CI_LOGSTRIDE]
        cov_limit = 1e6 * p0
        near_safe = (0.999 / ci[CI_G0]) ** 2  # below the finest support cell, squared

        pos = start
        n_order = order.shape[0]
        at_floor, D = False, cf[CF_DMAX]  # separation D of eq. (4), once at D_min no more pow
        while pos < n_order and st[ST_T] < t_end:
            t = st[ST_T]
            # a step that may add a neuron needs a free slot: ask for more slots before the
            # step changes anything (its residual in the RMS window, a log row), so that the
            # step, run again after the slots grew, counts its observation once
            if st[ST_NFREE] == 0 and st[ST_SLOTS] >= cap and st[ST_K] < ci[CI_MAXK]:
                return NEED_SLOTS, pos
            if stride > 0 and t % stride == 0:
                nl = st[ST_NLOG]
                if nl >= log_t.shape[0]:
                    return NEED_LOG, pos
                ssum = 0.0
                asum = 0.0
                for s in range(st[ST_SLOTS]):
                    if alive[s]:
                        ssum += W[s, 1]
                        asum += abs(W[s, 0])
                k = st[ST_K]
                log_t[nl] = t
                log_k[nl] = k
                log_rms[nl] = np.sqrt(fs[FS_WSUM] / max(st[ST_WCOUNT], 1))
                log_sig[nl] = ssum / k if k > 0 else 0.0  # no neuron yet: 0, never NaN
                log_amp[nl] = asum / k if k > 0 else 0.0
                st[ST_NLOG] = nl + 1

            i = order[pos]
            x = X[i, 0]
            y = X[i, 1]
            z = Z[i]

            # Stage 1: network output, residual (r = z - f: docs/design.md), windowed RMS.
            # sup_pi: |Pi_k| of this observation's output, before the update (pruning)
            fk, sabs, m, near, near_d2 = _support_query(x, y, W, cf, ci, l_head, l_nxt, lev_off,
                                                        lev_count, sup_idx, sup_phi, sup_d2,
                                                        sup_pi)
            r = z - (fs[FS_A0] + fk)
            wp = st[ST_WPOS]
            if st[ST_WCOUNT] == window:
                fs[FS_WSUM] -= wbuf[wp]
            else:
                st[ST_WCOUNT] += 1
            wbuf[wp] = r * r
            fs[FS_WSUM] += r * r
            st[ST_WPOS] = (wp + 1) % window
            if wp == window - 1:  # refresh the running sum once per window: no drift
                acc = 0.0
                for j in range(st[ST_WCOUNT]):
                    acc += wbuf[j]
                fs[FS_WSUM] = acc
            rms = np.sqrt(max(fs[FS_WSUM], 0.0) / st[ST_WCOUNT])

            if decay == DECAY_OBSERVATION:
                if not at_floor:
                    D = max(cf[CF_DMAX] * cf[CF_GAMMA] ** t, cf[CF_DMIN])
                    at_floor = D == cf[CF_DMIN]
            else:
                D = max(cf[CF_DMAX] * cf[CF_GAMMA] ** st[ST_K], cf[CF_DMIN])

            # the support query saw every centre within the finest level's cell of x: a centre
            # it saw closer than that is the nearest of all (the ring search only otherwise)
            if near >= 0 and near_d2 < near_safe:
                dist = np.sqrt(near_d2)
            elif st[ST_K] == 0:  # no centre: the ring search visits every cell (a Kinect
                near, dist = -1, np.inf  # piece with no neuron: 43,012 steps in 2.4 s)
            elif st[ST_K] <= FEW_NEURONS:
                near, near_d2, ties = _nearest_few(x, y, W, alive, st[ST_SLOTS])
                if ties == 0:
                    dist = np.sqrt(near_d2)
                else:
                    near, dist = _nearest(x, y, W, cf, ci, c_head, c_nxt)
            else:
                near, dist = _nearest(x, y, W, cf, ci, c_head, c_nxt)
            grow = dist > D and abs(r) > E and rms > EW
            if grow and st[ST_K] >= ci[CI_MAXK]:
                st[ST_CAPPED] += 1
                grow = False
            if grow:
                if st[ST_NFREE] > 0:
                    st[ST_NFREE] -= 1
                    s = free[st[ST_NFREE]]
                else:  # a free slot exists: checked at the start of the step
                    s = st[ST_SLOTS]
                    st[ST_SLOTS] += 1
                sig = cf[CF_PSI] * (dist if near >= 0 else D)
                sig = min(max(sig, cf[CF_SMIN]), cf[CF_SMAX])
                W[s, 0] = r
                W[s, 1] = sig
                W[s, 2] = x
                W[s, 3] = y
                _reset_block(P, s, sig, p0)
                alive[s] = 1
                gen[s] += 1
                last_active[s] = t
                miss[s] = 0
                _index_neuron(s, W, cf, ci, c_head, c_nxt, c_prv, c_cell, l_head, l_nxt, l_prv,
                              l_cell, l_lev, lev_off, lev_count)
                if prune_mode == PRUNE_LITERAL:
                    st[ST_HEAP] = _heap_push_checked(hk, hs, hg, st[ST_HEAP], t + pwin, s, gen[s],
                                                     alive, gen)
                if nparam_full > 0:
                    b = 1 + 4 * s
                    for a_ in range(4):
                        for j in range(nparam_full):
                            Pg[b + a_, j] = 0.0
                            Pg[j, b + a_] = 0.0
                    Pg[b, b] = p0
                    Pg[b + 1, b + 1] = p0
                    Pg[b + 2, b + 2] = p0 * sig * sig
                    Pg[b + 3, b + 3] = p0 * sig * sig
                st[ST_K] += 1
                st[ST_ADDED] += 1
            elif update == UPDATE_NEKF or update == UPDATE_NEKF_NB:
                # Stage 2: NEKF on the nearest neuron (K' = 1) or the neighbourhood, plus a0.
                if update == UPDATE_NEKF:
                    nsel = 0
                    if near >= 0:
                        nb_idx[0] = near
                        nsel = 1
                else:
                    nsel = _within(x, y, cf[CF_NBR] * D, W, cf, ci, c_head, c_nxt, nb_idx, nb_d2)
                    if nsel > ci[CI_MAXNB]:  # keep the closest (partial selection sort)
                        for a_ in range(ci[CI_MAXNB]):
                            best = a_
                            for b_ in range(a_ + 1, nsel):
                                if nb_d2[b_] < nb_d2[best] or (
                                        nb_d2[b_] == nb_d2[best] and nb_idx[b_] < nb_idx[best]):
                                    best = b_
                            nb_idx[a_], nb_idx[best] = nb_idx[best], nb_idx[a_]
                            nb_d2[a_], nb_d2[best] = nb_d2[best], nb_d2[a_]
                        nsel = ci[CI_MAXNB]
                    if nsel == 0 and near >= 0:
                        nb_idx[0] = near
                        nsel = 1
                # innovation variance S = R + B' P B over the selected blocks
                S = R + fs[FS_P00]
                for j in range(nsel):
                    s = nb_idx[j]
                    phi = 0.0
                    d2 = 0.0
                    for u in range(m):
                        if sup_idx[u] == s:
                            phi = sup_phi[u]
                            d2 = sup_d2[u]
                            break
                    sup_phi_sel = phi  # zero outside the truncated support
                    if sup_phi_sel == 0.0:
                        nb_d2[j] = -1.0  # mark: no gradient
                        continue
                    nb_d2[j] = d2
                    nb_phi[j] = phi
                    _grad(W, s, x, y, phi, d2, g)
                    for a_ in range(4):
                        acc = 0.0
                        for b_ in range(4):
                            acc += P[s, a_, b_] * g[b_]
                        S += g[a_] * acc
                for j in range(nsel):
                    s = nb_idx[j]
                    d2 = nb_d2[j]
                    if d2 < 0.0:
                        continue
                    phi = nb_phi[j]  # W[s] is unchanged since the support query
                    _grad(W, s, x, y, phi, d2, g)
                    for a_ in range(4):
                        acc = 0.0
                        for b_ in range(4):
                            acc += P[s, a_, b_] * g[b_]
                        pb[a_] = acc
                    # a local step: a neuron far wider than the separation D (the
                    # observation's neighbourhood) moves in proportion (local_width)
                    scale = 1.0
                    if cf[CF_LOCAL] > 0.0 and W[s, 1] > cf[CF_LOCAL] * D:
                        scale = cf[CF_LOCAL] * D / W[s, 1]
                    for a_ in range(4):
                        dw[a_] = scale * pb[a_] * r / S
                    _apply_step(W, s, dw, cf)
                    sig = W[s, 1]
                    for a_ in range(4):
                        for b_ in range(a_, 4):
                            v = P[s, a_, b_] - pb[a_] * pb[b_] / S
                            P[s, a_, b_] = v
                            P[s, b_, a_] = v
                    P[s, 0, 0] += q * p0
                    P[s, 1, 1] += q * p0
                    P[s, 2, 2] += q * p0 * sig * sig
                    P[s, 3, 3] += q * p0 * sig * sig
                    if not _block_finite(W, P, s):
                        st[ST_DIVERGED] += 1
                        _remove(s, alive, gen, free, st, c_head, c_nxt, c_prv, c_cell, l_head,
                                l_nxt, l_prv, l_cell, l_lev, lev_count, Pg, nparam_full)
                        continue
                    if not _block_healthy(P, s, cov_limit):
                        st[ST_RESET] += 1
                        _reset_block(P, s, sig, p0)
                    _reindex_neuron(s, W, cf, ci, c_head, c_nxt, c_prv, c_cell, l_head, l_nxt,
                                    l_prv, l_cell, l_lev, lev_off, lev_count)
                p00 = fs[FS_P00]
                fs[FS_A0] += p00 * r / S
                fs[FS_P00] = p00 - p00 * p00 / S + q * p0
            elif update == UPDATE_GD:
                rate = cf[CF_GD]
                for u in range(m):
                    s = sup_idx[u]
                    if alive[s] == 0:
                        continue
                    _grad(W, s, x, y, sup_phi[u], sup_d2[u], g)
                    sig = W[s, 1]
                    dw[0] = rate * g[0] * r
                    dw[1] = rate * g[1] * r
                    dw[2] = rate * sig * sig * g[2] * r
                    dw[3] = rate * sig * sig * g[3] * r
                    _apply_step(W, s, dw, cf)
                    _reindex_neuron(s, W, cf, ci, c_head, c_nxt, c_prv, c_cell, l_head, l_nxt,
                                    l_prv, l_cell, l_lev, lev_off, lev_count)
                fs[FS_A0] += rate * r
            else:
                # GEKF: one covariance over a0 and every alive neuron.
                na = 0
                for s in range(st[ST_SLOTS]):
                    if alive[s]:
                        gk_idx[na] = s
                        na += 1
                for j in range(nparam_full):
                    gb[j] = 0.0
                gb[0] = 1.0
                for u in range(m):
                    s = sup_idx[u]
                    _grad(W, s, x, y, sup_phi[u], sup_d2[u], g)
                    for a_ in range(4):
                        gb[1 + 4 * s + a_] = g[a_]
                # pb = P b, restricted to live rows (dead rows are zero)
                S = R
                for jj in range(na + 1):
                    for a_ in range(1 if jj == 0 else 4):
                        row = 0 if jj == 0 else 1 + 4 * gk_idx[jj - 1] + a_
                        acc = Pg[row, 0] * gb[0]
                        for u in range(m):
                            cb = 1 + 4 * sup_idx[u]
                            for b_ in range(4):
                                acc += Pg[row, cb + b_] * gb[cb + b_]
                        gpb[row] = acc
                        S += gb[row] * acc
                fs[FS_A0] += gpb[0] * r / S
                for jj in range(na + 1):
                    for a_ in range(1 if jj == 0 else 4):
                        row = 0 if jj == 0 else 1 + 4 * gk_idx[jj - 1] + a_
                        for kk in range(na + 1):
                            for b_ in range(1 if kk == 0 else 4):
                                col = 0 if kk == 0 else 1 + 4 * gk_idx[kk - 1] + b_
                                Pg[row, col] -= gpb[row] * gpb[col] / S
                Pg[0, 0] += q * p0
                for jj in range(na):
                    s = gk_idx[jj]
                    b = 1 + 4 * s
                    for a_ in range(4):
                        dw[a_] = gpb[b + a_] * r / S
                    _apply_step(W, s, dw, cf)
                    sig = W[s, 1]
                    Pg[b, b] += q * p0
                    Pg[b + 1, b + 1] += q * p0
                    Pg[b + 2, b + 2] += q * p0 * sig * sig
                    Pg[b + 3, b + 3] += q * p0 * sig * sig
                    ok = True
                    for a_ in range(4):
                        if not np.isfinite(W[s, a_]) or not (Pg[b + a_, b + a_] > 0.0):
                            ok = False
                    if not ok:
                        st[ST_DIVERGED] += 1
                        _remove(s, alive, gen, free, st, c_head, c_nxt, c_prv, c_cell, l_head,
                                l_nxt, l_prv, l_cell, l_lev, lev_count, Pg, nparam_full)
                        continue
                    _reindex_neuron(s, W, cf, ci, c_head, c_nxt, c_prv, c_cell, l_head, l_nxt,
                                    l_prv, l_cell, l_lev, lev_off, lev_count)

            # Stage 3: pruning by contribution ratio r_k = |Pi_k| / sum |Pi_j| (eqs. 11-13),
            # both of the output of Stage 1 (before the update: numerator and denominator of
            # the same network)
            if prune_mode == PRUNE_LITERAL:
                thr = cf[CF_PRUNE] * sabs
                for u in range(m):
                    s = sup_idx[u]
                    if alive[s] and sup_pi[u] >= thr:
                        last_active[s] = t
                while st[ST_HEAP] > 0 and hk[0] <= t:
                    s = hs[0]
                    gg = hg[0]
                    st[ST_HEAP] = _heap_pop(hk, hs, hg, st[ST_HEAP])
                    if alive[s] == 0 or gen[s] != gg:
                        continue
                    due = last_active[s] + pwin
                    if due > t:
                        st[ST_HEAP] = _heap_push_checked(hk, hs, hg, st[ST_HEAP], due, s, gg,
                                                         alive, gen)
                    else:
                        st[ST_PRUNED] += 1
                        _remove(s, alive, gen, free, st, c_head, c_nxt, c_prv, c_cell, l_head,
                                l_nxt, l_prv, l_cell, l_lev, lev_count, Pg, nparam_full)
            elif prune_mode == PRUNE_SUPPORT:
                thr = cf[CF_PRUNE] * sabs
                for u in range(m):
                    s = sup_idx[u]
                    ms = (miss[s] + 1) * (sup_pi[u] < thr)  # no branch; reset on slot reuse
                    miss[s] = ms
                    if ms >= pwin and alive[s] != 0:
                        st[ST_PRUNED] += 1
                        _remove(s, alive, gen, free, st, c_head, c_nxt, c_prv, c_cell,
                                l_head, l_nxt, l_prv, l_cell, l_lev, lev_count, Pg, nparam_full)
            st[ST_T] = t + 1
            pos += 1
        return DONE, pos

    return run_steps


_RUN_STEPS: dict = {}


def run_steps_for(update: int, prune_mode: int, decay: int):
    """Return the learning kernel for ``(update, prune_mode, decay)`` (``UPDATE_*``, ...)."""
    key = (int(update), int(prune_mode), int(decay))
    kernel = _RUN_STEPS.get(key)
    if kernel is None:
        kernel = _RUN_STEPS[key] = _make_run_steps(*key)
    return kernel


#: The default path's kernel (NEKF on the nearest neuron, support pruning, decay by
#: observation index).
run_steps = run_steps_for(UPDATE_NEKF, PRUNE_SUPPORT, DECAY_OBSERVATION)


@njit(cache=True)
def residuals(X, Z, W, alive, a0, cf, ci, l_head, l_nxt, lev_off, lev_count):
    """Residuals z - f(x) of every point under the current (learning-time) network."""
    cap = W.shape[0]
    sup_idx = np.empty(cap, np.int64)
    sup_phi = np.empty(cap)
    sup_d2 = np.empty(cap)
    sup_pi = np.empty(cap)
    out = np.empty(X.shape[0])
    for i in range(X.shape[0]):
        f, _, _, _, _ = _support_query(X[i, 0], X[i, 1], W, cf, ci, l_head, l_nxt, lev_off,
                                 lev_count, sup_idx, sup_phi, sup_d2, sup_pi)
        out[i] = Z[i] - a0 - f
    return out
