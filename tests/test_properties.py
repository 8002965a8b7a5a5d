"""Property tests (hypothesis): random height fields, scales, seeds and learning parameters.

Whatever the data and the parameters, a fit yields finite parameters, positive widths,
a finite surface, counters that add up, and an error no worse than the best constant.
Same seed, same bytes, in another process too.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import asrbf_mesh as am

PROPERTY = settings(max_examples=25, deadline=None, derandomize=True,
                    suppress_health_check=[HealthCheck.too_slow])


def height_field(seed: int, n: int, bumps: int, roughness: float, noise: float) -> np.ndarray:
    """(n, 3) points of a random sum of Gaussian bumps and a ramp on the unit square."""
    rng = np.random.default_rng(seed)
    xy = rng.random((n, 2))
    c = rng.random((bumps, 2))
    a = rng.normal(0.0, 1.0, bumps)
    s = rng.uniform(0.03, 0.5, bumps) / (1.0 + roughness)
    d2 = ((xy[:, None, :] - c[None]) ** 2).sum(-1)
    z = (a * np.exp(-d2 / (2 * s**2))).sum(1) + rng.normal(0, 0.3) * xy[:, 0]
    z = z + noise * rng.standard_normal(n)
    return np.column_stack([xy, z])


fields = st.builds(height_field, seed=st.integers(0, 2**32 - 1), n=st.integers(30, 300),
                   bumps=st.integers(0, 12), roughness=st.floats(0.0, 8.0),
                   noise=st.sampled_from([0.0, 1e-3, 0.05]))
scales = st.tuples(st.sampled_from([1e-6, 1e-3, 1.0, 250.0, 1e6]),  # x, y scale
                   st.sampled_from([1e-3, 1.0, 40.0]),                # depth scale
                   st.floats(-1e4, 1e4))                              # shift
configs = st.fixed_dictionaries({
    "error_threshold": st.sampled_from([0.001, 0.01, 0.05]),
    "psi": st.floats(0.3, 1.0),
    "d_max": st.sampled_from([0.2, 0.4, 0.8]),
    "passes": st.integers(1, 2),
    "update": st.sampled_from(["nekf", "nekf-neighbourhood", "gd"]),
    "pruning": st.sampled_from(["none", "literal", "support"]),
    "polish": st.sampled_from(["none", "weights", "full"]),
    "measurement_noise": st.sampled_from([1e-4, 0.01, 1.0]),
})


# Random sparse or noisy fields often look folded to the height-field check (the
# fold heuristic's false positives on such data are a known limitation): not tested here.
@pytest.mark.filterwarnings("ignore::asrbf_mesh.HeightFieldWarning")
@PROPERTY
@given(pts=fields, scale=scales, cfg=configs, seed=st.integers(0, 2**31))
def test_any_fit_is_finite_and_no_worse_than_a_constant(pts, scale, cfg, seed) -> None:
    sxy, sz, shift = scale
    pts = pts * np.array([sxy, sxy * 0.7, sz]) + shift
    net = am.fit(pts, seed=seed, progress=False, **cfg)
    for arr in (net.centers, net.widths, net.weights):
        assert np.all(np.isfinite(arr))
    assert all(np.isfinite(p.a0) for p in net.pieces)
    assert np.all(net.widths > 0)
    log = net.log_counters() or {"added": 0, "pruned": 0, "diverged": 0}
    # neurons: learned, less those dropped as weak, plus the tail refinement's and the
    # small fragments' (three each, fitted without learning)
    small = sum(p.n_neurons for p in net.pieces if p.log is None)
    assert (log["added"] - log["pruned"] - log["diverged"] - net.info["weak_pruned"]
            + net.info["tail_neurons"] + small == net.n_neurons)
    for p in net.pieces:
        if p.log is not None:
            assert np.all(np.isfinite(p.log.rms)) and np.all(np.isfinite(p.log.mean_width))
    # evaluated anywhere in (and around) the data: finite
    lo, hi = pts[:, :2].min(0), pts[:, :2].max(0)
    q = lo + (hi - lo) * np.random.default_rng(seed).uniform(-0.5, 1.5, (500, 2))
    assert np.all(np.isfinite(net.evaluate(q)))
    # the error is bounded: no worse than the best constant (the median) by more than
    # a margin, once a polish has solved the weights. The paper's sequential network
    # alone (polish "none") is not bounded so: on 30 random points with narrow neurons
    # (psi 0.31, E 0.001, one pass) it ends at twice the constant's error, before and
    # after the piecewise model; nor where most points lie on folds and the polish is
    # skipped (a plane 100 times steeper than wide: height_field(0, 153, 0, 0, 0) at
    # scale (1e-6, 1e-3, 0))
    from asrbf_mesh._learn import FOLD_NO_POLISH

    z = net.frame.to_unit(pts)[:, 2]
    const = float(np.mean(np.abs(z - np.median(z))))
    if cfg["polish"] != "none" and am.to_height_field(pts).fold <= FOLD_NO_POLISH:
        assert net.info["ebar"] <= 1.5 * const + 1e-9


@pytest.mark.filterwarnings("ignore::asrbf_mesh.HeightFieldWarning")
@PROPERTY
@given(pts=fields, scale=scales, seed=st.integers(0, 2**31),
       spacing=st.sampled_from([0.3, 1.0, 2.5]))
def test_a_reconstruction_on_the_scans_triangles_is_finite(pts, scale, seed, spacing) -> None:
    """On the scan's own triangles (the default, where vertices may take the scan's depth
    or a shelf), any fit's reconstruction and LOD levels have finite vertices, unit
    normals and valid triangles, at grids finer and coarser than the scan."""
    from scipy.spatial import Delaunay

    sxy, sz, shift = scale
    pts = pts * np.array([sxy, sxy * 0.7, sz]) + shift
    net = am.fit(pts, seed=seed, progress=False, passes=1)
    scan = am.Scan(pts, Delaunay(pts[:, :2]).simplices)
    step = spacing * float(np.ptp(pts[:, 0])) / np.sqrt(len(pts))
    for mode in ("surface", "scan"):
        mesh = am.reconstruct(net, footprint=scan, mode=mode, spacing_abs=step)
        assert np.all(np.isfinite(mesh.vertices))
        assert np.allclose(np.linalg.norm(mesh.vertex_normals, axis=1), 1.0)
        assert mesh.faces.min() >= 0 and mesh.faces.max() < len(mesh.vertices)
    lod = am.lod_set(scan, levels=2, net=net, seed=seed)
    assert all(np.all(np.isfinite(lv.mesh.vertices)) for lv in lod)


@pytest.mark.filterwarnings("ignore::asrbf_mesh.HeightFieldWarning")
@PROPERTY
@given(pts=fields, seed=st.integers(0, 2**31))
def test_save_load_evaluate_is_exact(tmp_path_factory, pts, seed) -> None:
    net = am.fit(pts, seed=seed, progress=False, passes=1)
    path = net.save(tmp_path_factory.mktemp("rt") / "n.asrbf")
    back = am.Network.load(path)
    q = np.random.default_rng(seed).random((200, 2))
    assert back.evaluate(q).tobytes() == net.evaluate(q).tobytes()
    assert back.save(path.with_name("again.asrbf")).read_bytes() == path.read_bytes()


def test_same_seed_same_bytes_in_another_process(tmp_path: Path, syn) -> None:
    src = tmp_path / "franke.npy"
    np.save(src, syn.franke_points(30))
    outs = []
    for run in ("a", "b"):
        d = tmp_path / run
        d.mkdir()
        for argv in (["fit", src, "-o", d / "n.asrbf", "--seed", "5"],
                     ["reconstruct", d / "n.asrbf", "-o", d / "s.ply", "--resolution", "50"]):
            done = subprocess.run([sys.executable, "-m", "asrbf_mesh.cli", *map(str, argv)],
                                  capture_output=True, text=True, timeout=300)
            assert done.returncode == 0, done.stderr
        outs.append([(d / f).read_bytes() for f in ("n.asrbf", "s.ply")])
    assert outs[0] == outs[1]


@pytest.mark.parametrize("seed", [0, 1])
def test_pickled_network_evaluates_identically(franke_net: am.Network, seed: int) -> None:
    import pickle

    back = pickle.loads(pickle.dumps(franke_net, protocol=pickle.HIGHEST_PROTOCOL))
    q = np.random.default_rng(seed).random((300, 2)) * 80 + [100, 20]
    assert back.evaluate(q).tobytes() == franke_net.evaluate(q).tobytes()
