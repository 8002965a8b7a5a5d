"""The pruning deadline heap of the sequential learning (private, compiled).

A binary min-heap of ``(key, slot, generation)`` in three parallel arrays, ordered by
key then slot: the literal pruning rule of :mod:`asrbf_mesh._learn_kernels` keeps one
deadline per neuron here and checks only the due ones (never all K neurons a step).
Entries of removed neurons go stale (their generation no longer matches) and are
dropped when the arrays fill up.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from . import _jit_cache  # noqa: F401 (first: where numba caches the kernels below)

__all__ = ["_heap_pop", "_heap_push", "_heap_push_checked"]


@njit(cache=True)
def _heap_push(hk, hs, hg, size, key, slot, gen):
    i = size
    hk[i] = key
    hs[i] = slot
    hg[i] = gen
    while i > 0:
        p = (i - 1) >> 1
        if hk[p] < hk[i] or (hk[p] == hk[i] and hs[p] <= hs[i]):
            break
        hk[p], hk[i] = hk[i], hk[p]
        hs[p], hs[i] = hs[i], hs[p]
        hg[p], hg[i] = hg[i], hg[p]
        i = p
    return size + 1


@njit(cache=True)
def _heap_pop(hk, hs, hg, size):
    size -= 1
    hk[0] = hk[size]
    hs[0] = hs[size]
    hg[0] = hg[size]
    i = 0
    while True:
        lc = 2 * i + 1
        if lc >= size:
            break
        c = lc
        rc = lc + 1
        if rc < size and (hk[rc] < hk[lc] or (hk[rc] == hk[lc] and hs[rc] < hs[lc])):
            c = rc
        if hk[i] < hk[c] or (hk[i] == hk[c] and hs[i] <= hs[c]):
            break
        hk[c], hk[i] = hk[i], hk[c]
        hs[c], hs[i] = hs[i], hs[c]
        hg[c], hg[i] = hg[i], hg[c]
        i = c
    return size


@njit(cache=True)
def _heap_push_checked(hk, hs, hg, size, key, slot, gen, alive, gens):
    """Push; when the arrays are full, first drop the stale entries of removed neurons."""
    if size == hk.shape[0]:
        n = 0
        for i in range(size):
            if alive[hs[i]] and gens[hs[i]] == hg[i]:
                hk[n] = hk[i]
                hs[n] = hs[i]
                hg[n] = hg[i]
                n += 1
        size = np.int64(0)  # int64, not a literal 0: one compiled version of _heap_push
        for i in range(n):  # re-heapify by pushing in place
            size = _heap_push(hk, hs, hg, size, hk[i], hs[i], hg[i])
    return _heap_push(hk, hs, hg, size, key, slot, gen)
