"""Sequential learning (Algorithm 1): accuracy, growth, decay, pruning, updaters,
determinism, invariance, the fit log and the info of a fitted network.

Thresholds carry a margin over the values measured when these tests were written
(quoted next to each assertion).
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import asrbf_mesh as am
from asrbf_mesh._config import LOCAL_WIDTH, FitConfig
from asrbf_mesh._frame import HeightFieldWarning, to_height_field
from asrbf_mesh._learn import MIN_POINTS, LearnedState, auto_d_min, learn, residuals
from asrbf_mesh.errors import ScanError

SEQ = {"polish": "none", "progress": False}  # the paper's method, no batch stage


def fit(pts, config: FitConfig | None = None, *, seed: int = 0, **kw) -> am.Network:
    kw.setdefault("progress", False)
    return am.fit(pts, config, seed=seed, **kw)


@pytest.fixture(scope="module")
def franke40(syn) -> np.ndarray:
    return syn.franke_points(40)  # 1,600 points


@pytest.fixture(scope="module")
def franke39(syn) -> np.ndarray:
    return syn.franke_points(39)  # 1,521 points, for the O(K^2) GEKF


# ----------------------------------------------------------------------------- accuracy


def test_default_fit_reaches_small_ebar(franke_net: am.Network) -> None:
    info = franke_net.info
    # measured: ebar 0.0011 (polished), ebar_sequential 0.0039, K 595 of 3,600 points
    assert info["ebar"] < 0.004
    assert info["ebar_sequential"] < 0.01
    assert info["ebar"] <= info["ebar_sequential"]
    assert 20 < franke_net.n_neurons < 3600 / 2


@pytest.mark.parametrize(("name", "limit"), [("plane", 0.008), ("bump", 0.02),
                                             ("franke", 0.015)])
def test_sequential_fit_of_analytic_surfaces(syn, name: str, limit: float) -> None:
    # measured (passes=2, no polish): plane 0.0023, bump 0.0055, franke 0.0033
    pts = syn.points(getattr(syn, name), 50, seed=1)
    net = fit(pts, **SEQ)
    assert net.info["ebar"] < limit
    # the unit-cube E-bar is the mean |depth error| over the depth span
    assert net.info["error_mean"] == pytest.approx(net.info["ebar"] * net.frame.scale[2],
                                                   rel=1e-9)


def test_info_ebar_is_the_mean_absolute_residual(franke_points, franke_net) -> None:
    hf = to_height_field(franke_points)
    res = residuals(franke_net, hf)
    assert franke_net.info["ebar"] == pytest.approx(np.mean(np.abs(res)), rel=1e-12)
    np.testing.assert_allclose(res, hf.z - franke_net.evaluate(hf.xy, unit=True))
    mm = np.abs(franke_net.evaluate(franke_points[:, :2]) - franke_points[:, 2])
    assert franke_net.info["error_mean"] == pytest.approx(mm.mean(), rel=1e-6)
    assert franke_net.info["error_std"] == pytest.approx(mm.std(), rel=1e-6)


def test_info_keys(franke_net: am.Network) -> None:
    info = franke_net.info
    for key in ("n_points", "ebar", "error_mean", "error_std", "steps", "fit_seconds",
                "us_per_step", "n_neurons", "seed", "spacing", "d_min", "source_sha256",
                "ebar_sequential", "learn_seconds", "polish_seconds", "version"):
        assert key in info, key
    assert info["n_points"] == 3600
    assert info["n_neurons"] == franke_net.n_neurons
    assert info["steps"] == 3600 * franke_net.config.passes
    assert info["seed"] == 0
    assert info["fit_seconds"] > 0 and info["us_per_step"] > 0
    assert info["version"] == am.__version__
    assert len(info["source_sha256"]) == 64
    assert info["d_min"] == pytest.approx(
        min(auto_d_min(info["spacing"], franke_net.config.error_threshold),
            franke_net.config.d_max))


# ----------------------------------------------------------------------------- growth


def test_larger_error_threshold_grows_fewer_neurons(franke_points) -> None:
    # measured K (3,600 points, one pass): E=0.005 -> 635, 0.02 -> 211, 0.05 -> 48
    ks = [fit(franke_points, error_threshold=e, passes=1, **SEQ).n_neurons
          for e in (0.005, 0.02, 0.05)]
    assert ks[0] > ks[1] > ks[2]
    assert ks[2] < ks[0] / 3


def test_larger_d_min_grows_fewer_neurons(franke_points) -> None:
    # measured K: D_min 0.02 -> 660, 0.04 -> 286, 0.08 -> 101, 0.16 -> 34
    ks = [fit(franke_points, d_min=d, passes=1, **SEQ).n_neurons
          for d in (0.02, 0.04, 0.08, 0.16)]
    assert ks == sorted(ks, reverse=True) and len(set(ks)) == 4
    assert ks[-1] < 60
    # a separation of 0.16 fits at most a dozen of centres per unit length
    assert ks[-1] < (1.5 / 0.16) ** 2


@pytest.mark.parametrize("d", [0.05, 0.15])
def test_growth_criteria_hold_at_insertion(franke40, d: float) -> None:
    # constant separation D and a negligible gradient step: every neuron keeps the
    # parameters it was born with, so the growth rules can be read off the network
    e, psi = 0.02, 0.7
    net = fit(franke40, d_max=d, d_min=d, error_threshold=e, psi=psi, update="gd",
              gd_rate=1e-12, pruning="none", passes=1, **SEQ)
    assert net.n_neurons > 10
    # criterion 1: a new centre is farther than D from every existing one
    c = net.centers
    d2 = ((c[:, None, :] - c[None, :, :]) ** 2).sum(-1) + np.eye(len(c))
    assert np.sqrt(d2.min()) > d * (1 - 1e-9)
    # criterion 2: a new weight is the residual, larger than E
    assert np.abs(net.weights).min() > e * (1 - 1e-6)
    # eq. 7: width = psi x distance to the nearest centre (>= psi D)
    assert net.widths.min() == pytest.approx(psi * d, rel=1e-9)
    # centres are observations
    hf = to_height_field(franke40)
    dist = np.sqrt(((hf.xy[None, :, :] - c[:, None, :]) ** 2).sum(-1)).min(axis=1)
    assert dist.max() < 1e-9


def test_rms_threshold_above_every_error_blocks_growth(franke40) -> None:
    # criterion 3 never holds: no neuron grows, the bias alone is a valid network
    net = fit(franke40, rms_threshold=5.0, **SEQ)
    assert net.n_neurons == 0 and net.log.added == 0
    assert np.isfinite(net.a0)


def test_literal_eq4_decay_stalls(franke_points) -> None:
    # measured: decay='neurons' stops at K = 8, decay='observation' grows to ~600
    literal = fit(franke_points, decay="neurons", **SEQ)
    observation = fit(franke_points, decay="observation", **SEQ)
    assert literal.n_neurons < 40
    assert observation.n_neurons > 3 * literal.n_neurons
    assert observation.info["ebar"] < literal.info["ebar"]


def test_pass_decay_reaches_d_min_at_its_share_of_the_first_pass(franke_points) -> None:
    # decay="pass" is the observation decay with gamma = (D_min / D_max) ** (1 / (f N))
    n = len(franke_points)
    short = fit(franke_points, decay="pass", decay_fraction=0.05, **SEQ)
    d_min, d_max = short.info["d_min"], short.config.d_max
    gamma = (d_min / d_max) ** (1.0 / (0.05 * n))
    same = fit(franke_points, decay="observation", gamma=gamma, **SEQ)
    np.testing.assert_array_equal(short.centers, same.centers)
    np.testing.assert_array_equal(short.weights, same.weights)
    # a longer wide-to-narrow phase: fewer, wider neurons than gamma = 0.99
    long = fit(franke_points, decay="pass", decay_fraction=0.5, **SEQ)
    today = fit(franke_points, **SEQ)
    assert long.n_neurons < today.n_neurons
    assert np.median(long.widths) > np.median(today.widths)


def test_max_neurons_caps_k_with_a_warning(franke39) -> None:
    for cap in (5, 20):
        with pytest.warns(am.NeuronCapWarning, match=f"stopped growth at K = {cap}: "):
            net = fit(franke39, max_neurons=cap, pruning="none", **SEQ)
        assert net.n_neurons == cap
        assert net.log.n_neurons.max() <= cap
        assert net.log.capped > 0
        assert net.log.counters()["capped"] == net.log.capped
    with warnings.catch_warnings():
        warnings.simplefilter("error", am.NeuronCapWarning)
        free = fit(franke39, pruning="none", **SEQ)
        roomy = fit(franke39, pruning="none", max_neurons=free.n_neurons, **SEQ)
    assert free.n_neurons > 20 and free.log.capped == 0
    # a cap the fit never reaches changes nothing, bit for bit
    assert roomy.log.capped == 0
    np.testing.assert_array_equal(roomy.weights, free.weights)


def test_error_threshold_above_the_depth_range_blocks_growth(franke40) -> None:
    # no observation is badly fitted enough to grow a neuron: a bias-only network
    net = fit(franke40, error_threshold=2.0, **SEQ)
    assert net.n_neurons == 0
    z = net.evaluate(np.zeros((3, 2)) + franke40[:3, :2])
    assert np.all(np.isfinite(z)) and np.ptp(z) == 0


# ----------------------------------------------------------------------------- pruning


def test_pruning_none_keeps_every_neuron(franke_points) -> None:
    net = fit(franke_points, pruning="none", prune_threshold=0.05, prune_window=200, passes=1,
              **SEQ)
    assert net.log.pruned == 0
    assert net.log.added == net.n_neurons
    assert net.log.diverged == 0


@pytest.mark.parametrize("rule", ["literal", "support"])
def test_pruning_rules_remove_neurons(franke_points, rule: str) -> None:
    # measured (P = 0.05, window 200, one pass): literal prunes 1679 of 1792 added,
    # support 40 of 620
    net = fit(franke_points, pruning=rule, prune_threshold=0.05, prune_window=200, passes=1,
              **SEQ)
    log = net.log
    assert log.pruned > 0
    assert log.added - log.pruned - log.diverged == net.n_neurons
    assert log.n_neurons[-1] <= log.added


def test_literal_pruning_prunes_with_paper_defaults(franke_points) -> None:
    # measured: 41 of 590 pruned in one pass over 3,600 points (P = 0.001, omega = 1000)
    net = fit(franke_points, pruning="literal", passes=1, **SEQ)
    assert net.log.pruned > 0
    assert net.log.added - net.log.pruned - net.log.diverged == net.n_neurons


def test_literal_pruning_prunes_more_than_support_pruning(franke_points) -> None:
    kw = {"prune_threshold": 0.05, "prune_window": 200, "passes": 1, **SEQ}
    literal = fit(franke_points, pruning="literal", **kw)
    support = fit(franke_points, pruning="support", **kw)
    assert literal.log.pruned > support.log.pruned


# ----------------------------------------------------------------------------- updaters


@pytest.mark.parametrize(("update", "limit"), [("nekf", 0.03), ("nekf-neighbourhood", 0.012),
                                               ("gekf", 0.01), ("gd", 0.012)])
def test_every_updater_learns(franke39, update: str, limit: float) -> None:
    # measured E-bar (1,521 points, one pass, no polish): nekf 0.0147,
    # nekf-neighbourhood 0.0040, gekf 0.0028, gd 0.0047
    net = fit(franke39, update=update, passes=1, **SEQ)
    assert net.config.update == update
    assert net.n_neurons > 10
    for arr in (net.centers, net.widths, net.weights):
        assert np.all(np.isfinite(arr))
    assert np.isfinite(net.a0)
    assert np.all((net.widths >= 1e-5) & (net.widths <= 2.0))
    assert np.all((net.centers >= -0.25) & (net.centers <= 1.25))
    assert net.info["ebar"] < limit
    assert net.log.diverged == 0


# ----------------------------------------------------------------------------- determinism


def test_same_seed_is_bit_identical(franke40) -> None:
    a = fit(franke40, seed=7)
    b = fit(franke40, seed=7)
    assert a.a0 == b.a0
    for name in ("centers", "widths", "weights"):
        assert getattr(a, name).tobytes() == getattr(b, name).tobytes()
    for name in ("step", "n_neurons", "rms", "mean_width", "mean_weight"):
        np.testing.assert_array_equal(getattr(a.log, name), getattr(b.log, name))
    assert a.log.counters() == b.log.counters()


def test_different_seeds_differ(franke40) -> None:
    a = fit(franke40, seed=1, **SEQ)
    b = fit(franke40, seed=2, **SEQ)
    assert a.n_neurons != b.n_neurons or not np.array_equal(a.centers, b.centers)
    # but both fit: measured E-bar 0.0030 and 0.0034
    assert a.info["ebar"] < 0.015 and b.info["ebar"] < 0.015


def test_a_local_step_holds_a_wide_neuron_in_place(franke40) -> None:
    """A neuron wider than local_width x D takes its NEKF step scaled by local_width D / sigma."""
    hf = to_height_field(franke40)
    base = {"passes": 1, "pruning": "none"}
    paper = learn(hf, FitConfig(**base), seed=3)  # None: the paper's step, as 0
    off = learn(hf, FitConfig(**base, local_width=0.0), seed=3)
    for name in ("centers", "widths", "weights"):
        assert getattr(paper, name).tobytes() == getattr(off, name).tobytes()

    def moved(st: LearnedState) -> np.ndarray:  # each centre's distance from its point
        d = np.linalg.norm(st.centers[:, None, :] - hf.xy[None, :, :], axis=2)
        return d.min(axis=1)

    # every neuron is born on an observation; with a vanishing local width no step
    # moves it (measured: at most 9e-10), with the paper's step they travel (0.08)
    held = learn(hf, FitConfig(**base, local_width=1e-9), seed=3)
    assert moved(held).max() < 1e-6
    assert moved(off).max() > 1e-3


def test_the_pieces_keep_their_steps_local(franke40) -> None:
    x, y = np.meshgrid(np.linspace(0, 1, 40), np.linspace(0, 1, 40))
    cliff = np.c_[x.ravel(), y.ravel(), np.where(x < 0.5, 0.0, 0.5).ravel()]
    assert fit(cliff).n_pieces == 2
    assert fit(cliff).config.local_width == LOCAL_WIDTH == 8.0
    assert fit(cliff, local_width=2.0).config.local_width == 2.0
    # one network learns as the paper's: pieces=1, and a scan of one piece
    assert fit(cliff, pieces=1).config.local_width == 0.0
    assert fit(franke40).n_pieces == 1 and fit(franke40).config.local_width == 0.0


def test_learn_returns_the_raw_state(franke40) -> None:
    hf = to_height_field(franke40)
    st = learn(hf, FitConfig(passes=1), seed=3)
    assert isinstance(st, LearnedState)
    k = len(st.widths)
    assert st.centers.shape == (k, 2) and st.weights.shape == (k,)
    assert st.steps == hf.n_points
    assert st.log.added - st.log.pruned - st.log.diverged == k
    # the raw state is the sequential network of fit(..., polish='none')
    net = fit(franke40, seed=3, passes=1, **SEQ)
    np.testing.assert_array_equal(net.centers, st.centers)
    np.testing.assert_array_equal(net.weights, st.weights)
    assert net.a0 == st.a0


# ----------------------------------------------------------------------------- fit log


def test_fit_log_is_consistent(franke_net: am.Network) -> None:
    log = franke_net.log
    assert log is not None
    n = len(log.step)
    assert n > 100
    for name in ("n_neurons", "rms", "mean_width", "mean_weight"):
        assert len(getattr(log, name)) == n
    assert log.step[0] == 0
    assert np.all(np.diff(log.step) > 0)
    assert log.step[-1] < franke_net.info["steps"]
    assert np.all(log.n_neurons <= log.added)
    assert np.all(log.n_neurons >= 0)
    # after learning, the default model drops weak neurons and adds tail ones
    weak, tails = franke_net.info["weak_pruned"], franke_net.info["tail_neurons"]
    assert log.n_neurons[-1] <= franke_net.n_neurons + log.pruned + log.diverged + weak
    assert np.all(log.rms >= 0)
    grown = log.n_neurons > 0
    assert np.all(np.isfinite(log.mean_width[grown])) and np.all(log.mean_width[grown] > 0)
    # before the first neuron (step 0) the means are 0, not NaN: the log is saved
    assert log.n_neurons[0] == 0 and log.mean_width[0] == 0 and log.mean_weight[0] == 0
    for name in ("rms", "mean_width", "mean_weight"):
        assert np.all(np.isfinite(getattr(log, name)))
    assert log.added - log.pruned - log.diverged - weak + tails == franke_net.n_neurons
    # the windowed RMS error falls while the network grows
    assert log.rms[-1] < log.rms[n // 10 : n // 5].max()


# ----------------------------------------------------------------------------- invariance


@pytest.mark.parametrize(("scale", "shift"), [(1e6, 1e9), (1e-6, 0.0), (1.0, 1e4)])
def test_scale_and_shift_invariance(franke40, scale: float, shift: float) -> None:
    ref = fit(franke40, seed=5)
    net = fit(franke40 * scale + shift, seed=5)
    assert net.n_neurons == ref.n_neurons
    for name in ("centers", "widths", "weights"):
        np.testing.assert_allclose(getattr(net, name), getattr(ref, name), rtol=0, atol=1e-9)
    assert net.a0 == pytest.approx(ref.a0, abs=1e-9)
    assert net.info["ebar"] == pytest.approx(ref.info["ebar"], rel=1e-6)
    np.testing.assert_allclose(net.frame.scale, ref.frame.scale * scale, rtol=1e-9)
    assert net.info["error_mean"] == pytest.approx(ref.info["error_mean"] * scale, rel=1e-6)


# ----------------------------------------------------------------------------- bad input


@pytest.mark.filterwarnings("ignore::asrbf_mesh.HeightFieldWarning")
def test_too_few_points(syn) -> None:
    pts = syn.franke_points(10)[: MIN_POINTS - 1]
    with pytest.raises(ScanError, match=f"at least {MIN_POINTS} points, got {MIN_POINTS - 1}"):
        fit(pts)
    with pytest.raises(ScanError, match="at least"):
        learn(to_height_field(pts))


@pytest.mark.parametrize("pts", [np.zeros((50, 2)), np.zeros(30)])
def test_bad_point_shapes(pts) -> None:
    with pytest.raises(ScanError, match=r"\(N, 3\) array"):
        fit(pts)


def test_fit_accepts_a_scan_and_overrides(franke40) -> None:
    scan = am.Scan(franke40, source="memory.xyz")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", am.NeuronCapWarning)
        net = fit(scan, FitConfig(passes=1), polish="none", max_neurons=30)
    assert net.info["source"] == "memory.xyz"
    assert net.config.passes == 1 and net.config.max_neurons == 30
    assert net.n_neurons <= 30
    with pytest.raises(am.ConfigError, match="passes"):
        fit(franke40, passes=0)


def test_flat_scan_fits(syn) -> None:
    pts = syn.flat_points(30, z=7.5)
    net = fit(pts)
    np.testing.assert_allclose(net.evaluate(pts[:, :2]), 7.5, atol=1e-9)


def test_auto_d_min_is_clamped() -> None:
    assert auto_d_min(1.0) == 0.2
    values = [auto_d_min(s) for s in (1e-5, 1e-4, 1e-3, 1e-2, 5e-2, 0.5)]
    assert values == sorted(values)
    assert all(0 < v <= 0.2 for v in values)
    assert auto_d_min(0.03) == pytest.approx(0.06)


def test_a_closed_surface_fits_in_seconds_not_minutes(syn) -> None:
    """A closed mesh (a sphere, bunny.obj) is no height field: its polish took 220 s for
    28,000 points (CG on front and back at once); it is skipped with a warning."""
    import time

    pts = syn.sphere_points(28_000, radius=50.0)
    t = time.perf_counter()
    with pytest.warns(HeightFieldWarning) as record:
        net = am.fit(pts, seed=0, progress=False)
    assert time.perf_counter() - t < 30
    assert any("polish is skipped" in str(w.message) for w in record)
    assert net.info["ebar_sequential"] == net.info["ebar"]


def test_slots_growing_mid_fit_count_each_observation_once(franke40, monkeypatch) -> None:
    """Starting from 4 slots (doubled 5 times during the fit) gives the very same network
    and log as starting with room for every neuron: a step interrupted to grow the slot
    arrays must not push its residual into the RMS window (or its log row) twice."""
    import asrbf_mesh._learn as learn_mod

    cfg = FitConfig(polish="none", passes=1)
    monkeypatch.setattr(learn_mod, "_SLOTS", 1 << 12)
    roomy = am.fit(franke40, cfg, seed=3, pieces=1)
    monkeypatch.setattr(learn_mod, "_SLOTS", 4)
    tight = am.fit(franke40, cfg, seed=3, pieces=1)
    assert roomy.n_neurons > 64
    assert np.array_equal(roomy.centers, tight.centers)
    assert np.array_equal(roomy.weights, tight.weights)
    assert np.array_equal(roomy.log.step, tight.log.step)
    assert np.array_equal(roomy.log.rms, tight.log.rms)


def test_gekf_beyond_its_neuron_limit_raises_instead_of_hanging(franke39, monkeypatch) -> None:
    import asrbf_mesh._learn as learn_mod
    from asrbf_mesh.errors import FitError

    monkeypatch.setattr(learn_mod, "_GEKF_MAX", 8)
    with pytest.raises(FitError, match="limited to 8 neurons"):
        am.fit(franke39, FitConfig(update="gekf", polish="none", passes=1), seed=0, pieces=1)


def test_each_learning_kernel_is_warmed_before_its_fit_is_timed(franke40) -> None:
    # one compiled kernel per updater, pruning rule and decay: a fit with another updater
    # after a default fit warms its own kernel first, so its learning time and
    # microseconds per step never include a compilation
    from asrbf_mesh import _learn
    from asrbf_mesh import _learn_kernels as lk

    hf = to_height_field(franke40)
    learn(hf, FitConfig(passes=1), seed=0)
    learn(hf, FitConfig(passes=1, update="gd", pruning="literal"), seed=0)
    assert {("nekf", "support", "observation"), ("gd", "literal", "observation")} \
        <= _learn._WARM
    gd = lk.run_steps_for(lk.UPDATE_GD, lk.PRUNE_LITERAL, lk.DECAY_OBSERVATION)
    assert gd is not lk.run_steps and gd.signatures  # its own kernel, compiled
    assert lk.run_steps_for(lk.UPDATE_GD, lk.PRUNE_LITERAL, lk.DECAY_OBSERVATION) is gd


def test_nearest_few_is_the_nearest_alive_centre_and_counts_ties() -> None:
    """Few neurons: the nearest centre among all slots, dead ones skipped, ties counted."""
    from asrbf_mesh._learn_cells import _nearest_few

    rng = np.random.default_rng(3)
    W = np.zeros((12, 4))
    W[:, 2:] = rng.uniform(size=(12, 2))
    alive = np.ones(12, dtype=np.int8)
    alive[[2, 7]] = 0
    for x, y in rng.uniform(size=(50, 2)):
        d2 = (W[:, 2] - x) ** 2 + (W[:, 3] - y) ** 2
        d2[alive == 0] = np.inf
        slot, best, ties = _nearest_few(x, y, W, alive, 12)
        assert (slot, best, ties) == (int(np.argmin(d2)), d2.min(), 0)
    W[4, 2:], W[9, 2:] = (0.25, 0.5), (0.75, 0.5)  # (0.5, 0.5) is as near to both
    W[[0, 1, 3, 5, 6, 8, 10, 11], 2:] = 5.0
    slot, best, ties = _nearest_few(0.5, 0.5, W, alive, 12)
    assert (slot, best, ties) == (4, 0.0625, 1)
    assert _nearest_few(0.5, 0.5, W, np.zeros(12, dtype=np.int8), 12)[0] == -1
