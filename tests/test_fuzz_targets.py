"""The fuzz targets of ``scripts/fuzz.py``, run briefly in CI (hypothesis, no atheris).

The long coverage-guided runs are ``python scripts/fuzz.py all``; here the same
contract — a loader raises the package's one-line error or returns a whole object —
is checked on the seed files, on every single-byte truncation of them, and on random
byte strings and mutations drawn by hypothesis.
"""

from __future__ import annotations

import sys
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "scripts"))
import fuzz  # noqa: E402

QUICK = settings(max_examples=150, deadline=None, derandomize=True)


@pytest.fixture(scope="module")
def scan_seeds() -> dict[str, bytes]:
    return fuzz._seed_scans()


@pytest.fixture(scope="module")
def network_seeds() -> dict[str, bytes]:
    fuzz._network_file.valid = fuzz._valid_network()
    return fuzz._seed_networks()


def test_every_scan_seed_loads(scan_seeds: dict[str, bytes]) -> None:
    assert len(scan_seeds) >= 9
    for name, data in scan_seeds.items():
        assert fuzz.check_scan(data), name  # raises Finding on a broken contract
        assert fuzz.check_scan(bytes([data[0] | 0x80]) + data[1:]), name  # height-field check


def test_truncated_scan_seeds_fail_cleanly(scan_seeds: dict[str, bytes]) -> None:
    for data in scan_seeds.values():
        for cut in range(1, len(data), max(1, len(data) // 40)):
            fuzz.check_scan(data[:cut])


def test_network_seeds_load_and_truncations_fail_cleanly(
        network_seeds: dict[str, bytes]) -> None:
    for name, data in network_seeds.items():
        assert fuzz.check_network(data), name
    raw = network_seeds["raw"]
    for cut in range(1, len(raw), max(1, len(raw) // 60)):
        fuzz.check_network(raw[:cut])


def test_a_broken_contract_is_reported(monkeypatch) -> None:
    # the harness itself can fail: a loader returning NaN points or stray faces is a finding
    from types import SimpleNamespace

    import numpy as np

    import asrbf_mesh._io as aio

    bad = SimpleNamespace(points=np.array([[np.nan, 0, 0], [1, 1, 1], [2, 0, 1]]), faces=None)
    monkeypatch.setattr(aio, "load_scan", lambda *a, **k: bad)
    with pytest.raises(fuzz.Finding, match="bad points"):
        fuzz.check_scan(b"\x04anything")
    bad.points, bad.faces = np.zeros((3, 3)), np.array([[0, 1, 3]])
    with pytest.raises(fuzz.Finding, match="faces out of range"):
        fuzz.check_scan(b"\x04anything")


@QUICK
@given(st.binary(max_size=400))
def test_random_bytes_as_any_scan_format(data: bytes) -> None:
    fuzz.check_scan(data)


@QUICK
@given(st.data())
def test_mutated_scan_seeds(scan_seeds: dict[str, bytes], data) -> None:
    seed = data.draw(st.sampled_from(sorted(scan_seeds)))
    b = bytearray(scan_seeds[seed])
    for _ in range(data.draw(st.integers(1, 6))):
        i = data.draw(st.integers(1, len(b) - 1))
        b[i] = data.draw(st.integers(0, 255))
    fuzz.check_scan(bytes(b))


@QUICK
@given(st.data())
def test_mutated_network_members(network_seeds: dict[str, bytes], data) -> None:
    seed = data.draw(st.sampled_from(sorted(k for k in network_seeds if k != "raw")))
    b = bytearray(network_seeds[seed])
    start = 1 if b[0] == 1 else 2
    for _ in range(data.draw(st.integers(1, 4))):
        if len(b) > start:
            b[data.draw(st.integers(start, len(b) - 1))] = data.draw(st.integers(0, 255))
    fuzz.check_network(bytes(b))
