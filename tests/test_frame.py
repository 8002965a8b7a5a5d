"""Frame and HeightField: view axes, normalization to the unit cube and back."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from asrbf_mesh._frame import (
    VIEW_AXES,
    Frame,
    HeightFieldWarning,
    sampling_spacing,
    to_height_field,
)
from asrbf_mesh.errors import ScanError

# world axis that carries the depth for each fixed view axis
DEPTH_AXIS = {"z": 2, "x": 0, "y": 1}


def height_field_along(points_z: np.ndarray, axis: int) -> np.ndarray:
    """Move the depth (last) column of z-view points onto world ``axis``."""
    a, b, d = points_z.T
    cols = {0: (d, a, b), 1: (b, d, a), 2: (a, b, d)}[axis]
    return np.column_stack(cols)


def no_warnings(func, *args, **kwargs):
    with warnings.catch_warnings():
        warnings.simplefilter("error", HeightFieldWarning)
        return func(*args, **kwargs)


@pytest.mark.parametrize("view_axis", ["z", "x", "y"])
def test_round_trip_fixed_axes(syn, view_axis: str) -> None:
    pts = height_field_along(syn.franke_points(40), DEPTH_AXIS[view_axis])
    hf = no_warnings(to_height_field, pts, view_axis=view_axis)
    fr = hf.frame
    assert fr.view_axis == view_axis
    # rotation: orthonormal, right-handed, depth column along the chosen world axis
    np.testing.assert_allclose(fr.rotation.T @ fr.rotation, np.eye(3), atol=1e-15)
    assert np.linalg.det(fr.rotation) == pytest.approx(1.0)
    np.testing.assert_array_equal(fr.rotation[:, 2], np.eye(3)[DEPTH_AXIS[view_axis]])
    # the unit cube is spanned exactly
    assert hf.xy.min(axis=0).tolist() == [0.0, 0.0]
    assert hf.xy.max(axis=0).tolist() == [1.0, 1.0]
    assert (hf.z.min(), hf.z.max()) == (0.0, 1.0)
    assert hf.n_points == len(pts)
    unit = np.column_stack([hf.xy, hf.z])
    np.testing.assert_allclose(fr.to_unit(pts), unit, atol=1e-14)
    np.testing.assert_allclose(fr.to_world(unit), pts, rtol=1e-14, atol=1e-12)
    # depth in world units is the chosen world coordinate
    np.testing.assert_allclose(unit[:, 2] * fr.scale[2] + fr.offset[2],
                               pts[:, DEPTH_AXIS[view_axis]], rtol=1e-14)
    # xy helpers are the first two columns of the full maps
    local = pts @ fr.rotation
    np.testing.assert_allclose(fr.xy_to_unit(local[:, :2]), hf.xy, atol=1e-14)
    np.testing.assert_allclose(fr.xy_from_unit(hf.xy), local[:, :2], rtol=1e-14)


def test_pca_recovers_the_normal_of_a_tilted_plane(syn) -> None:
    normal = np.array([0.3, -0.5, 0.8])
    normal /= np.linalg.norm(normal)
    e1 = np.cross(normal, [1.0, 0.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(normal, e1)
    uv = syn.grid(50, jitter=0.0) * [90.0, 50.0]
    relief = 0.3 * np.cos(2 * np.pi * uv[:, 0] / 90.0)  # uncorrelated with the plane axes
    pts = (uv[:, :1] * e1 + uv[:, 1:] * e2 + relief[:, None] * normal
           + [1000.0, -200.0, 50.0])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", HeightFieldWarning)  # not the subject here
        hf = to_height_field(pts, view_axis="pca")
    rot = hf.frame.rotation
    assert hf.frame.view_axis == "pca"
    np.testing.assert_allclose(rot.T @ rot, np.eye(3), atol=1e-12)
    assert np.linalg.det(rot) == pytest.approx(1.0)
    assert abs(rot[:, 2] @ normal) == pytest.approx(1.0, abs=1e-6)
    assert rot[np.argmax(np.abs(rot[:, 2])), 2] > 0  # deterministic sign
    # the longest extent (about 90 mm) is the local x axis
    assert abs(rot[:, 0] @ e1) == pytest.approx(1.0, abs=1e-6)
    assert hf.frame.scale[0] == pytest.approx(88.2, rel=0.01)
    assert hf.frame.scale[2] == pytest.approx(0.6, rel=0.01)
    unit = np.column_stack([hf.xy, hf.z])
    np.testing.assert_allclose(hf.frame.to_world(unit), pts, atol=1e-9)


def test_pca_is_invariant_to_point_order(syn) -> None:
    pts = syn.franke_points(40)
    a = no_warnings(to_height_field, pts, view_axis="pca").frame.rotation
    b = no_warnings(to_height_field, pts[::-1].copy(), view_axis="pca").frame.rotation
    np.testing.assert_allclose(a, b, atol=1e-12)


def test_flat_scan_is_valid_and_maps_depth_to_zero(syn) -> None:
    pts = syn.flat_points(30, z=7.5)
    hf = no_warnings(to_height_field, pts)
    assert np.all(hf.z == 0.0)
    assert hf.frame.scale[2] == 1.0
    assert hf.frame.offset[2] == 7.5
    back = hf.frame.to_world(np.column_stack([hf.xy, hf.z]))
    np.testing.assert_allclose(back, pts, rtol=1e-14)


@pytest.mark.parametrize(("column", "name"), [(0, "x"), (1, "y")])
def test_zero_xy_extent_is_rejected(syn, column: int, name: str) -> None:
    pts = syn.franke_points(20)
    pts[:, column] = 42.0
    with pytest.raises(ScanError, match=f"zero {name} extent in the 'z' view frame"):
        to_height_field(pts)


def test_zero_extent_on_the_view_axis_frame(syn) -> None:
    pts = syn.franke_points(20)
    pts[:, 1] = 3.0  # zero y: valid along y (a flat scan), invalid along z and x
    hf = to_height_field(pts, view_axis="y")
    assert np.all(hf.z == 0.0)
    with pytest.raises(ScanError, match="zero x extent in the 'x' view frame"):
        to_height_field(pts, view_axis="x")


@pytest.mark.parametrize(("pts", "match"), [
    (np.zeros((10, 2)), r"an \(N, 3\) array, got shape \(10, 2\)"),
    (np.array([[0.0, 0.0, 0.0], [1.0, 1.0, np.nan], [0.0, 1.0, 0.0]]), "NaN"),
    (np.array([[0.0, 0.0, 0.0], [1.0, 1.0, np.inf], [0.0, 1.0, 0.0]]), "NaN or infinite"),
])
def test_bad_points_are_rejected(pts: np.ndarray, match: str) -> None:
    with pytest.raises(ScanError, match=match):
        to_height_field(pts)


def test_unknown_view_axis(syn) -> None:
    with pytest.raises(ScanError, match="view_axis must be one of z, x, y, pca"):
        to_height_field(syn.franke_points(10), view_axis="w")  # type: ignore[arg-type]
    assert VIEW_AXES == ("z", "x", "y", "pca")


def test_sphere_is_not_a_height_field(syn) -> None:
    with pytest.warns(HeightFieldWarning, match=r"folds over itself along the 'z' axis"):
        to_height_field(syn.sphere_points(2000))


def test_height_fields_do_not_warn(syn) -> None:
    for pts in (syn.franke_points(40), syn.plane_points(30), syn.bump_points(50),
                syn.flat_points(20)):
        no_warnings(to_height_field, pts)


def test_steep_coarse_height_field_does_not_warn(syn) -> None:
    no_warnings(to_height_field, syn.bump_points(30))


def test_noisy_flat_scan_does_not_warn(syn) -> None:
    pts = syn.flat_points(40)
    pts[:, 2] += np.random.default_rng(0).normal(0.0, 0.01, len(pts))
    no_warnings(to_height_field, pts)


def test_warn_fraction_controls_the_warning(syn) -> None:
    pts = syn.sphere_points(2000)
    no_warnings(to_height_field, pts, warn_fraction=0.99)


def test_sampling_spacing_of_regular_grids() -> None:
    g = np.stack(np.meshgrid(np.arange(30.0), np.arange(20.0)), -1).reshape(-1, 2)
    assert sampling_spacing(g * 0.25) == pytest.approx(0.25, rel=1e-12)
    # duplicated points are ignored; anisotropic grids give the smaller step
    assert sampling_spacing(np.concatenate([g, g]) * 0.01) == pytest.approx(0.01, rel=1e-12)
    assert sampling_spacing(g * [0.02, 0.05]) == pytest.approx(0.02, rel=1e-12)
    with pytest.raises(ScanError, match="same"):
        sampling_spacing(np.zeros((5, 2)))
    # copies a hair apart (written twice, once through float32) are copies too: the
    # spacing was 1e-13 and the hole fill's footprint raster 10^26 cells
    rng = np.random.default_rng(0)
    for hair in (1e-13, 1e-9 * 7.25 * 0.5):
        near = g[::2] * 0.25 + rng.uniform(-hair, hair, (len(g[::2]), 2))
        assert sampling_spacing(np.concatenate([g * 0.25, near])) == pytest.approx(0.25)


def test_sampling_spacing_subsamples_large_inputs() -> None:
    g = np.stack(np.meshgrid(np.arange(300.0), np.arange(300.0)), -1).reshape(-1, 2)
    assert sampling_spacing(g / 299, max_samples=5000) == pytest.approx(1 / 299, rel=1e-9)


def test_height_field_spacing(syn) -> None:
    hf = to_height_field(syn.franke_points(50))
    assert 0.3 / 50 < hf.spacing < 1.2 / 50


def test_frame_validation_and_dict_round_trip() -> None:
    fr = Frame(np.eye(3)[:, [1, 2, 0]], [1.0, 2.0, 3.0], [4.0, 5.0, 6.0], "x")
    back = Frame.from_dict(fr.to_dict())
    np.testing.assert_array_equal(back.rotation, fr.rotation)
    np.testing.assert_array_equal(back.offset, fr.offset)
    np.testing.assert_array_equal(back.scale, fr.scale)
    assert back.view_axis == "x"
    with pytest.raises(ValueError):
        fr.offset[0] = 0.0
    with pytest.raises(ValueError, match="scale must be positive"):
        Frame(np.eye(3), np.zeros(3), [1.0, 0.0, 1.0])
    with pytest.raises(ValueError, match="rotation"):
        Frame(np.eye(2), np.zeros(3), np.ones(3))
    with pytest.raises(ValueError, match="offset"):
        Frame(np.eye(3), [0.0, np.nan, 0.0], np.ones(3))


@pytest.mark.parametrize("axis", ["z", "pca"])
def test_height_field_advice_never_names_the_axis_in_use(syn, axis) -> None:
    with pytest.warns(HeightFieldWarning) as record:
        to_height_field(syn.sphere_points(2000), view_axis=axis)
    text = str(record[0].message)
    advice = text.split("try --view-axis ", 1)[1]
    assert axis not in advice.replace(" or ", ", ").split(", ")
    assert len(advice.replace(" or ", ", ").split(", ")) == 3
