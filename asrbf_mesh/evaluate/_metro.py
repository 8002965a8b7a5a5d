"""Metro-style distances between two surfaces, both ways (pymeshlab's Hausdorff filter).

``metro(a, b)`` measures how far the mesh under test ``a`` (a reconstruction, a fill, a
level of detail) lies from the reference ``b`` (usually the scan) and back:

- direction ``a -> b``: every referenced vertex of ``a`` plus ``samples`` points drawn
  uniformly over its area (seeded), each with its distance to the closest point of ``b``;
- direction ``b -> a``: the same from ``b`` to ``a`` (for a point-set reference, its points);
- symmetric: Hausdorff = the larger maximum; mean and RMS = the average of the two
  directions' area-sample means / mean squares (Cignoni, Rocchini, Scopigno 1998).

Percentages are of the reference's bounding-box diagonal. Unlike MeshLab's filter, the
per-sample distances are available (``per_sample=True``) and the per-vertex error of
``a`` can be written as vertex quality (:meth:`MetroResult.error_mesh`) to view in
MeshLab with a quality colour map.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._io import Scan
from .._mesh import Mesh
from .._validate import check_int, check_seed
from ..errors import AsrbfError, ScanError
from . import _meshlab

__all__ = ["Direction", "MetroResult", "metro"]

# What the sampling is, in words, for reports and --json.
SAMPLING = ("vertices + uniform area samples (seeded Monte Carlo, stratified); mean and RMS "
            "over the area samples, Hausdorff over all samples")


@dataclass(frozen=True, eq=False)
class Direction:
    """One direction of a Metro measurement: samples of one surface against the other.

    Attributes
    ----------
    max, min, mean, rms : float
        Over the samples (mean and RMS over the area samples when there are any).
    n_samples, n_vertex_samples, n_area_samples : int
    points : (S, 3) array or None
        The samples (vertex samples first), with ``per_sample=True``.
    distances : (S,) array or None
        Each sample's distance to the other surface, with ``per_sample=True``.
    """

    max: float
    min: float
    mean: float
    rms: float
    n_samples: int
    n_vertex_samples: int
    n_area_samples: int
    points: np.ndarray | None = field(default=None, repr=False)
    distances: np.ndarray | None = field(default=None, repr=False)

    def to_dict(self) -> dict[str, Any]:
        """Return the scalar fields as a dict."""
        return {k: getattr(self, k) for k in ("max", "min", "mean", "rms", "n_samples",
                                              "n_vertex_samples", "n_area_samples")}


@dataclass(frozen=True, eq=False)
class MetroResult:
    """Symmetric Metro distances between a mesh ``a`` and a reference ``b``.

    Attributes
    ----------
    hausdorff, mean, rms : float
        Symmetric figures, scan units.
    hausdorff_pct, mean_pct, rms_pct : float
        The same in % of the reference's bounding-box diagonal.
    diagonal : float
        The reference's bounding-box diagonal.
    n_samples : int
        Samples over both directions.
    samples_per_direction : int
        Area samples drawn on each mesh (0 for a point-set reference).
    seed : int
        Seed of the area sampling.
    a_to_b : Direction or None
        ``a`` sampled against ``b`` (None when ``b`` is a bare point set).
    b_to_a : Direction
        ``b`` sampled against ``a``.
    mesh : Mesh
        The mesh under test, ``a``.
    """

    hausdorff: float
    mean: float
    rms: float
    hausdorff_pct: float
    mean_pct: float
    rms_pct: float
    diagonal: float
    n_samples: int
    samples_per_direction: int
    seed: int
    a_to_b: Direction | None
    b_to_a: Direction
    mesh: Mesh = field(repr=False)
    _vertex_error: np.ndarray | None = field(default=None, repr=False)

    @property
    def sampling(self) -> str:
        """How the surfaces were sampled, in words."""
        return SAMPLING

    def to_dict(self) -> dict[str, Any]:
        """Everything scalar, for ``--json`` (per-sample arrays left out)."""
        return {"hausdorff": self.hausdorff, "mean": self.mean, "rms": self.rms,
                "hausdorff_pct": self.hausdorff_pct, "mean_pct": self.mean_pct,
                "rms_pct": self.rms_pct, "diagonal": self.diagonal,
                "n_samples": self.n_samples,
                "samples_per_direction": self.samples_per_direction, "seed": self.seed,
                "sampling": self.sampling,
                "a_to_b": None if self.a_to_b is None else self.a_to_b.to_dict(),
                "b_to_a": self.b_to_a.to_dict()}

    @property
    def vertex_error(self) -> np.ndarray:
        """Distance of every vertex of ``a`` to ``b`` (0 on unreferenced vertices).

        Raises
        ------
        AsrbfError
            If the measurement was made without ``per_sample=True``, or against a
            bare point set (whose distances measure its gaps, not the surface).
        """
        if self._vertex_error is None:
            raise AsrbfError("per-vertex errors need metro(..., per_sample=True) and a mesh "
                             "reference")
        return self._vertex_error

    def error_mesh(self) -> Mesh:
        """Return the mesh ``a`` with its per-vertex error to ``b`` as vertex quality."""
        return Mesh(self.mesh.vertices, self.mesh.faces, self.mesh.vertex_normals,
                    self.vertex_error)


def _as_surface(x: Mesh | Scan | np.ndarray, name: str,
                points_ok: bool) -> Mesh | np.ndarray:
    if isinstance(x, Scan):
        if x.faces is not None and len(x.faces):
            return x.to_mesh()
        if points_ok:
            return x.points
        where = x.source or f"metro: {name}"
        raise ScanError(f"{where}: is a point set without faces; it must be a mesh")
    if isinstance(x, Mesh):
        return x
    if points_ok:
        return np.asarray(x, dtype=np.float64)
    raise ScanError(f"metro: {name} must be a Mesh or a Scan with faces, got "
                     f"{type(x).__name__}")


def _direction(d: dict[str, Any] | None) -> Direction | None:
    if d is None:
        return None
    return Direction(d["max"], d["min"], d["mean"], d["rms"], d["n_samples"],
                     d["n_vertex_samples"], d["n_area_samples"], d.get("points"),
                     d.get("distances"))


def metro(a: Mesh | Scan, b: Mesh | Scan | np.ndarray, *, samples: int | None = None,
          seed: int = 0, per_sample: bool = False) -> MetroResult:
    """Metro distances between the mesh ``a`` and the reference ``b``, both ways.

    Parameters
    ----------
    a : Mesh or Scan
        The mesh under test (a scan must have faces).
    b : Mesh, Scan or (N, 3) array
        The reference; a bare point set (or a scan without faces) gives only ``b -> a``.
    samples : int, optional
        Area samples per direction; default ``max(4 max(V_a, V_b), 10000)``.
    seed : int
        Seed of the area sampling: same seed, same figures.
    per_sample : bool
        Keep every sample's position and distance (``a_to_b.points``, ``.distances``)
        and the per-vertex error of ``a`` (:attr:`MetroResult.vertex_error`).

    Returns
    -------
    MetroResult

    Any mesh with at least one face is measured (a cube, a single triangle), against
    a reference mesh with at least one face or a point set of at least one point.

    Raises
    ------
    ConfigError
        Bad ``samples`` or ``seed``.
    ScanError
        A mesh without faces, non-finite coordinates.
    AsrbfError
        A pymeshlab failure.

    Examples
    --------
    >>> v = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]])
    >>> f = np.array([[0, 1, 3], [0, 3, 2]])
    >>> r = metro(Mesh(v + [0, 0, 0.25], f), Mesh(v, f), samples=200)
    >>> round(r.hausdorff, 6), round(r.mean, 6), round(r.rms, 6)
    (0.25, 0.25, 0.25)
    """
    seed = check_seed(seed)
    if samples is not None:
        samples = check_int(samples, "samples", 1)
    mesh_a = _as_surface(a, "a", points_ok=False)
    ref = _as_surface(b, "b", points_ok=True)
    d = _meshlab.hausdorff(mesh_a, ref, samples=samples, seed=seed, keep_samples=per_sample)
    a_to_b, b_to_a = _direction(d["a_to_b"]), _direction(d["b_to_a"])
    vertex_error = None
    if per_sample and d["a_to_b"] is not None:
        idx = d["a_to_b"]["vertex_index"]
        vertex_error = np.zeros(mesh_a.n_vertices)
        vertex_error[idx] = d["a_to_b"]["distances"][: len(idx)]
    n_area = 0 if a_to_b is None else a_to_b.n_area_samples
    return MetroResult(d["hausdorff"], d["mean"], d["rms"], d["hausdorff_pct"], d["mean_pct"],
                       d["rms_pct"], d["diagonal"], d["n_samples"], n_area, seed, a_to_b,
                       b_to_a, mesh_a, vertex_error)
