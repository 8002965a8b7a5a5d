"""Filling range grids directly on the grid (:func:`asrbf_mesh._grid_fill.fill_grid`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from asrbf_mesh._grid_fill import fill_grid, grid_holes
from asrbf_mesh._range import RangeGrid, read_grid_array
from asrbf_mesh._range_write import write_like
from asrbf_mesh.errors import ConfigError, ScanError

DATA = Path(__file__).parent / "data"


def _smooth(n: int = 64) -> np.ndarray:
    r, c = np.mgrid[:n, :n].astype(np.float64)
    return 100.0 + 8.0 * np.sin(c / 11.0) * np.cos(r / 9.0) + 0.05 * c + 0.02 * r * r / n


def _disk(shape: tuple[int, int], cy: float, cx: float, rad: float) -> np.ndarray:
    r, c = np.mgrid[:shape[0], :shape[1]]
    return (r - cy) ** 2 + (c - cx) ** 2 <= rad * rad


@pytest.fixture(scope="module")
def smooth_case():
    truth = _smooth()
    voids = _disk(truth.shape, 20, 20, 5) | _disk(truth.shape, 42, 44, 3.5)
    edge = _disk(truth.shape, 63, 30, 4)  # open to the bottom border
    z = np.where(voids | edge, np.nan, truth)
    grid = RangeGrid(z, "elevation", cell=(2.0, 2.0))
    return grid, truth, voids, edge, fill_grid(grid, seed=0)


def test_smooth_voids_filled_close_to_truth(smooth_case) -> None:
    grid, truth, voids, _, res = smooth_case
    assert res.z_filled.shape == grid.shape
    assert np.array_equal(res.filled_mask, voids)
    assert np.all(np.isfinite(res.z_filled[voids]))
    zr = np.ptp(truth)
    rms = np.sqrt(np.mean((res.z_filled[voids] - truth[voids]) ** 2))
    assert rms < 0.01 * zr, rms / zr
    # the valid cells are untouched
    keep = np.isfinite(grid.z)
    assert np.array_equal(res.z_filled[keep], grid.z[keep])
    assert len(res.holes) == 2 and res.holes_filled == 2
    assert res.holes[0].cells > res.holes[1].cells  # largest first
    assert all(h.filled and h.reason is None and h.side is None for h in res.holes)
    assert res.seconds >= res.fit_seconds > 0


def test_border_open_voids_stay_nodata(smooth_case) -> None:
    _, _, _, edge, res = smooth_case
    assert np.all(np.isnan(res.z_filled[edge]))
    assert not res.filled_mask[edge].any()
    assert res.border_cells == int(edge.sum())
    d = res.to_dict()
    assert d["holes_found"] == 2 and d["border_cells"] == int(edge.sum())


def test_max_hole_size_respected(smooth_case) -> None:
    grid, _, voids, _, res = smooth_case
    small, big = sorted(res.holes, key=lambda h: h.size_abs)
    limit = 0.5 * (small.size_abs + big.size_abs)
    out = fill_grid(grid, res.network, max_hole_size=limit)
    by_index = {h.index: h for h in out.holes}
    assert by_index[big.index].filled is False
    assert "larger than max_hole_size" in by_index[big.index].reason
    assert by_index[small.index].filled
    assert out.filled_mask.sum() == small.cells
    pct = 100.0 * limit / np.hypot(63 * 2.0, 63 * 2.0)
    out2 = fill_grid(grid, res.network, max_hole_size=f"{pct}%")
    assert np.array_equal(out2.filled_mask, out.filled_mask)
    # given the same network, the fill of the small hole is the same
    assert np.allclose(out.z_filled[out.filled_mask], res.z_filled[out.filled_mask])
    assert out.fit_seconds == 0.0
    assert voids.sum() == res.filled_mask.sum()


def test_grid_holes_are_eight_connected() -> None:
    m = np.zeros((6, 6), dtype=bool)
    m[2, 2] = m[3, 3] = True  # diagonal neighbours: one hole
    m[0, 4] = True  # on the border: outside
    labels, holes, border = grid_holes(m)
    assert len(holes) == 1 and sorted(holes[0].tolist()) == [14, 21]
    assert border == 1 and labels[0, 4] == 0


@pytest.mark.parametrize("metric", [True, False], ids=["intrinsics", "pixels"])
def test_shadow_hole_filled_from_far_side(metric: bool) -> None:
    # a depth image: a far wall at 2 m (tilted a little) with a near box at 1.2 m on the
    # right; the Kinect shadow (no data) lies left of the box's edge, on the wall
    H, W = 60, 80
    fx = fy = 300.0
    cx, cy = W / 2, H / 2
    r, c = np.mgrid[:H, :W].astype(np.float64)
    wall = 2.0 + 0.002 * (c - cx)
    depth = wall.copy()
    box = (r >= 12) & (r < 48) & (c >= 50) & (c < 70)
    depth[box] = 1.2
    shadow = (r >= 12) & (r < 48) & (c >= 44) & (c < 50)
    depth[shadow] = np.nan
    grid = RangeGrid(depth, "depth", intrinsics=(fx, fy, cx, cy) if metric else None)
    res = fill_grid(grid, seed=0)
    assert len(res.holes) == 1
    h = res.holes[0]
    assert h.filled and h.side == "far"
    got = res.z_filled[shadow]
    assert np.all(np.isfinite(got))
    assert np.max(np.abs(got - wall[shadow])) < 0.01  # the wall, not the box
    assert np.array_equal(res.filled_mask, shadow)


def test_depth_hole_without_edge_uses_both_sides() -> None:
    H, W = 48, 48
    r, c = np.mgrid[:H, :W].astype(np.float64)
    truth = 1.5 + 0.003 * c + 0.002 * r + 0.02 * np.sin(c / 8.0)
    hole = _disk((H, W), 24, 24, 4)
    grid = RangeGrid(np.where(hole, np.nan, truth), "depth", intrinsics=(400.0, 400.0, 24, 24))
    res = fill_grid(grid, seed=0)
    assert res.holes[0].side is None and res.holes[0].filled
    assert np.max(np.abs(res.z_filled[hole] - truth[hole])) < 0.005


def test_jacksboro_crop_void(tmp_path: Path) -> None:
    src = read_grid_array(DATA / "jacksboro_crop.npz")
    truth = src.z
    void = _disk(truth.shape, 30, 34, 6)
    grid = RangeGrid(np.where(void, np.nan, truth), "elevation", cell=src.cell,
                     origin=src.origin, source=src.source, fmt=src.fmt, dtype=src.dtype,
                     extra=src.extra, key=src.key)
    res = fill_grid(grid, seed=0)
    assert np.array_equal(res.filled_mask, void)
    err = res.z_filled[void] - truth[void]
    assert np.sqrt(np.mean(err ** 2)) < 0.06 * np.ptp(truth)
    # written back in kind: the void holds numbers again
    out = tmp_path / "filled.npz"
    write_like(grid, res.z_filled, out)
    back = read_grid_array(out)
    assert np.all(np.isfinite(back.z)) and np.max(np.abs(back.z - res.z_filled)) <= 0.5


def test_bad_inputs(smooth_case) -> None:
    grid, _, _, _, res = smooth_case
    with pytest.raises(ScanError, match="RangeGrid"):
        fill_grid(np.zeros((4, 4)))  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="net must be a Network"):
        fill_grid(grid, "net")  # type: ignore[arg-type]
    for bad in (-1, 0, "inf", "150%", "x"):
        with pytest.raises(ConfigError, match="max_hole_size"):
            fill_grid(grid, res.network, max_hole_size=bad)
    with pytest.raises(ConfigError, match="seed"):
        fill_grid(grid, res.network, seed=-1)
    with pytest.raises(ConfigError, match="pieces"):
        fill_grid(grid, res.network, pieces="many")
    with pytest.raises(ScanError, match="no cell holds a measurement"):
        fill_grid(RangeGrid(np.full((5, 5), np.nan), "elevation", cell=1.0))


def test_membrane_reproduces_a_plane_and_keeps_to_the_allowed_side() -> None:
    from asrbf_mesh._grid_fill import _membrane

    r, c = np.mgrid[:30, :40].astype(np.float64)
    plane = 2.0 + 0.3 * c - 0.1 * r  # harmonic: the membrane is exact
    hole_mask = _disk(plane.shape, 15, 20, 6)
    valid = ~hole_mask
    z = np.where(valid, plane, np.nan).ravel()
    hole = np.flatnonzero(hole_mask)
    out = _membrane(hole, None, valid, z)
    assert np.allclose(out, plane.ravel()[hole], atol=1e-6)
    # only the right-hand side as boundary: a constant there gives that constant
    right = np.flatnonzero((c.ravel() > 20) & valid.ravel())
    z2 = np.where(valid.ravel(), np.where(c.ravel() > 20, 5.0, -100.0), np.nan)
    out2 = _membrane(hole, right, valid, z2)
    assert np.allclose(out2, 5.0, atol=1e-6)


def test_a_hole_the_spline_cannot_fill_gets_a_membrane(smooth_case, monkeypatch) -> None:
    import asrbf_mesh._grid_fill as gf

    grid, truth, voids, _, res = smooth_case
    monkeypatch.setattr(gf, "_fill_hole", lambda hole, *a: (np.zeros(0), 0, None,
                                                            "the fill is not finite"))
    out = fill_grid(grid, res.network)
    assert out.holes_filled == 2 and all(h.side == "membrane" for h in out.holes)
    assert np.all(np.isfinite(out.z_filled[voids]))
    lo, hi = np.nanmin(grid.z), np.nanmax(grid.z)
    assert np.all((out.z_filled[voids] >= lo) & (out.z_filled[voids] <= hi))


def test_a_large_ring_keeps_its_rim_and_thins_the_rest() -> None:
    from asrbf_mesh._grid_fill import _GRID_RING_MAX, _thin_ring

    g = np.stack(np.meshgrid(np.arange(80.0), np.arange(80.0)), -1).reshape(-1, 2)
    ring = np.arange(len(g)) * 3  # flat cell ids, any order-preserving labels
    rim = ring[(np.abs(g[:, 0] - 40) <= 1) & (g[:, 1] < 60)]  # 180 rim cells
    keep = _thin_ring(ring, g, rim)
    assert len(keep) <= _GRID_RING_MAX and np.all(np.diff(keep) > 0)
    assert np.isin(rim, ring[keep]).all()  # every rim cell kept
    far = ring[keep][~np.isin(ring[keep], rim)]
    assert 100 <= len(far) <= _GRID_RING_MAX - len(rim)  # the rest: thinned into the budget
    small = np.arange(50)
    assert np.array_equal(_thin_ring(small, g[:50], small[:5]), np.arange(50))
