"""Synthetic holed scans for crash campaigns of hole filling: shapes that break rims.

Each kind is a meshed range grid (two triangles per cell) with holes cut where hole
filling is hard: across a cliff, on a spiral ramp (a cliff that winds around), a ring
around an island (a hole nested around scan), a surface folded over itself (two layers
joined by a wall), the steep side of a cylinder (a rim that folds over itself in the view
plane), and many holes at random (touching each other, the border, each other's rims).
Every size, place and count is drawn from the seed: ``synthetic_holes(kind, seed)``.
"""

from __future__ import annotations

import numpy as np

from .._igl import orient_faces
from .._mesh import Scan
from .._surface import grid_faces
from ._punch import remove_points

__all__ = ["SYNTHETIC_KINDS", "synthetic_holes"]

#: The kinds :func:`synthetic_holes` makes.
SYNTHETIC_KINDS = ("cliff", "spiral", "nested", "fold", "cylinder", "random")


def synthetic_holes(kind: str, seed: int) -> Scan:
    """Make a synthetic scan of ``kind`` (see :data:`SYNTHETIC_KINDS`) with holes, from ``seed``."""
    rng = np.random.default_rng(seed)
    if kind == "fold":
        return _fold(rng)
    if kind == "cylinder":
        return _cylinder(rng)
    n = int(rng.integers(30, 61))
    x, y = np.meshgrid(np.arange(n, dtype=float), np.arange(n, dtype=float))
    c = n / 2
    if kind == "cliff":
        wave = rng.uniform(0, 5) * np.sin(y / rng.uniform(3, 8))
        z = np.where(x > c + wave, rng.uniform(3, 20), 0.0) + 0.3 * np.sin(x / 4)
    elif kind == "spiral":
        r, th = np.hypot(x - c, y - c), np.arctan2(y - c, x - c)
        z = rng.uniform(2, 8) * np.mod(th + r / rng.uniform(2, 6), 2 * np.pi)
    elif kind == "nested":
        z = rng.uniform(0.01, 0.1) * x * y + rng.uniform(0, 3) * np.sin(x / 5)
    elif kind == "random":
        z = rng.uniform(1, 6) * np.sin(x / rng.uniform(4, 12)) * np.cos(y / rng.uniform(4, 12))
    else:
        raise ValueError(f"unknown kind {kind!r}; one of {', '.join(SYNTHETIC_KINDS)}")
    pts = np.c_[x.ravel(), y.ravel(), z.ravel()]
    xy = pts[:, :2]
    if kind == "nested":  # a ring around an island, off centre
        o = c + rng.uniform(-n / 8, n / 8, 2)
        d = np.linalg.norm(xy - o, axis=1)
        inner = rng.uniform(2, n / 8)
        drop = (d > inner) & (d < inner + rng.uniform(2, n / 6))
    else:
        k = int(rng.integers(1, 4 if kind != "random" else 12))
        centres = rng.uniform(0, n - 1, (k, 2))
        radii = rng.uniform(1.5, n / 7, k)
        drop = (np.linalg.norm(xy[:, None] - centres[None], axis=2) < radii).any(axis=1)
    return _cut(pts, grid_faces(n, n), drop)


def _cut(pts: np.ndarray, faces: np.ndarray, drop: np.ndarray) -> Scan:
    """Return the scan without the points ``drop`` and the faces touching them."""
    return Scan(*remove_points(pts, faces, drop))


def _fold(rng: np.random.Generator) -> Scan:
    """Fold a sheet under itself and cut a hole through both layers (across the fold or not).

    A front sheet over ``0 <= x <= x1`` turns down a wall seen edge-on at ``x1`` and runs
    back under itself as a back sheet over ``x0 <= x <= x1`` (half a cell apart in xy,
    its triangles facing away): one manifold surface folded over ``x0 <= x <= x1``,
    where the hole is cut, through both layers, sometimes into the wall.
    """
    x0 = float(rng.integers(5, 20))
    x1 = x0 + float(rng.integers(10, 25))
    h = float(rng.integers(25, 50))
    ys = np.arange(0.0, h + 1e-9, 1.0)
    fxs = np.arange(0.0, x1 + 1e-9, 1.0)
    bxs = x1 + 0.5 - np.arange(0.0, x1 - x0 + 1e-9, 1.0)  # from the fold back to x0
    lift, tilt, slope = rng.uniform(5, 40), rng.uniform(-0.1, 0.1), rng.uniform(-0.1, 0.1)
    gx, gy = np.meshgrid(fxs, ys)
    front = np.c_[gx.ravel(), gy.ravel(), lift + tilt * gx.ravel()]
    gx, gy = np.meshgrid(bxs, ys + 0.5)
    back = np.c_[gx.ravel(), gy.ravel(), slope * gy.ravel()]
    fx, bx, ny = len(fxs), len(bxs), len(ys)
    top = np.arange(ny) * fx + (fx - 1)
    bottom = len(front) + np.arange(ny) * bx  # the back's first column, at x1 + 0.5
    wall = [[top[j], bottom[j], top[j + 1]] for j in range(ny - 1)]
    wall += [[top[j + 1], bottom[j], bottom[j + 1]] for j in range(ny - 1)]
    faces = np.vstack([grid_faces(fx, ny), grid_faces(bx, ny) + len(front), np.array(wall)])
    faces = orient_faces(faces)  # one orientation over the fold
    flip = np.cross(*(front[faces[0, 1:]] - front[faces[0, 0]]))[2] < 0  # front faces +z
    faces = faces[:, ::-1] if flip else faces
    pts = np.vstack([front, back])
    r = rng.uniform(2, max(2.5, (x1 - x0) / 2))
    # inside the back layer's end at x0 (else a notch of its border), up to the wall or over
    centre = np.array([rng.uniform(x0 + r + 1, x1 + r / 2), rng.uniform(r + 1, h - r - 1)])
    return _cut(pts, faces, np.linalg.norm(pts[:, :2] - centre, axis=1) < r)


def _cylinder(rng: np.random.Generator) -> Scan:
    """Cut a hole in the steep side of a part-cylinder seen along z (its rim folds in xy)."""
    nx, ny = int(rng.integers(40, 70)), int(rng.integers(30, 50))
    half = rng.uniform(0.55, 0.8) * np.pi
    radius = rng.uniform(5, 20)
    th, y = np.meshgrid(np.linspace(-half, half, nx), np.linspace(0, 30, ny))
    pts = np.c_[radius * np.sin(th).ravel(), y.ravel(), radius * np.cos(th).ravel()]
    a = rng.uniform(0.3, 0.95) * half * rng.choice([-1, 1])
    centre = np.array([radius * np.sin(a), rng.uniform(8, 22), radius * np.cos(a)])
    drop = np.linalg.norm(pts - centre, axis=1) < rng.uniform(0.15, 0.4) * radius
    return _cut(pts, grid_faces(nx, ny), drop)
