"""Batch polish of a learned network: sparse design matrix, weights LS, full LM."""

from __future__ import annotations

import warnings
from dataclasses import replace

import numpy as np
import pytest

import asrbf_mesh as am
from asrbf_mesh._config import FitConfig
from asrbf_mesh._frame import to_height_field
from asrbf_mesh._learn import learn
from asrbf_mesh._polish import design_matrix, drop_idle, polish_full, polish_weights


@pytest.fixture(scope="module")
def learned(syn):
    """A height field of Franke's function (1,600 points) and its sequential network."""
    hf = to_height_field(syn.franke_points(40))
    return hf, learn(hf, FitConfig(passes=1), seed=0)


def mean_abs(xy, z, a0, centers, widths, weights, support=3.5) -> float:
    A = design_matrix(xy, centers, widths, weights, support)
    return float(np.mean(np.abs(A @ np.concatenate([[a0], weights]) - z)))


# ----------------------------------------------------------------------------- design matrix


def dense_design(xy, centers, widths, weights, support, full):
    dx = xy[:, None, 0] - centers[None, :, 0]
    dy = xy[:, None, 1] - centers[None, :, 1]
    d2 = dx * dx + dy * dy
    s2 = widths * widths
    phi = np.where(d2 < support * support * s2, np.exp(-d2 / s2), 0.0)
    if not full:
        return np.column_stack([np.ones(len(xy)), phi])
    ap = weights * phi
    cols = np.stack([phi, 2 * ap * d2 / s2, 2 * ap * dx / s2, 2 * ap * dy / s2], axis=2)
    return np.column_stack([np.ones(len(xy)), cols.reshape(len(xy), -1)])


def random_net(seed: int, k: int = 60, widths=(0.005, 0.3)):
    rng = np.random.default_rng(seed)
    centers = rng.uniform(-0.25, 1.25, (k, 2))
    w = np.exp(rng.uniform(np.log(widths[0]), np.log(widths[1]), k))
    a = rng.normal(0, 0.3, k)
    xy = np.concatenate([rng.uniform(-0.3, 1.3, (400, 2)),
                         centers + rng.normal(size=(k, 2)) * w[:, None]])
    return xy, centers, w, a


@pytest.mark.parametrize("full", [False, True])
def test_design_matrix_matches_dense_brute_force(full: bool) -> None:
    xy, centers, widths, weights = random_net(1)
    A = design_matrix(xy, centers, widths, weights, 3.5, full=full)
    assert A.shape == (len(xy), 1 + (4 if full else 1) * len(widths))
    ref = dense_design(xy, centers, widths, weights, 3.5, full)
    np.testing.assert_allclose(A.toarray(), ref, rtol=1e-12, atol=1e-14)
    # sparse: only the truncated supports are stored (plus the bias column)
    per = 4 if full else 1
    assert A.nnz == len(xy) + per * int(np.count_nonzero(ref[:, 1::per]))
    assert A.nnz < 0.5 * A.shape[0] * A.shape[1]


def test_full_design_matrix_is_the_jacobian() -> None:
    # wide truncation: smooth, so central differences of f must match the columns
    xy, centers, widths, weights = random_net(2, k=15, widths=(0.05, 0.3))
    support = 9.0
    J = design_matrix(xy, centers, widths, weights, support, full=True).toarray()

    def f(a0, c, w, a):
        return design_matrix(xy, c, w, a, support) @ np.concatenate([[a0], a])

    h = 1e-6
    for k in (0, 7, 14):
        for col, name in enumerate(("a", "log_sigma", "ux", "uy")):
            c, w, a = centers.copy(), widths.copy(), weights.copy()
            c2, w2, a2 = centers.copy(), widths.copy(), weights.copy()
            if name == "a":
                a[k] += h
                a2[k] -= h
            elif name == "log_sigma":
                w[k] *= np.exp(h)
                w2[k] *= np.exp(-h)
            else:
                c[k, col - 2] += h
                c2[k, col - 2] -= h
            fd = (f(0.0, c, w, a) - f(0.0, c2, w2, a2)) / (2 * h)
            np.testing.assert_allclose(J[:, 1 + 4 * k + col], fd, rtol=0, atol=1e-6)
    np.testing.assert_array_equal(J[:, 0], 1.0)


# ----------------------------------------------------------------------------- weights


def test_polish_weights_improves_the_sequential_network(learned) -> None:
    hf, st = learned
    before = mean_abs(hf.xy, hf.z, st.a0, st.centers, st.widths, st.weights)
    pr = polish_weights(hf.xy, hf.z, st.a0, st.centers, st.widths, st.weights, 3.5)
    assert pr.ebar_before == pytest.approx(before, rel=1e-12)
    # measured: 0.0040 -> 0.0022
    assert pr.ebar_after < 0.8 * pr.ebar_before
    assert pr.ebar_after == pytest.approx(
        mean_abs(hf.xy, hf.z, pr.a0, pr.centers, pr.widths, pr.weights), rel=1e-12)
    # structure untouched, only a0 and the weights move
    np.testing.assert_array_equal(pr.centers, st.centers)
    np.testing.assert_array_equal(pr.widths, st.widths)
    assert not np.array_equal(pr.weights, st.weights)


@pytest.mark.parametrize("seed", range(4))
def test_polish_weights_never_increases_ebar(syn, seed: int) -> None:
    hf = to_height_field(syn.franke_points(30, seed=seed))
    xy, centers, widths, weights = random_net(seed + 10)
    for ridge in (1e-9, 1e-4, 1.0):
        pr = polish_weights(hf.xy, hf.z, 0.2, centers, widths, weights, 3.5, ridge)
        assert pr.ebar_after <= pr.ebar_before


def test_polish_weights_keeps_the_network_when_least_squares_is_worse() -> None:
    # one outlier: the least-squares bias lowers the squared error but doubles E-bar
    xy = np.random.default_rng(0).random((100, 2))
    z = np.zeros(100)
    z[0] = 100.0
    centers, widths, weights = np.array([[5.0, 5.0]]), np.array([0.01]), np.array([0.3])
    pr = polish_weights(xy, z, 0.0, centers, widths, weights, 3.5, 1e-9)
    assert pr.iterations == 0
    assert pr.ebar_after == pr.ebar_before == pytest.approx(1.0)
    assert pr.a0 == 0.0 and pr.weights is weights


def test_polish_weights_without_ridge_tolerates_a_neuron_without_data(learned) -> None:
    hf, st = learned
    centers = np.vstack([st.centers, [[1.2, 1.2]]])  # no point within 3.5 sigma
    widths = np.append(st.widths, 0.01)
    weights = np.append(st.weights, 0.1)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        pr = polish_weights(hf.xy, hf.z, st.a0, centers, widths, weights, 3.5, ridge=0.0)
    assert pr.ebar_after < 0.8 * pr.ebar_before


def test_polish_weights_recovers_exact_weights() -> None:
    # data generated by the network itself, weights perturbed: least squares restores them
    xy, centers, widths, weights = random_net(4, k=20, widths=(0.05, 0.2))
    z = design_matrix(xy, centers, widths, weights, 3.5) @ np.concatenate([[0.1], weights])
    pr = polish_weights(xy, z, 0.0, centers, widths, weights * 0.5, 3.5, ridge=0.0)
    # neurons without data under them are left where they were
    A = design_matrix(xy, centers, widths, weights, 3.5).toarray()
    seen = np.count_nonzero(A[:, 1:] > 1e-3, axis=0) >= 3
    assert seen.sum() > 10
    np.testing.assert_allclose(pr.weights[seen], weights[seen], rtol=1e-6, atol=1e-8)
    assert pr.a0 == pytest.approx(0.1, abs=1e-8)
    assert pr.ebar_after < 1e-9


# ----------------------------------------------------------------------------- full


def test_polish_full_beats_polish_weights(learned) -> None:
    hf, st = learned
    args = (hf.xy, hf.z, st.a0, st.centers, st.widths, st.weights, 3.5)
    pw = polish_weights(*args)
    pf = polish_full(*args, iterations=4)
    assert pf.ebar_before == pytest.approx(pw.ebar_before, rel=1e-12)
    # measured: sequential 0.0040, weights 0.0022, full 0.0009
    assert pf.ebar_after < 0.9 * pw.ebar_after
    assert pf.iterations >= 2
    assert np.all(np.isfinite(pf.centers)) and np.all(np.isfinite(pf.weights))
    assert np.all((pf.widths >= 1e-5) & (pf.widths <= 2.0))
    assert np.all((pf.centers >= -0.25) & (pf.centers <= 1.25))
    assert pf.ebar_after == pytest.approx(
        mean_abs(hf.xy, hf.z, pf.a0, pf.centers, pf.widths, pf.weights), rel=1e-9)


def test_polish_full_with_zero_iterations_is_polish_weights(learned) -> None:
    hf, st = learned
    args = (hf.xy, hf.z, st.a0, st.centers, st.widths, st.weights, 3.5)
    pw = polish_weights(*args)
    pf = polish_full(*args, iterations=0)
    assert pf.iterations == 1
    np.testing.assert_allclose(pf.weights, pw.weights, rtol=1e-12)
    assert pf.ebar_after == pytest.approx(pw.ebar_after, rel=1e-9)


def test_fit_polish_modes(syn) -> None:
    pts = syn.franke_points(40)
    # the paper's single network, then each polish (the default model refines after it)
    nets = {p: am.fit(pts, seed=0, polish=p, passes=1, pieces=1, progress=False)
            for p in ("none", "weights", "full")}
    seq = nets["none"].info["ebar"]
    for net in nets.values():
        assert net.info["ebar_sequential"] == pytest.approx(seq, rel=1e-12)
        assert net.config.polish in ("none", "weights", "full")
    assert nets["full"].info["ebar"] < nets["weights"].info["ebar"] < seq
    np.testing.assert_array_equal(nets["weights"].centers, nets["none"].centers)
    assert nets["weights"].info["polish_seconds"] >= 0


def test_weight_polish_is_the_same_in_chunks_bit_for_bit(learned, monkeypatch) -> None:
    # the compiled kernel adds the rows one after another: chunks cannot change a bit
    import asrbf_mesh._polish as P

    hf, st = learned
    args = (hf.xy, hf.z, st.a0, st.centers, st.widths, st.weights, 3.5)
    whole = polish_weights(*args)
    monkeypatch.setattr(P, "_CHUNK", 97)
    chunked = polish_weights(*args)
    np.testing.assert_array_equal(chunked.weights, whole.weights)
    np.testing.assert_array_equal(chunked.ata, whole.ata)


def test_dense_normal_equations_equal_the_sparse_ones(learned, monkeypatch) -> None:
    # the compiled dense sum (up to DENSE_MAX unknowns) against scipy's sparse products
    import scipy.sparse as sp

    import asrbf_mesh._polish as P

    hf, st = learned
    args = (hf.xy, hf.z, st.a0, st.centers, st.widths, st.weights, 3.5)
    dense = polish_weights(*args)
    assert isinstance(dense.ata, np.ndarray)
    A = design_matrix(hf.xy, st.centers, st.widths, st.weights, 3.5)
    np.testing.assert_allclose(dense.ata, (A.T @ A).toarray(), rtol=1e-10, atol=1e-9)
    np.testing.assert_allclose(dense.atz, A.T @ hf.z, rtol=1e-10, atol=1e-9)
    monkeypatch.setattr(P, "DENSE_MAX", 1)  # the sparse path
    sparse = polish_weights(*args)
    assert sp.issparse(sparse.ata)
    np.testing.assert_allclose(sparse.ata.toarray(), dense.ata, rtol=1e-10, atol=1e-9)
    np.testing.assert_allclose(sparse.weights, dense.weights, rtol=1e-7, atol=1e-9)


@pytest.mark.parametrize("dense_max", [1, 2049])
def test_extend_and_solve_equals_a_polish_of_all_neurons(learned, monkeypatch,
                                                         dense_max: int) -> None:
    # appended neurons: the extended normal equations are those of the whole network
    import asrbf_mesh._polish as P
    from asrbf_mesh._polish import extend_and_solve

    monkeypatch.setattr(P, "DENSE_MAX", dense_max)
    hf, st = learned
    k = len(st.widths) - 5
    first = polish_weights(hf.xy, hf.z, st.a0, st.centers[:k], st.widths[:k],
                           st.weights[:k], 3.5)
    weights = np.r_[first.weights, st.weights[k:]]
    got = extend_and_solve(hf.xy, hf.z, first, first.a0, st.centers, st.widths, weights, 3.5)
    ref = polish_weights(hf.xy, hf.z, first.a0, st.centers, st.widths, weights, 3.5)
    dense = got.ata if isinstance(got.ata, np.ndarray) else got.ata.toarray()
    ref_ata = ref.ata if isinstance(ref.ata, np.ndarray) else ref.ata.toarray()
    np.testing.assert_allclose(dense, ref_ata, rtol=1e-10, atol=1e-9)
    np.testing.assert_allclose(got.atz, ref.atz, rtol=1e-10, atol=1e-9)
    np.testing.assert_allclose(got.weights, ref.weights, rtol=1e-6, atol=1e-8)


def test_rows_under_are_the_rows_where_the_neurons_columns_are_not_zero(learned) -> None:
    from asrbf_mesh._polish import rows_under

    hf, st = learned
    some = slice(3, 40, 4)
    got = rows_under(hf.xy, st.centers[some], st.widths[some], 3.5)
    A = design_matrix(hf.xy, st.centers, st.widths, st.weights, 3.5).tocsc()[:, 1:][:, some]
    np.testing.assert_array_equal(got, np.flatnonzero(np.diff(A.tocsr().indptr) > 0))
    assert len(rows_under(hf.xy, np.zeros((0, 2)), np.zeros(0), 3.5)) == 0


def _appended(learned, m: int) -> tuple:
    """A learned network's last ``m`` neurons appended to a polish of the others."""
    hf, st = learned
    k = len(st.widths) - m
    first = polish_weights(hf.xy, hf.z, st.a0, st.centers[:k], st.widths[:k],
                           st.weights[:k], 3.5)
    return hf, st, first, np.r_[first.weights, st.weights[k:]]


def test_appended_columns_sum_to_the_same_bits_on_one_thread_or_two(learned) -> None:
    import numba

    from asrbf_mesh._polish import extend_normal

    hf, st, first, weights = _appended(learned, 6)
    threads = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        one = extend_normal(hf.xy, hf.z, first, st.centers, st.widths, weights, 3.5)
    finally:
        numba.set_num_threads(threads)
    two = extend_normal(hf.xy, hf.z, first, st.centers, st.widths, weights, 3.5)
    assert one[0].tobytes() == two[0].tobytes() and one[1].tobytes() == two[1].tobytes()
    np.testing.assert_array_equal(one[0], one[0].T)  # symmetric


def test_appended_columns_equal_the_dense_design_matrix_products(learned) -> None:
    # the fused kernel's A'A rows and A'z of the appended columns, against A'A by hand
    from asrbf_mesh._polish import extend_normal

    hf, st, first, weights = _appended(learned, 6)
    ata, atz = extend_normal(hf.xy, hf.z, first, st.centers, st.widths, weights, 3.5)
    A = dense_design(hf.xy, st.centers, st.widths, weights, 3.5, False)
    np.testing.assert_allclose(ata, A.T @ A, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(atz, A.T @ hf.z, rtol=1e-12, atol=1e-9)


def test_appended_weights_are_the_local_least_squares_weights(learned) -> None:
    # the tails' new weights from the extended normal equations = a solve on the residual
    from asrbf_mesh._pieces import _appended_weights, _local_weights
    from asrbf_mesh._polish import appended_rows

    hf, st, first, weights = _appended(learned, 6)
    rows, atz = appended_rows(hf.xy, hf.z, st.centers, st.widths, weights, 3.5,
                              len(first.widths))
    res = hf.z - first.a0 - dense_design(hf.xy, first.centers, first.widths, first.weights,
                                         3.5, False)[:, 1:] @ first.weights
    cfg = FitConfig()
    got = _appended_weights(rows, atz, first.a0, first.weights, cfg.polish_ridge)
    ref = _local_weights(hf.xy, res, st.centers[-6:], st.widths[-6:], cfg)
    np.testing.assert_allclose(got, ref, rtol=1e-8, atol=1e-10)
    assert np.abs(got).max() > 1e-3


def test_normal_equations_grown_in_two_rounds_are_extend_normals_bit_for_bit(learned) -> None:
    # the tails keep only each round's new rows and write the whole matrix once
    from asrbf_mesh._polish import GrownNormal, appended_rows, extend_normal

    hf, st, first, weights = _appended(learned, 9)
    k = len(first.widths)
    grown = GrownNormal(first.ata, first.atz)
    for end in (k + 4, k + 9):  # two rounds: 4 neurons, then 5
        grown.append(*appended_rows(hf.xy, hf.z, st.centers[:end], st.widths[:end],
                                    weights[:end], 3.5, grown.size - 1))
    ata, atz = extend_normal(hf.xy, hf.z, first, st.centers, st.widths, weights, 3.5)
    np.testing.assert_allclose(grown.matrix(), ata, rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(grown.matrix(), grown.matrix().T)
    np.testing.assert_allclose(grown.atz, atz, rtol=1e-12, atol=1e-12)  # (rows summed apart)
    one = GrownNormal(first.ata, first.atz)
    one.append(*appended_rows(hf.xy, hf.z, st.centers, st.widths, weights, 3.5, k))
    assert one.matrix().tobytes() == ata.tobytes() and one.atz.tobytes() == atz.tobytes()
    with pytest.raises(ValueError, match="every column"):
        one.append(np.zeros((1, 3)), np.zeros(1))


def test_a_kept_residual_is_the_polished_networks_own(learned) -> None:
    # the tail refinement starts from it instead of evaluating the network again
    from asrbf_mesh._piece import Piece
    from asrbf_mesh._polish import extend_normal, solve_and_drop

    hf, st, first, weights = _appended(learned, 8)
    assert first.residual is None  # not asked for: no N floats kept
    pr = polish_weights(hf.xy, hf.z, st.a0, st.centers, st.widths, st.weights, 3.5,
                        keep_residual=True)
    f = Piece(pr.a0, pr.centers, pr.widths, pr.weights).eval_unit(hf.xy, 3.5)[0]
    assert pr.residual.tobytes() == (hf.z - f).tobytes()
    assert pr.ebar_after == float(np.abs(pr.residual).mean())
    ata, atz = extend_normal(hf.xy, hf.z, first, st.centers, st.widths, weights, 3.5)
    got, _ = solve_and_drop(hf.xy, hf.z, ata, atz, first.a0, st.centers, st.widths,
                            weights, 3.5, 1e-4, 1e-6)
    f = Piece(got.a0, got.centers, got.widths, got.weights).eval_unit(hf.xy, 3.5)[0]
    assert got.residual.tobytes() == (hf.z - f).tobytes()


def test_eliminate_is_greedy_backward_elimination_by_brute_force() -> None:
    # each step removes the unknown whose removal raises the objective least, exactly
    import scipy.linalg as sla

    from asrbf_mesh._network_kernels import eliminate

    rng = np.random.default_rng(0)
    A = rng.normal(size=(200, 12))
    A[:, 0] = 1.0
    A[:, 5] = A[:, 4] + 1e-3 * rng.normal(size=200)  # a near twin
    z = A[:, :4] @ rng.normal(size=4) + 0.01 * rng.normal(size=200)
    M, b = A.T @ A + 1e-6 * np.eye(12), A.T @ z
    inv = sla.lapack.dpotri(sla.lapack.dpotrf(M, lower=1)[0], lower=1)[0]
    inv[np.triu_indices(12, 1)] = np.nan  # the upper triangle is not read

    def solve(keep: list[int]) -> tuple[np.ndarray, float]:
        w = np.zeros(12)
        w[keep] = np.linalg.solve(M[np.ix_(keep, keep)], b[keep])
        return w, w @ M @ w - 2.0 * b @ w

    cur, order = list(range(12)), []
    while True:
        rises = [(solve([c for c in cur if c != j])[1] - solve(cur)[1], j) for j in cur[1:]]
        rise, j = min(rises)
        if rise >= 0.05:
            break
        order.append(j)
        cur.remove(j)
    w = np.linalg.solve(M, b)
    dropped = eliminate(inv, w, 0.05, np.inf)
    assert dropped.tolist() == order and 0 not in order and len(order) >= 3
    np.testing.assert_allclose(w, solve(cur)[0], atol=1e-10)
    # a budget stops the removals before their rises add up past it
    first = solve([c for c in range(12) if c != order[0]])[1] - solve(list(range(12)))[1]
    assert eliminate(inv, np.linalg.solve(M, b), 0.05, first * 1.01).tolist() == order[:1]


def test_solve_and_drop_gives_back_at_most_its_share_of_the_gain(learned) -> None:
    from asrbf_mesh._polish import extend_normal, solve_and_drop

    hf, st, first, weights = _appended(learned, 8)
    ata, atz = extend_normal(hf.xy, hf.z, first, st.centers, st.widths, weights, 3.5)
    base = np.r_[first.a0, first.weights, np.zeros(8)]

    def sum_squares(pr) -> float:
        A = design_matrix(hf.xy, pr.centers, pr.widths, pr.weights, 3.5)
        return float(((A @ np.r_[pr.a0, pr.weights] - hf.z) ** 2).sum())

    free, n_free = solve_and_drop(hf.xy, hf.z, ata, atz, first.a0, st.centers, st.widths,
                                  weights, 3.5, 1e-4, np.inf)
    assert n_free == len(st.widths)  # no limit, no budget: every neuron goes
    full, none = solve_and_drop(hf.xy, hf.z, ata, atz, first.a0, st.centers, st.widths,
                                weights, 3.5, 1e-4, 0.0)  # solved, nothing dropped
    got, n = solve_and_drop(hf.xy, hf.z, ata, atz, first.a0, st.centers, st.widths,
                            weights, 3.5, 1e-4, np.inf, base=base, give_back=0.5)
    assert none == 0 and 0 < n < len(st.widths)
    before, best, after = sum_squares(first), sum_squares(full), sum_squares(got)
    assert best < after <= best + 0.5 * (before - best) * (1 + 1e-6)
    assert got.ebar_after == pytest.approx(mean_abs(hf.xy, hf.z, got.a0, got.centers,
                                                    got.widths, got.weights))


def test_large_systems_are_solved_by_conjugate_gradients() -> None:
    # above _DIRECT_MAX unknowns: CG, same solution as the direct solve
    import scipy.sparse as sp
    from scipy.sparse.linalg import spsolve

    from asrbf_mesh._polish import _DIRECT_MAX, _solve_spd

    side = int(np.sqrt(_DIRECT_MAX)) + 4  # a 2D neighbourhood structure, like A'A
    lap = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], shape=(side, side))
    eye = sp.eye(side)
    mat = (sp.kron(lap, eye) + sp.kron(eye, lap) + 0.01 * sp.eye(side * side)).tocsr()
    assert mat.shape[0] > _DIRECT_MAX
    rhs = np.random.default_rng(0).standard_normal(mat.shape[0])
    np.testing.assert_allclose(_solve_spd(mat, rhs), spsolve(mat.tocsc(), rhs),
                               rtol=1e-7, atol=1e-9)


# ----------------------------------------------------------------------------- idle neurons


def _two_bumps():
    """A height field of two Gaussians (3,600 points) and a network of them plus a twin."""
    g = np.linspace(0.0, 1.0, 60)
    xy = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
    centers = np.array([[0.3, 0.3], [0.7, 0.6]])
    widths = np.array([0.15, 0.2])
    z = 0.1 + design_matrix(xy, centers, widths, np.ones(2), 3.5)[:, 1:] @ [0.5, 0.3]
    z += np.random.default_rng(0).normal(0.0, 1e-3, len(z))  # noise: E-bar 8e-4
    # the second bump twice: either twin can go at no cost, never both
    twin_c, twin_w = np.vstack([centers, centers[1]]), np.r_[widths, widths[1]]
    return xy, z, twin_c, twin_w


def test_drop_idle_drops_a_redundant_neuron_and_keeps_the_needed_ones() -> None:
    xy, z, centers, widths = _two_bumps()
    pr = polish_weights(xy, z, 0.0, centers, widths, np.array([0.4, 0.1, 0.1]), 3.5, 1e-8)
    got, dropped = drop_idle(xy, z, pr, 3.5, 1e-8, 1e-6)
    assert dropped == 1 and len(got.widths) == 2
    assert sorted(got.widths.tolist()) == [0.15, 0.2]  # one bump each: the twin went
    assert got.ebar_after < 1e-3 and mean_abs(xy, z, got.a0, got.centers, got.widths,
                                              got.weights) == pytest.approx(got.ebar_after)
    assert got.ata.shape == (3, 3) and got.atz.shape == (3,)  # still extendable
    # a limit no neuron's removal stays under drops nothing
    assert drop_idle(xy, z, pr, 3.5, 1e-8, 1e-30)[1] == 0


def test_drop_idle_keeps_the_network_without_normal_equations(learned) -> None:
    hf, st = learned
    pr = polish_full(hf.xy, hf.z, st.a0, st.centers, st.widths, st.weights, 3.5,
                     iterations=1)
    assert drop_idle(hf.xy, hf.z, pr, 3.5, 1e-4, 1.0) == (pr, 0)


def _blas_threads() -> list[int]:
    from threadpoolctl import threadpool_info

    return [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]


def test_one_blas_thread_restores_the_limit_once_the_last_holder_leaves(monkeypatch) -> None:
    """Two threads hold the limit, the first to enter leaves first: one limit, one restore.

    (threadpoolctl's calls are faked: OpenBLAS itself sometimes ignores a thread count
    raised from a thread other than the one that lowered it, which is not under test.)
    """
    import threading

    from asrbf_mesh import _blas

    calls: list[str] = []

    class Limiter:
        def restore_original_limits(self) -> None:
            calls.append("restore")

    class Controller:
        def limit(self, *, limits: int, user_api: str) -> Limiter:
            calls.append(f"limit {limits} {user_api}")
            return Limiter()

    monkeypatch.setattr(_blas, "_controller", lambda: Controller())
    first_in, second_in, first_out = threading.Event(), threading.Event(), threading.Event()
    seen: list[list[str]] = []

    def first() -> None:
        with _blas.one_blas_thread():
            first_in.set()
            second_in.wait(10)
        first_out.set()

    def second() -> None:
        first_in.wait(10)
        with _blas.one_blas_thread():
            second_in.set()
            first_out.wait(10)
            seen.append(list(calls))  # the first left: nothing restored yet

    threads = [threading.Thread(target=first), threading.Thread(target=second)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(20)
    assert seen == [["limit 1 blas"]]
    assert calls == ["limit 1 blas", "restore"]
    assert _blas._STATE == {"depth": 0, "limiter": None}


def test_a_fit_runs_blas_on_one_thread_and_gives_it_back(monkeypatch) -> None:
    from asrbf_mesh import _polish

    seen: list[list[int]] = []
    solve = _polish._solve_spd

    def spy(*args, **kwargs):
        seen.append(_blas_threads())
        return solve(*args, **kwargs)

    monkeypatch.setattr(_polish, "_solve_spd", spy)
    before = _blas_threads()
    rng = np.random.default_rng(0)
    xy = rng.random((3000, 2))
    am.fit(np.c_[xy, np.sin(3 * xy[:, 0])], seed=0, progress=False)
    assert seen and all(set(s) <= {1} for s in seen)
    assert _blas_threads() == before


def test_tiled_solve_and_drop_keeps_its_share_of_the_gain(learned, monkeypatch) -> None:
    """By strips (block Gauss-Seidel, drops strip by strip): near the whole solve."""
    from asrbf_mesh import _polish
    from asrbf_mesh._polish import extend_normal, solve_and_drop

    hf, st, first, weights = _appended(learned, 8)
    ata, atz = extend_normal(hf.xy, hf.z, first, st.centers, st.widths, weights, 3.5)
    base = np.r_[first.a0, first.weights, np.zeros(8)]
    args = (hf.xy, hf.z, ata, atz, first.a0, st.centers, st.widths, weights, 3.5, 1e-4)

    def sum_squares(pr) -> float:
        A = design_matrix(hf.xy, pr.centers, pr.widths, pr.weights, 3.5)
        return float(((A @ np.r_[pr.a0, pr.weights] - hf.z) ** 2).sum())

    whole, _ = solve_and_drop(*args, 0.0)
    whole_drop, n_whole = solve_and_drop(*args, np.inf, base=base, give_back=0.5)
    k = len(st.widths)
    monkeypatch.setattr(_polish, "TILE_ABOVE", k // 4)
    monkeypatch.setattr(_polish, "TILE_NEURONS", k // 4)  # four or five strips
    tiled, none = solve_and_drop(*args, 0.0)
    got, n = solve_and_drop(*args, np.inf, base=base, give_back=0.5)
    before, best, swept = sum_squares(first), sum_squares(whole), sum_squares(tiled)
    assert none == 0 and 0 < n < k
    # two sweeps come within a few percent of the whole solve's gain
    assert best <= swept * (1 + 1e-9) and swept - best < 0.05 * (before - best)
    # the drops give back at most half of the sweeps' gain
    after = sum_squares(got)
    assert swept < after <= swept + 0.5 * (before - swept) * (1 + 1e-6)
    # priced with fewer weights free, the strips drop no more here than the whole solve
    assert n <= n_whole
    assert got.ebar_after == pytest.approx(mean_abs(hf.xy, hf.z, got.a0, got.centers,
                                                    got.widths, got.weights))


@pytest.mark.parametrize("tiled", [False, True])
def test_a_memo_gives_later_drops_the_first_ones_solve(learned, monkeypatch, tiled) -> None:
    # drops that differ only in their budget and in how many must go share one solve:
    # each the same numbers as alone, dense or by tiles
    import asrbf_mesh._polish as P

    if tiled:
        monkeypatch.setattr(P, "TILE_ABOVE", 10)
        monkeypatch.setattr(P, "TILE_NEURONS", 15)
    hf, st, first, weights = _appended(learned, 8)
    ata, atz = P.extend_normal(hf.xy, hf.z, first, st.centers, st.widths, weights, 3.5)
    args = (hf.xy, hf.z, ata, atz, first.a0, st.centers, st.widths, weights, 3.5, 1e-4,
            1e-3)
    base = np.r_[first.a0, first.weights, np.zeros(8)]
    memo: dict = {}
    for give_back, at_least in ((0.25, 0), (0.75, 5), (0.25, 0), (1.0, 12)):
        alone = P.solve_and_drop(*args, base=base, give_back=give_back, at_least=at_least)
        shared = P.solve_and_drop(*args, base=base, give_back=give_back, at_least=at_least,
                                  memo=memo)
        assert alone[1] == shared[1] and np.array_equal(alone[0].weights, shared[0].weights)
        assert np.array_equal(alone[0].residual, shared[0].residual)
    assert ("tiles" in memo) == tiled and ("inv" in memo) != tiled


def test_sparse_equations_are_extended_and_dropped_strip_by_strip(learned,
                                                                  monkeypatch) -> None:
    # past the dense normal equations (a scan of one piece with thousands of neurons: an
    # elevation tile) the appended columns are summed sparse, only their own rows of A'A,
    # and the drop goes strip by strip from the sparse matrix: the same equations and the
    # same drop as dense ones, to rounding; without ``strips`` no drop is made there
    import scipy.sparse as sparse

    import asrbf_mesh._polish as P

    hf, st, first, weights = _appended(learned, 8)
    dense_ata, dense_atz = P.extend_normal(hf.xy, hf.z, first, st.centers, st.widths,
                                           weights, 3.5)
    sparse_first = replace(first, ata=sparse.csr_matrix(first.ata))
    k = len(st.widths)
    monkeypatch.setattr(P, "DENSE_MAX", k // 2)  # the extension takes the sparse sums
    ata, atz = P.extend_normal(hf.xy, hf.z, sparse_first, st.centers, st.widths, weights, 3.5)
    assert sparse.issparse(ata)
    assert np.allclose(ata.toarray(), dense_ata, rtol=1e-12, atol=1e-12 * abs(dense_ata).max())
    assert np.allclose(atz, dense_atz, rtol=1e-12, atol=1e-12 * abs(dense_atz).max())
    monkeypatch.setattr(P, "TILE_ABOVE", k // 4)
    monkeypatch.setattr(P, "TILE_NEURONS", k // 4)
    base = np.r_[first.a0, first.weights, np.zeros(8)]
    tail = (first.a0, st.centers, st.widths, weights, 3.5, 1e-4, np.inf)
    by_dense, n_dense = P.solve_and_drop(hf.xy, hf.z, dense_ata, dense_atz, *tail,
                                         base=base, give_back=0.5)
    monkeypatch.setattr(P, "IDLE_MAX_NEURONS", k // 2)
    assert P.solve_and_drop(hf.xy, hf.z, ata, atz, *tail, base=base) is None
    by_sparse, n_sparse = P.solve_and_drop(hf.xy, hf.z, ata, atz, *tail, base=base,
                                           give_back=0.5, strips=True)
    assert 0 < n_sparse == n_dense < k
    assert np.array_equal(by_sparse.widths, by_dense.widths)
    assert np.allclose(by_sparse.weights, by_dense.weights, rtol=1e-9, atol=1e-12)
