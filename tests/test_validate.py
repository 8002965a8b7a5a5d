"""The one validation layer (asrbf_mesh._validate) and the rules every public function follows."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

import asrbf_mesh as am
from asrbf_mesh import _validate as v
from asrbf_mesh.errors import ConfigError, ScanError


@pytest.mark.parametrize("bad", [-1, 1.5, "a", True, None, 2.0, np.float64(3)])
def test_check_seed_refuses_what_is_not_a_non_negative_integer(bad) -> None:
    with pytest.raises(ConfigError, match=r"^seed must be an integer >= 0, got "):
        v.check_seed(bad)


def test_check_int_bounds_and_numpy_integers() -> None:
    assert v.check_int(np.int64(5), "levels", 1, 12) == 5
    assert type(v.check_int(np.int32(5), "levels", 1)) is int
    with pytest.raises(ConfigError, match=r"levels must be an integer in \[1, 12\], got 13"):
        v.check_int(13, "levels", 1, 12)


def test_check_points_is_a_scan_error_naming_the_argument() -> None:
    assert v.check_points(am.Scan(np.zeros((4, 3)) + np.eye(4, 3))).shape == (4, 3)
    with pytest.raises(ScanError, match=r"^footprint must be an \(N, 3\) array"):
        v.check_points(np.zeros((4, 2)), "footprint")
    with pytest.raises(ScanError, match="footprint must hold at least 3 points"):
        v.check_points(np.zeros((2, 3)), "footprint", min_points=3)
    with pytest.raises(ScanError, match="NaN or infinite"):
        v.check_points(np.full((4, 3), np.nan))


@pytest.mark.parametrize(("value", "match"), [
    ("200%", r"a percentage in \(0, 100\], got '200%'"),
    ("-5%", "a finite length > 0"),
    ("0%", "a finite length > 0"),
    ("inf", "a finite length > 0"),
    (True, "a finite length > 0"),
])
def test_parse_length_one_rule(value, match) -> None:
    with pytest.raises(ConfigError, match=match):
        v.parse_length(value, 10.0, "max hole size")
    assert v.parse_length("100%", 10.0, "max hole size") == 10.0
    assert v.parse_length(None, 10.0, "max hole size") is None


def test_progress_contract(monkeypatch) -> None:
    """False: never; True: always, at once; None: on a terminal only, after a delay."""
    assert v.progress(100, False, "x") is None
    monkeypatch.setattr("sys.stderr.isatty", lambda: False, raising=False)
    assert v.progress(100, None, "x") is None
    tick = v.progress(10, True, "x")
    assert tick is not None and tick.bar is not None  # type: ignore[attr-defined]
    tick(10)  # reaching the total closes the bar
    assert tick.bar is None  # type: ignore[attr-defined]


def test_strict_json_has_no_nan_and_expands_records() -> None:
    text = v.strict_json({"a": np.float64("nan"), "s": am.NeuronStats(0, *[0.0] * 8),
                          "i": np.int64(3)})
    data = json.loads(text)
    assert data["a"] is None and data["i"] == 3 and data["s"]["n_neurons"] == 0


def _points() -> np.ndarray:
    rng = np.random.default_rng(0)
    xy = rng.random((400, 2))
    return np.c_[xy, 0.1 * np.sin(3 * xy[:, 0])]


@pytest.mark.parametrize("seed", [-1, 1.5, "a"])
def test_every_public_function_checks_its_seed(seed, tmp_path) -> None:
    """A bad seed is a ConfigError naming seed, not a numpy error (fit, learn, ...)."""
    from asrbf_mesh.evaluate import metro, train_som

    pts = _points()
    np.save(tmp_path / "p.npy", pts)
    hf = am.to_height_field(pts)
    mesh = am.Mesh(np.eye(3), np.array([[0, 1, 2]]))
    calls = [lambda: am.fit(pts, seed=seed, progress=False),
             lambda: am.learn(hf, seed=seed, progress=False),
             lambda: am.fit_stream(tmp_path / "p.npy", seed=seed, chunk=8192, progress=False),
             lambda: am.lod_set(pts, seed=seed),
             lambda: metro(mesh, mesh, seed=seed),
             lambda: train_som(pts, 16, seed=seed, progress=False)]
    for call in calls:
        with pytest.raises(ConfigError, match="^seed must be an integer >= 0"):
            call()


def test_constructors_raise_config_errors() -> None:
    frame = am.Frame(np.eye(3), np.zeros(3), np.ones(3))
    with pytest.raises(ConfigError, match="Frame.scale must be positive"):
        am.Frame(np.eye(3), np.zeros(3), np.zeros(3))
    with pytest.raises(ConfigError, match="widths must be positive"):
        am.Network(0.0, np.zeros((1, 2)), np.zeros(1), np.ones(1), frame, am.FitConfig())
    with pytest.raises(ConfigError, match="config must be a FitConfig"):
        am.Network(0.0, np.zeros((1, 2)), np.ones(1), np.ones(1), frame, {})
    with pytest.raises(ConfigError, match="width_max must be a finite number"):
        am.NeuronStats(1, math.nan, 0.1, 0.1, 0.0, 1.0, 1.0, 1.0, 0.0)
    with pytest.raises(ConfigError, match="n_neurons must be an integer >= 0"):
        am.NeuronStats(-1, *[0.0] * 8)


def test_public_return_types_are_exported() -> None:
    for name in ("FitInfo", "LearnedState", "FillResult", "LodLevel", "NeuronStats", "FitLog",
                 "HeightField", "Mesh", "Scan", "Network"):
        assert name in am.__all__ and hasattr(am, name), name
    assert "PunchedScan" in am.evaluate.__all__  # punch_holes is a benchmark helper
