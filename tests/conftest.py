"""Shared synthetic scans with known truth, and a fitted network reused by many tests.

Every synthetic scan is a height field ``z = f(x, y)`` sampled on a jittered grid
and scaled to physical units (x in [100, 180] mm, y in [20, 80] mm, z in about
[5, 30] mm), so that the unit-cube normalization of :mod:`asrbf_mesh._frame` is
exercised by every test.
"""

from __future__ import annotations

import numpy as np
import pytest
from _grids import X0, XS, Y0, YS, Z0, ZS  # the mm frame; gridded scans: tests/_grids.py

import asrbf_mesh as am


def franke(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Franke's test function on the unit square (values in about [0, 1.22])."""
    t1 = 0.75 * np.exp(-((9 * x - 2) ** 2 + (9 * y - 2) ** 2) / 4)
    t2 = 0.75 * np.exp(-((9 * x + 1) ** 2) / 49 - (9 * y + 1) / 10)
    t3 = 0.5 * np.exp(-((9 * x - 7) ** 2 + (9 * y - 3) ** 2) / 4)
    t4 = -0.2 * np.exp(-((9 * x - 4) ** 2) - (9 * y - 7) ** 2)
    return t1 + t2 + t3 + t4


def bump(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """A single Gaussian bump of height 1 on the unit square."""
    return np.exp(-((x - 0.45) ** 2 + (y - 0.55) ** 2) / 0.15**2)


def plane(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """A tilted plane on the unit square."""
    return 0.3 * x + 0.5 * y


class Synthetic:
    """Factories of synthetic scans (physical units) and their exact surfaces."""

    franke = staticmethod(franke)
    bump = staticmethod(bump)
    plane = staticmethod(plane)

    @staticmethod
    def grid(n: int, *, seed: int = 0, jitter: float = 0.3) -> np.ndarray:
        """An ``n x n`` grid of the unit square, each node jittered by up to ``jitter`` cells."""
        rng = np.random.default_rng(seed)
        g = (np.arange(n) + 0.5) / n
        x, y = np.meshgrid(g, g)
        uv = np.column_stack([x.ravel(), y.ravel()])
        uv = uv + rng.uniform(-jitter, jitter, uv.shape) / n
        return np.clip(uv, 0.0, 1.0)

    @staticmethod
    def to_physical(uv: np.ndarray, h: np.ndarray) -> np.ndarray:
        """Unit-square (x, y) and unit height to (N, 3) points in mm."""
        return np.column_stack([X0 + XS * uv[:, 0], Y0 + YS * uv[:, 1], Z0 + ZS * h])

    @classmethod
    def points(cls, func, n: int = 60, *, seed: int = 0, noise: float = 0.0) -> np.ndarray:
        """(n*n, 3) points of ``Z0 + ZS * func(u, v)`` in mm, optional Gaussian noise (mm)."""
        uv = cls.grid(n, seed=seed)
        h = func(uv[:, 0], uv[:, 1])
        pts = cls.to_physical(uv, h)
        if noise:
            pts[:, 2] += np.random.default_rng(seed + 1).normal(0.0, noise, len(pts))
        return pts

    @classmethod
    def franke_points(cls, n: int = 60, *, seed: int = 0) -> np.ndarray:
        return cls.points(franke, n, seed=seed)

    @classmethod
    def bump_points(cls, n: int = 50, *, seed: int = 0) -> np.ndarray:
        return cls.points(bump, n, seed=seed)

    @classmethod
    def plane_points(cls, n: int = 50, *, seed: int = 0) -> np.ndarray:
        return cls.points(plane, n, seed=seed)

    @classmethod
    def flat_points(cls, n: int = 40, *, seed: int = 0, z: float = 7.5) -> np.ndarray:
        uv = cls.grid(n, seed=seed)
        pts = cls.to_physical(uv, np.zeros(len(uv)))
        pts[:, 2] = z
        return pts

    @staticmethod
    def truth(func, xy: np.ndarray) -> np.ndarray:
        """Exact depth (mm) of ``func`` at physical (M, 2) points."""
        xy = np.asarray(xy, dtype=np.float64)
        return Z0 + ZS * func((xy[:, 0] - X0) / XS, (xy[:, 1] - Y0) / YS)

    @staticmethod
    def sphere_points(n: int = 2000, *, seed: int = 0, radius: float = 30.0) -> np.ndarray:
        """Points spread over a whole sphere: not a height field along any axis."""
        rng = np.random.default_rng(seed)
        v = rng.normal(size=(n, 3))
        v /= np.linalg.norm(v, axis=1, keepdims=True)
        return radius * v + np.array([140.0, 50.0, 10.0])


@pytest.fixture(scope="session")
def syn() -> type[Synthetic]:
    return Synthetic


@pytest.fixture(scope="session")
def franke_points() -> np.ndarray:
    """3,600 points of Franke's function (60 x 60 jittered grid), read-only."""
    pts = Synthetic.franke_points(60, seed=0)
    pts.flags.writeable = False
    return pts


@pytest.fixture(scope="session")
def franke_net(franke_points: np.ndarray) -> am.Network:
    """The default fit (seed 0) of :func:`franke_points`, shared by many tests."""
    return am.fit(franke_points, seed=0, progress=False)

