"""One network per smooth piece (private prototype, asrbf_mesh._pieces)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from _grids import grid_faces, height_grid

import asrbf_mesh as am
from asrbf_mesh._pieces import PieceFit, fit_pieces, piece_seed

NX, NY = 60, 30  # a range grid of unit spacing; the cliff runs along x = 30


def cliff(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """A smooth surface raised by ten spacings where x >= 30 (a vertical cliff)."""
    return 2.0 * np.sin(x / 9.0) * np.cos(y / 7.0) + np.where(x >= 29.5, 10.0, 0.0)


def cliff_scan(fragment: bool = False) -> am.Scan:
    pts, faces = height_grid(cliff, NX, NY, x=(0.0, NX - 1.0), y=(0.0, NY - 1.0))
    if fragment:  # a floating 5 x 2 fragment beside the grid, 30 up: a small piece
        fx, fy = np.meshgrid(np.arange(5.0) + NX + 4, np.arange(2.0) + 5)
        frag = np.c_[fx.ravel(), fy.ravel(), np.full(10, 30.0)]
        pts, faces = np.vstack([pts, frag]), np.vstack([faces, grid_faces(5, 2) + len(pts)])
    return am.Scan(pts, faces)


@pytest.fixture(scope="module")
def fitted() -> tuple[am.Scan, PieceFit]:
    scan = cliff_scan()
    return scan, fit_pieces(scan, seed=0)


def test_pieces_fit_the_cliff_far_better_than_one_network(fitted) -> None:
    scan, pf = fitted
    assert pf.segmentation.n_pieces == 2 and len(pf.networks) == 2
    single = am.fit(scan, seed=0, progress=False)
    assert pf.ebar < 0.3 * single.info["ebar"]  # measured 0.0017 vs 0.0144
    assert pf.n_neurons == sum(n.n_neurons for n in pf.networks) < single.n_neurons
    assert pf.n_points == scan.n_points and pf.seconds > 0


def test_every_point_has_a_piece_and_the_reported_ebar(fitted) -> None:
    scan, pf = fitted
    labels = pf.segmentation.labels
    np.testing.assert_array_equal(labels, (scan.points[:, 0] >= 29.5).astype(np.int64))
    hf = am.to_height_field(scan.points)
    f = np.empty(len(labels))
    for i, net in enumerate(pf.networks):
        f[labels == i] = net.evaluate(hf.xy[labels == i], unit=True)
    assert np.mean(np.abs(f - hf.z)) == pytest.approx(pf.ebar, rel=1e-12)


def test_the_networks_share_the_scans_frame(fitted) -> None:
    scan, pf = fitted
    frame = am.to_height_field(scan.points).frame
    for net in pf.networks:
        for name in ("rotation", "offset", "scale"):
            np.testing.assert_array_equal(getattr(net.frame, name), getattr(frame, name))
    assert pf.networks[0].frame is pf.networks[1].frame


def test_same_seed_same_networks(fitted) -> None:
    scan, pf = fitted
    again = fit_pieces(scan, seed=0)
    other = fit_pieces(scan, seed=1)
    for a, b in zip(pf.networks, again.networks, strict=True):
        assert a.a0 == b.a0
        for name in ("centers", "widths", "weights"):
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    assert pf.ebar == again.ebar
    assert other.networks[0].info["seed"] != pf.networks[0].info["seed"]
    assert pf.networks[0].info["seed"] == piece_seed(0, 0) != piece_seed(0, 1)


def test_a_tiny_fragment_gets_a_constant_network() -> None:
    scan = cliff_scan(fragment=True)
    pf = fit_pieces(scan, seed=0)
    seg = pf.segmentation
    assert seg.n_pieces == 3 and seg.small.tolist() == [False, False, True]
    frag = pf.networks[2]
    hf = am.to_height_field(scan.points)
    assert frag.n_neurons == 0 and frag.a0 == pytest.approx(hf.z[-10:].mean())
    assert pf.n_neurons == pf.networks[0].n_neurons + pf.networks[1].n_neurons
    assert pf.n_points == NX * NY + 10


def test_a_given_segmentation_is_used() -> None:
    scan = cliff_scan()
    seg = am.segment(scan, min_piece_points=2000)  # both pieces small: two constants
    pf = fit_pieces(scan, segmentation=seg)
    assert pf.segmentation is seg and pf.n_neurons == 0


@pytest.mark.parametrize("kw, name", [
    ({"config": {"passes": 2}}, "config"), ({"seed": -1}, "seed"), ({"seed": 1.5}, "seed"),
    ({"view_axis": "w"}, "view_axis"), ({"segmentation": "pieces"}, "segmentation"),
    ({"progress": "yes"}, "progress")])
def test_bad_arguments_raise_config_error(kw: dict, name: str) -> None:
    with pytest.raises(am.ConfigError, match=f"^{name}"):
        fit_pieces(cliff_scan(), **kw)


def test_a_segmentation_of_another_scan_or_axis_is_refused() -> None:
    scan = cliff_scan()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        other = am.segment(cliff_scan(fragment=True))
        along_x = am.segment(scan, view_axis="x")
    with pytest.raises(am.ConfigError, match="segmentation has 1,810 points"):
        fit_pieces(scan, segmentation=other)
    with pytest.raises(am.ConfigError, match="view_axis 'x'"):
        fit_pieces(scan, segmentation=along_x)
