"""The compiled spatial queries checked against brute force.

* learning-time structures of ``asrbf_mesh._learn_kernels``: the centre grid
  (``_nearest``, ``_within``), the support pyramid (``_support_query``), insertion,
  removal and re-indexing of neurons, and the pruning deadline heap;
* the static evaluation grid of ``asrbf_mesh._network_kernels`` behind
  ``Network.evaluate`` / ``Network.gradient``.
"""

from __future__ import annotations

import heapq

import numpy as np
import pytest

from asrbf_mesh import _learn_heap as lh
from asrbf_mesh import _learn_kernels as lk
from asrbf_mesh import _network_kernels as nk
from asrbf_mesh._config import FitConfig
from asrbf_mesh._frame import Frame, to_height_field
from asrbf_mesh._learn import _State
from asrbf_mesh._network import Network

BOX = (-0.25, 1.25)  # the centre box of learning


# ------------------------------------------------------------------ learning-time state


class Neurons:
    """A learning state with hand-placed neurons and thin wrappers of the kernels."""

    def __init__(self, d_min: float, cfg: FitConfig | None = None, steps: int = 1000) -> None:
        self.cfg = cfg = cfg or FitConfig()
        self.s = _State(cfg, d_min, steps, steps, cfg.window, cfg.prune_window or cfg.window)
        self.near_shortcuts = 0  # support queries whose closest centre was the nearest

    # -- mutation
    def add(self, a: float, sigma: float, ux: float, uy: float) -> int:
        s = self.s
        slot = int(s.st[lk.ST_SLOTS])
        assert slot < s.cap
        s.W[slot] = (a, sigma, ux, uy)
        s.alive[slot] = 1
        s.st[lk.ST_SLOTS] += 1
        s.st[lk.ST_K] += 1
        lk._index_neuron(slot, s.W, s.cf, s.ci, s.c_head, s.c_nxt, s.c_prv, s.c_cell, s.l_head,
                         s.l_nxt, s.l_prv, s.l_cell, s.l_lev, s.lev_off, s.lev_count)
        return slot

    def remove(self, slot: int) -> None:
        s = self.s
        lk._remove(slot, s.alive, s.gen, s.free, s.st, s.c_head, s.c_nxt, s.c_prv, s.c_cell,
                   s.l_head, s.l_nxt, s.l_prv, s.l_cell, s.l_lev, s.lev_count, s.Pg, 0)

    def move(self, slot: int, sigma: float, ux: float, uy: float) -> None:
        s = self.s
        s.W[slot, 1:] = (sigma, ux, uy)
        lk._reindex_neuron(slot, s.W, s.cf, s.ci, s.c_head, s.c_nxt, s.c_prv, s.c_cell,
                           s.l_head, s.l_nxt, s.l_prv, s.l_cell, s.l_lev, s.lev_off,
                           s.lev_count)

    # -- queries
    def support_query(self, x: float, y: float):
        s = self.s
        idx = np.empty(s.cap, np.int64)
        phi = np.empty(s.cap)
        d2 = np.empty(s.cap)
        pi = np.empty(s.cap)
        f, sabs, m, near, near_d2 = lk._support_query(x, y, s.W, s.cf, s.ci, s.l_head,
                                                      s.l_nxt, s.lev_off, s.lev_count,
                                                      idx, phi, d2, pi)
        # |Pi_k| = |a_k phi_k| of every neuron in the list, summing to sum |Pi|
        np.testing.assert_array_equal(pi[:m], np.abs(s.W[idx[:m], 0] * phi[:m]))
        # the closest centre it saw: the nearest of all when closer than the finest cell
        # (run_steps then skips the ring search)
        k, dist2 = self.brute_distances(x, y)
        if near >= 0 and near_d2 < (0.999 / s.ci[lk.CI_G0]) ** 2:
            self.near_shortcuts += 1
            assert near_d2 == dist2.min() and near in set(k[dist2 == dist2.min()].tolist())
        elif len(k) and near >= 0:
            assert near_d2 >= dist2.min()
        return f, sabs, idx[:m].copy(), phi[:m].copy(), d2[:m].copy()

    def nearest(self, x: float, y: float):
        s = self.s
        return lk._nearest(x, y, s.W, s.cf, s.ci, s.c_head, s.c_nxt)

    def within(self, x: float, y: float, radius: float) -> np.ndarray:
        s = self.s
        idx = np.empty(s.cap, np.int64)
        d2 = np.empty(s.cap)
        m = lk._within(x, y, radius, s.W, s.cf, s.ci, s.c_head, s.c_nxt, idx, d2)
        return idx[:m].copy()

    # -- brute force
    @property
    def alive(self) -> np.ndarray:
        return np.flatnonzero(self.s.alive[: self.s.st[lk.ST_SLOTS]])

    def brute_support(self, x: float, y: float):
        W = self.s.W
        k = self.alive
        dx = x - W[k, 2]
        dy = y - W[k, 3]
        d2 = dx * dx + dy * dy
        sig = W[k, 1]
        supp2 = self.cfg.support * self.cfg.support
        inside = d2 < supp2 * sig * sig
        p = W[k, 0] * np.exp(-d2 / (sig * sig))
        return float(p[inside].sum()), float(np.abs(p[inside]).sum()), set(k[inside].tolist())

    def brute_distances(self, x: float, y: float) -> tuple[np.ndarray, np.ndarray]:
        W = self.s.W
        k = self.alive
        dx = x - W[k, 2]
        dy = y - W[k, 3]
        return k, dx * dx + dy * dy

    def check_lists(self) -> None:
        """Every alive slot is linked exactly once in each structure, dead slots never."""
        s = self.s
        alive = set(self.alive.tolist())
        for head, nxt, prv, cell in ((s.c_head, s.c_nxt, s.c_prv, s.c_cell),
                                     (s.l_head, s.l_nxt, s.l_prv, s.l_cell)):
            seen: list[int] = []
            for c in np.flatnonzero(head >= 0):
                prev = -1
                slot = head[c]
                while slot >= 0:
                    assert cell[slot] == c
                    assert prv[slot] == prev
                    seen.append(int(slot))
                    prev = slot
                    slot = nxt[slot]
            assert sorted(seen) == sorted(alive)
        levels = np.bincount(s.l_lev[self.alive], minlength=len(s.lev_count))
        np.testing.assert_array_equal(s.lev_count, levels)
        assert s.st[lk.ST_K] == len(alive)


def random_neurons(rng: np.random.Generator, k: int, corners: bool = True) -> np.ndarray:
    """(k, 4) rows (a, sigma, ux, uy): centres over the whole centre box (some outside
    the unit square, optionally some on its corners), widths log-uniform over 1e-3 .. 0.5."""
    a = rng.normal(0.0, 0.3, k)
    sigma = np.exp(rng.uniform(np.log(1e-3), np.log(0.5), k))
    u = rng.uniform(BOX[0], BOX[1], (k, 2))
    if corners:
        u[:4] = [[BOX[0], BOX[0]], [BOX[1], BOX[1]], [BOX[0], BOX[1]], [-0.1, 1.1]]
    return np.column_stack([a, sigma, u])


def query_points(rng: np.random.Generator, state: Neurons) -> np.ndarray:
    """Points in the unit square, in [-0.5, 1.5]^2 and close to the centres (so that the
    narrow neurons are hit too)."""
    W = state.s.W[state.alive]
    near = W[:, 2:4] + rng.normal(size=(len(W), 2)) * W[:, 1:2] * 1.5
    return np.concatenate([rng.random((150, 2)), rng.uniform(-0.5, 1.5, (150, 2)), near,
                           [[0.0, 0.0], [1.0, 1.0], [0.5, 0.5], [3.0, -2.0]]])


def check_queries(state: Neurons, rng: np.random.Generator) -> None:
    pts = query_points(rng, state)
    hits = 0
    for x, y in pts:
        f, sabs, idx, phi, d2 = state.support_query(x, y)
        bf, bsabs, bset = state.brute_support(x, y)
        assert len(idx) == len(set(idx.tolist())), "a neuron is reported twice"
        assert set(idx.tolist()) == bset
        assert f == pytest.approx(bf, rel=1e-12, abs=1e-14)
        assert sabs == pytest.approx(bsabs, rel=1e-12, abs=1e-14)
        W = state.s.W[idx]
        np.testing.assert_allclose(d2, (x - W[:, 2]) ** 2 + (y - W[:, 3]) ** 2, rtol=1e-12,
                                   atol=1e-15)
        np.testing.assert_allclose(phi, np.exp(-d2 / W[:, 1] ** 2), rtol=1e-12)
        hits += len(idx)

        k, bd2 = state.brute_distances(x, y)
        slot, dist = state.nearest(x, y)
        assert slot in k
        assert dist == np.sqrt(bd2[k == slot][0])
        assert dist == pytest.approx(np.sqrt(bd2.min()), rel=1e-14)

        for radius in (0.003, 0.05, 0.3):
            got = state.within(x, y, radius)
            assert len(got) == len(set(got.tolist()))
            assert set(got.tolist()) == set(k[bd2 <= radius * radius].tolist())
    assert hits > len(pts), "the query points should hit the supports of many neurons"
    assert state.near_shortcuts > len(pts) / 10, "the nearest-centre shortcut is exercised"


@pytest.mark.parametrize("d_min", [0.002, 0.01, 0.1])
def test_queries_match_brute_force_after_insert_remove_move(d_min: float) -> None:
    rng = np.random.default_rng(int(d_min * 1e4))
    state = Neurons(d_min)
    for row in random_neurons(rng, 300):
        state.add(*row)
    state.check_lists()
    assert len(np.unique(state.s.l_lev[state.alive])) >= 3, "several support levels in use"
    check_queries(state, rng)

    # remove a third of the neurons
    gone = rng.choice(state.alive, 100, replace=False)
    for slot in gone:
        state.remove(int(slot))
    assert state.s.st[lk.ST_K] == 200
    assert state.s.st[lk.ST_NFREE] == 100
    assert not np.any(state.s.alive[gone])
    state.check_lists()
    check_queries(state, rng)

    # move some neurons far (new cells and levels) and some by a hair (same cells)
    survivors = state.alive
    far = rng.choice(survivors, 60, replace=False)
    for slot, row in zip(far, random_neurons(rng, 60, corners=False), strict=True):
        state.move(int(slot), *row[1:])
    hair = np.setdiff1d(survivors, far)[:40]
    for slot in hair:
        w = state.s.W[slot]
        state.move(int(slot), w[1] * 1.001, w[2] + 1e-7, w[3] - 1e-7)
    state.check_lists()
    check_queries(state, rng)


@pytest.mark.parametrize(("update", "pruning"), [("nekf-neighbourhood", "literal"),
                                                 ("nekf", "support"), ("gd", "literal")])
def test_structures_stay_exact_through_real_learning(syn, update: str, pruning: str) -> None:
    """Run the learning loop itself (growth, moving centres, pruning, slot reuse), then
    check the index structures and the learning-time evaluation against brute force."""
    hf = to_height_field(syn.franke_points(40))
    cfg = FitConfig(update=update, pruning=pruning, prune_threshold=0.05, prune_window=200,
                    window=200, d_min=0.02, passes=2)
    n = hf.n_points
    state = Neurons(0.02, cfg, steps=2 * n)
    s = state.s
    X = np.ascontiguousarray(hf.xy)
    Z = np.ascontiguousarray(hf.z)
    rng = np.random.default_rng(0)
    for _ in range(2):
        s.run(X, Z, rng.permutation(n).astype(np.int64), int(s.st[lk.ST_T]) + n)
    assert s.st[lk.ST_T] == 2 * n
    if pruning == "literal":
        assert s.st[lk.ST_PRUNED] > 0 and s.st[lk.ST_NFREE] > 0  # slots were freed
    state.check_lists()
    assert s.st[lk.ST_K] == s.st[lk.ST_ADDED] - s.st[lk.ST_PRUNED] - s.st[lk.ST_DIVERGED]
    # every alive neuron sits at the finest support level whose cell holds its support
    alive = state.alive
    for slot in alive:
        lev = s.l_lev[slot]
        cell = 1.0 / (s.ci[lk.CI_G0] >> lev)
        support = cfg.support * s.W[slot, 1]
        assert cell >= support or lev == s.ci[lk.CI_NLEV] - 1
        assert lev == 0 or cell / 2 < support
    res = lk.residuals(X, Z, s.W, s.alive, s.fs[lk.FS_A0], s.cf, s.ci, s.l_head, s.l_nxt,
                       s.lev_off, s.lev_count)
    W = s.W[alive]
    net = Network(s.fs[lk.FS_A0], W[:, 2:4], W[:, 1], W[:, 0], UNIT_FRAME, cfg)
    f_ref, _, scale = brute_eval(net, X)
    assert np.all(np.abs((Z - res) - f_ref) <= 1e-12 * scale)
    check_queries(state, np.random.default_rng(1))


def test_queries_on_empty_state() -> None:
    state = Neurons(0.01)
    slot, dist = state.nearest(0.3, 0.7)
    assert slot == -1 and dist == np.inf
    f, sabs, idx, _, _ = state.support_query(0.3, 0.7)
    assert (f, sabs, len(idx)) == (0.0, 0.0, 0)
    assert len(state.within(0.3, 0.7, 10.0)) == 0


def test_single_neuron_outside_unit_square_found_from_inside() -> None:
    state = Neurons(0.01)
    slot = state.add(1.0, 0.05, -0.1, 1.1)  # support 0.175 reaches into the unit square
    f, _, idx, _, _ = state.support_query(0.0, 1.0)  # 0.141 away
    assert idx.tolist() == [slot]
    assert f == pytest.approx(np.exp(-(0.01 + 0.01) / 0.05**2))
    f, _, idx, _, _ = state.support_query(0.1, 1.0)  # 0.224 away: outside the support
    assert len(idx) == 0 and f == 0.0
    assert state.nearest(1.0, 0.0)[0] == slot


# ------------------------------------------------------------------ pruning deadline heap


def test_heap_matches_heapq_order() -> None:
    rng = np.random.default_rng(5)
    n = 600
    hk = np.zeros(n, np.int64)
    hs = np.zeros(n, np.int64)
    hg = np.zeros(n, np.int64)
    size = 0
    ref: list[tuple[int, int]] = []
    popped = 0
    for _ in range(2000):
        if size < n and (size == 0 or rng.random() < 0.55):
            key, slot, gen = int(rng.integers(0, 40)), int(rng.integers(0, 30)), int(
                rng.integers(0, 1000))
            size = lh._heap_push(hk, hs, hg, size, key, slot, gen)
            heapq.heappush(ref, (key, slot))
            assert (hk[0], hs[0]) == ref[0]
        else:
            top = (int(hk[0]), int(hs[0]))
            assert top == heapq.heappop(ref)
            size = lh._heap_pop(hk, hs, hg, size)
            popped += 1
        assert size == len(ref)
    while size:
        assert (int(hk[0]), int(hs[0])) == heapq.heappop(ref)
        size = lh._heap_pop(hk, hs, hg, size)
    assert popped > 500


def test_heap_keeps_generation_with_its_entry() -> None:
    hk = np.zeros(8, np.int64)
    hs = np.zeros(8, np.int64)
    hg = np.zeros(8, np.int64)
    size = 0
    for key, slot in [(5, 1), (3, 2), (9, 3), (1, 4), (7, 5)]:
        size = lh._heap_push(hk, hs, hg, size, key, slot, 100 * slot)
    out = []
    while size:
        out.append((int(hk[0]), int(hs[0]), int(hg[0])))
        size = lh._heap_pop(hk, hs, hg, size)
    assert out == [(1, 4, 400), (3, 2, 200), (5, 1, 100), (7, 5, 500), (9, 3, 300)]


# ------------------------------------------------------------------ static evaluation grid

UNIT_FRAME = Frame(np.eye(3), np.zeros(3), np.ones(3))


def random_network(seed: int, k: int = 250, support: float = 3.5,
                   widths: tuple[float, float] = (1e-3, 0.5)) -> Network:
    rng = np.random.default_rng(seed)
    centers = rng.uniform(BOX[0], BOX[1], (k, 2))
    w = np.exp(rng.uniform(np.log(widths[0]), np.log(widths[1]), k))
    a = rng.normal(0.0, 0.3, k)
    return Network(0.25, centers, w, a, UNIT_FRAME, FitConfig(support=support))


def brute_eval(net: Network, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """f, its gradient and sum |a_k phi_k| (the scale of rounding errors), by brute force."""
    s = net.config.support
    dx = pts[:, None, 0] - net.centers[None, :, 0]
    dy = pts[:, None, 1] - net.centers[None, :, 1]
    d2 = dx * dx + dy * dy
    s2 = net.widths * net.widths
    v = np.where(d2 < s * s * s2, net.weights * np.exp(-d2 / s2), 0.0)
    f = net.a0 + v.sum(axis=1)
    grad = np.column_stack([(-2.0 * v * dx / s2).sum(axis=1), (-2.0 * v * dy / s2).sum(axis=1)])
    return f, grad, np.abs(v).sum(axis=1) + abs(net.a0)


def eval_points(net: Network, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    near = net.centers + rng.normal(size=net.centers.shape) * net.widths[:, None] * 2
    return np.concatenate([rng.uniform(-0.5, 1.5, (1500, 2)), near, [[5.0, -4.0], [-3, 7]]])


@pytest.mark.parametrize("seed", [0, 1])
def test_network_evaluate_and_gradient_match_brute_force(seed: int) -> None:
    net = random_network(seed)
    pts = eval_points(net, seed + 10)
    f_ref, g_ref, scale = brute_eval(net, pts)
    assert np.count_nonzero(scale > abs(net.a0)) > len(pts) / 2  # most points see neurons
    # the evaluation may use a polynomial exp (relative error < 1e-12 per term)
    err = np.abs(net.evaluate(pts, unit=True) - f_ref)
    assert np.all(err <= 1e-11 * scale)
    np.testing.assert_allclose(net.gradient(pts, unit=True), g_ref, rtol=1e-10, atol=1e-10)
    # far outside every support only the bias is left
    assert net.evaluate(np.array([[50.0, 50.0]]), unit=True)[0] == net.a0


@pytest.mark.parametrize(("k", "widths"), [(250, (1e-3, 0.5)), (3000, (2e-3, 4e-3))])
def test_blocked_evaluation_matches_brute_force_on_every_path(k, widths) -> None:
    """Blocks sorted by cell (threaded and serial), and few points on a fine grid one by one."""
    from asrbf_mesh import _network_kernels as nk

    net = random_network(7, k=k, widths=widths)
    rng = np.random.default_rng(3)
    many = rng.uniform(-0.2, 1.2, (3 * nk.BLOCK + 17, 2))  # several blocks, a partial one
    f = net.evaluate(many, unit=True)
    assert f.shape == (len(many),)
    probe = rng.choice(len(many), 600, replace=False)
    f_ref, _, scale = brute_eval(net, many[probe])
    assert np.all(np.abs(f[probe] - f_ref) <= 1e-11 * scale)
    # each point's value depends on the point alone: not on its block, order or neighbours
    perm = rng.permutation(len(many))
    np.testing.assert_array_equal(net.evaluate(many[perm], unit=True), f[perm])
    few = many[probe[:50]]  # below SERIAL_BELOW; on the fine grid, fewer points than cells
    np.testing.assert_array_equal(net.evaluate(few, unit=True), f[probe[:50]])
    import numba  # one thread: other blocks, the same values

    threads = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        np.testing.assert_array_equal(net.evaluate(many, unit=True), f)
    finally:
        numba.set_num_threads(threads)


def test_build_grid_cells_hold_every_neuron_reaching_them() -> None:
    net = random_network(3)
    from asrbf_mesh._piece import eval_grid

    grid = eval_grid(net.centers, net.widths, net.weights, net.config.support)
    s, lo, h, g, start, items = grid[:6]  # (support, lo, h, g, start, items, packed)
    assert start[0] == 0 and start[-1] == len(items)
    assert np.all(np.diff(start) >= 0)
    for c in range(g * g):  # no duplicates in any cell list
        cell = items[start[c]:start[c + 1]]
        assert len(cell) == len(np.unique(cell))
    pts = eval_points(net, 4)
    for x, y in pts:
        cx = min(max(int(np.floor((x - lo[0]) / h)), 0), g - 1)
        cy = min(max(int(np.floor((y - lo[1]) / h)), 0), g - 1)
        c = cy * g + cx
        listed = set(items[start[c]:start[c + 1]].tolist())
        d2 = (x - net.centers[:, 0]) ** 2 + (y - net.centers[:, 1]) ** 2
        reaching = set(np.flatnonzero(d2 < (s * net.widths) ** 2).tolist())
        assert reaching <= listed


def test_build_grid_direct_call_small_case() -> None:
    centers = np.array([[0.6, 0.6], [-0.2, 0.1]])
    widths = np.array([0.01, 0.1])
    start, items = nk.build_grid(centers, widths, 3.5, np.array([-0.25, -0.25]), 0.25, 6)
    cells = {c: sorted(items[start[c]:start[c + 1]].tolist()) for c in range(36)}
    # neuron 0 (support 0.035) sits inside cell (3, 3); neuron 1 (support 0.35) spans
    # x in [-0.55, 0.15] -> columns 0..1, y in [-0.25, 0.45] -> rows 0..2
    assert {c for c, v in cells.items() if 0 in v} == {3 * 6 + 3}
    assert {c for c, v in cells.items() if 1 in v} == {r * 6 + q for r in range(3)
                                                         for q in range(2)}
    assert sum(len(v) for v in cells.values()) == 1 + 6


def test_gradient_matches_central_differences() -> None:
    # a wide truncation makes the truncated Gaussians smooth to machine precision
    net = random_network(7, k=80, support=8.0, widths=(0.03, 0.3))
    rng = np.random.default_rng(8)
    pts = rng.uniform(-0.5, 1.5, (300, 2))
    h = 1e-6
    ex = np.array([h, 0.0])
    ey = np.array([0.0, h])
    fd = np.column_stack([
        (net.evaluate(pts + ex, unit=True) - net.evaluate(pts - ex, unit=True)) / (2 * h),
        (net.evaluate(pts + ey, unit=True) - net.evaluate(pts - ey, unit=True)) / (2 * h)])
    grad = net.gradient(pts, unit=True)
    assert np.abs(grad).max() > 1.0
    np.testing.assert_allclose(grad, fd, rtol=0, atol=2e-6 * np.abs(grad).max())


def test_empty_network_evaluates_to_bias() -> None:
    net = Network(0.3, np.zeros((0, 2)), np.zeros(0), np.zeros(0), UNIT_FRAME, FitConfig())
    pts = np.array([[0.2, 0.4], [-1.0, 2.0]])
    np.testing.assert_array_equal(net.evaluate(pts, unit=True), [0.3, 0.3])
    np.testing.assert_array_equal(net.gradient(pts, unit=True), np.zeros((2, 2)))


def test_threaded_kernels_work_in_a_child_forked_after_the_parent_used_them() -> None:
    # the pool of threads is per process: a forked child must not wait for the
    # parent's threads (which do not exist in it)
    import multiprocessing as mp

    from asrbf_mesh._grid_knn import knn

    rng = np.random.default_rng(0)
    xy = rng.random((20_000, 2))
    ref = knn(xy, np.arange(len(xy)), 4)  # the parent's pool is up now
    ctx = mp.get_context("fork")
    with ctx.Pool(1) as pool:
        got = pool.apply_async(knn, (xy, np.arange(len(xy)), 4)).get(timeout=120)
    assert np.array_equal(got[1], ref[1]) and np.array_equal(got[0], ref[0])
