"""FitConfig: paper defaults, validation with messages naming the field, dict round trip."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from asrbf_mesh._config import DECAYS, POLISHES, PRUNINGS, UPDATES, FitConfig
from asrbf_mesh.errors import AsrbfError, ConfigError


def test_paper_defaults() -> None:
    c = FitConfig()
    # section 5.1 of the paper, unit cube
    assert (c.error_threshold, c.rms_threshold, c.d_max, c.gamma, c.psi) == (
        0.01, 0.01, 0.4, 0.99, 0.7)
    assert (c.window, c.prune_threshold) == (1000, 0.001)
    assert c.d_min is None  # from the data
    assert c.decay == "observation"
    assert c.update == "nekf"
    assert c.update in UPDATES and c.pruning in PRUNINGS and c.decay in DECAYS
    assert c.polish in POLISHES


def test_frozen_and_replace() -> None:
    c = FitConfig()
    with pytest.raises(dataclasses.FrozenInstanceError):
        c.window = 5  # type: ignore[misc]
    d = c.replace(window=200, update="gd")
    assert (d.window, d.update) == (200, "gd")
    assert c.window == 1000
    with pytest.raises(ConfigError, match="window"):
        c.replace(window=0)


def test_dict_round_trip_is_json() -> None:
    c = FitConfig(d_min=0.02, max_neurons=50, pruning="literal", polish="full")
    d = json.loads(json.dumps(c.to_dict()))
    assert FitConfig.from_dict(d) == c
    assert set(d) == {f.name for f in dataclasses.fields(FitConfig)}


def test_from_dict_rejects_unknown_fields() -> None:
    with pytest.raises(ConfigError, match="unknown FitConfig field.*bogus, zeta"):
        FitConfig.from_dict({"zeta": 1, "bogus": 2, "window": 10})


@pytest.mark.parametrize(("changes", "match"), [
    ({"error_threshold": 0.0}, "error_threshold must be a positive finite number"),
    ({"rms_threshold": -1.0}, "rms_threshold must be a positive"),
    ({"d_max": float("nan")}, "d_max must be a positive finite"),
    ({"measurement_noise": float("inf")}, "measurement_noise must be a positive finite"),
    ({"support": 0}, "support must be a positive"),
    ({"gd_rate": "0.1"}, "gd_rate must be a positive"),
    ({"d_min": 0.0}, "d_min must be a positive"),
    ({"d_min": 0.5}, r"d_min \(0.5\) must not exceed d_max \(0.4\)"),
    ({"gamma": 1.0}, r"gamma must be a number in \(0, 1\)"),
    ({"gamma": 0.0}, "gamma must be a number in"),
    ({"psi": 1.5}, r"psi must be a number in \(0, 1\]"),
    ({"prune_threshold": 1.0}, r"prune_threshold must be a number in \[0, 1\)"),
    ({"prune_threshold": float("nan")}, "prune_threshold must be a number in"),
    ({"process_noise": -1e-3}, "process_noise must be a finite number >= 0"),
    ({"polish_ridge": float("inf")}, "polish_ridge must be a finite number >= 0"),
    ({"local_width": -1.0}, "local_width must be a finite number >= 0"),
    ({"local_width": float("nan")}, "local_width must be a finite number >= 0"),
    ({"window": 0}, "window must be an integer >= 1"),
    ({"passes": 1.5}, "passes must be an integer >= 1"),
    ({"max_neighbours": 0}, "max_neighbours must be an integer"),
    ({"prune_window": 0}, "prune_window must be an integer >= 1 or None"),
    ({"max_neurons": 2.0}, "max_neurons must be an integer >= 1 or None"),
    ({"polish_iterations": -1}, "polish_iterations must be an integer >= 0"),
    ({"update": "ekf"}, "update must be one of nekf, nekf-neighbourhood, gekf, gd; got 'ekf'"),
    ({"pruning": "all"}, "pruning must be one of none, literal, support"),
    ({"decay": "time"}, "decay must be one of observation, neurons, pass"),
    ({"decay_fraction": 0.0}, r"decay_fraction must be a number in \(0, 1\]"),
    ({"decay_fraction": 1.5}, r"decay_fraction must be a number in \(0, 1\]"),
    ({"polish": "yes"}, "polish must be one of none, weights, full"),
])
def test_invalid_values_are_rejected(changes: dict, match: str) -> None:
    with pytest.raises(ConfigError, match=match) as info:
        FitConfig(**changes)
    assert isinstance(info.value, AsrbfError) and isinstance(info.value, ValueError)


def test_boundary_values_are_accepted() -> None:
    c = FitConfig(psi=1.0, prune_threshold=0.0, process_noise=0.0, polish_ridge=0.0,
                  polish_iterations=0, d_min=0.4, window=1, passes=1)
    assert c.psi == 1.0 and c.d_min == c.d_max


@pytest.mark.parametrize("field", ["window", "passes", "error_threshold"])
def test_bools_are_not_numbers(field: str) -> None:
    with pytest.raises(ConfigError, match=field):
        FitConfig(**{field: True})


def test_numpy_integers_are_accepted() -> None:
    c = FitConfig(passes=np.int64(2), window=np.int32(500), max_neurons=np.int64(40))
    assert (c.passes, c.window, c.max_neurons) == (2, 500, 40)


@pytest.mark.parametrize("field", ["gamma", "psi", "prune_threshold", "process_noise"])
def test_non_numeric_values_raise_config_error(field: str) -> None:
    with pytest.raises(ConfigError, match=field):
        FitConfig(**{field: "0.5"})
