"""The self-organizing-map baseline of the paper's section 5.4.

A standard Kohonen SOM (MiniSom's algorithm: rectangular grid, Gaussian neighbourhood,
online training; run compiled, equal to MiniSom's weights bit for bit) learns the
scan's 3D points on the most square-like grid whose node count is closest to the
network's K. Its nodes, and as many vertices sampled from our network
over the scan's footprint, are each meshed by ball pivoting (MeshLab) and compared with
the raw scan mesh by Metro distances (:func:`~asrbf_mesh.evaluate._metro.metro`).

Choices, each measured (see the functions): MiniSom's default schedule with a PCA
start on standardised points, 500 training steps per node; dead nodes (the best match
of no point) dropped unless asked; our vertices spread evenly in 3D by farthest-point
sampling, as many as the SOM's meshed nodes; the ball radius is MeshLab's guess for
both vertex sets.

>>> from asrbf_mesh.evaluate._som import compare_som      # doctest: +SKIP
>>> c = compare_som(scan, net, seed=0)                    # doctest: +SKIP
>>> c.asrbf.rms_pct, c.som.rms_pct                        # doctest: +SKIP
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from .._footprint import Footprint
from .._frame import sampling_spacing
from .._io import Scan
from .._mesh import Mesh
from .._network import Network
from .._surface import piece_grid_mesh
from .._validate import check_int, check_points, check_seed
from .._validate import progress as progress_bar
from ..errors import AsrbfError, ConfigError, ScanError
from . import _meshlab
from ._metro import MetroResult, metro
from ._som_kernels import train_online

__all__ = ["SomMap", "SomComparison", "som_grid", "train_som", "network_vertices",
           "compare_som"]

#: Online training steps per node by default (Kohonen's rule of thumb, see train_som).
STEPS_PER_NODE = 500
#: Initial neighbourhood radius in grid cells (MiniSom's default).
SIGMA = 1.0
#: Initial learning rate (MiniSom's default).
LEARNING_RATE = 0.5


# --------------------------------------------------------------------------- grid


def som_grid(k: int) -> tuple[int, int]:
    """Return the most square-like SOM grid whose node count is closest to ``k``.

    Among the square and near-square grids (rows and columns differ by at most one),
    the one whose ``rows * cols`` is closest to ``k``; on a tie the square one. This is
    the rule of the paper's Table 4 (K = 1,056, 1,901, 522, 1,527 gave 33 x 32,
    44 x 43, 23 x 23, 39 x 39): squareness first, then the count.

    Parameters
    ----------
    k : int
        Wanted node count (the network's K), >= 1.

    Returns
    -------
    (rows, cols) : tuple of int
        ``rows >= cols >= rows - 1``.

    Raises
    ------
    AsrbfError
        If ``k`` is not a positive integer.

    Examples
    --------
    >>> [som_grid(k) for k in (1056, 1901, 522, 1527)]
    [(33, 32), (44, 43), (23, 23), (39, 39)]
    >>> som_grid(727), som_grid(1), som_grid(3)
    ((27, 27), (1, 1), (2, 2))
    """
    k = check_int(k, "k", 1)
    n = math.isqrt(int(k))  # n*n <= k < (n+1)*(n+1)
    grids = [(n, n), (n + 1, n), (n + 1, n + 1)]
    return min(grids, key=lambda g: (abs(g[0] * g[1] - int(k)), g[0] - g[1]))


# --------------------------------------------------------------------------- training


@dataclass(frozen=True, eq=False)
class SomMap:
    """A trained self-organizing map of a point set.

    Attributes
    ----------
    nodes : (M, 3) float64 array
        Node positions in world (scan) units, grid row-major (``M = rows * cols``).
    shape : (rows, cols)
        The grid.
    dead : (M,) bool array
        Nodes that are the best match of no training point (after training).
    hits : (M,) int64 array
        Training points whose best match each node is.
    iterations : int
        Online training steps (one point each).
    seconds : float
        Training time (initialization, training and the final best-match pass).
    quantization_error : float
        Mean distance of the points to their best-matching node, world units.
    sigma : float
        Initial neighbourhood radius, in grid cells.
    learning_rate : float
        Initial learning rate.
    seed : int
    """

    nodes: np.ndarray
    shape: tuple[int, int]
    dead: np.ndarray
    hits: np.ndarray
    iterations: int
    seconds: float
    quantization_error: float
    sigma: float
    learning_rate: float
    seed: int

    def __post_init__(self) -> None:
        for name in ("nodes", "dead", "hits"):
            getattr(self, name).flags.writeable = False

    @property
    def n_nodes(self) -> int:
        """Number of grid nodes, ``rows * cols``."""
        return int(len(self.nodes))

    @property
    def n_dead(self) -> int:
        """Number of dead nodes."""
        return int(self.dead.sum())

    @property
    def live_nodes(self) -> np.ndarray:
        """The nodes that win at least one point, (M - n_dead, 3), grid order."""
        return self.nodes[~self.dead]

    def to_dict(self) -> dict[str, Any]:
        """Scalar summary: ``shape``, ``n_nodes``, ``n_dead``, ``iterations``, ..."""
        return {"shape": list(self.shape), "n_nodes": self.n_nodes, "n_dead": self.n_dead,
                "iterations": self.iterations, "seconds": self.seconds,
                "quantization_error": self.quantization_error, "sigma": self.sigma,
                "learning_rate": self.learning_rate, "seed": self.seed}


def _pca_init(x: np.ndarray, rows: int, cols: int) -> np.ndarray:
    """MiniSom's ``pca_weights_init``: the grid spans the first two principal axes.

    Node ``(i, j)`` starts at ``mean + a_i pc1 + b_j pc2`` with ``a`` and ``b`` evenly
    spaced over [-1, 1] (unit vectors, not scaled to the data: ``x`` is standardised).
    """
    vals, vecs = np.linalg.eigh(np.cov(x, rowvar=False))
    order = np.argsort(vals)[::-1]
    pc1, pc2 = vecs[:, order[0]], vecs[:, order[1]]
    a = np.linspace(-1, 1, rows)[:, None, None]
    b = np.linspace(-1, 1, cols)[None, :, None]
    return np.ascontiguousarray(x.mean(axis=0) + a * pc1 + b * pc2)


def train_som(points: Scan | np.ndarray, n_nodes: int, *, seed: int = 0,
              iterations: int | None = None, progress: bool | None = None) -> SomMap:
    """Train a standard Kohonen SOM on 3D points (MiniSom's algorithm, compiled).

    The grid is :func:`som_grid` of ``n_nodes``. The points are standardised first
    (centred, and divided by one common scale, the standard deviation along their
    first principal axis, so that distances stay Euclidean); the nodes start on the
    plane of the first two principal components (MiniSom's PCA initialization, which
    is not scaled to the data, hence the standardisation). Online training: one point
    per step, drawn in a seeded random order (every point once per pass over the
    data), Gaussian neighbourhood, the winner by Euclidean distance, MiniSom's update
    ``w += eta(t) h(t) (x - w)`` with MiniSom's default schedule: radius 1 cell and
    learning rate 0.5 at the start, both divided by ``1 + 2 t / T`` (a third of their
    start value at the end). The PCA start already orders the map, so no wide
    ordering phase is needed; the textbook schedule (radius falling linearly from half
    the grid's longer side to one cell, rate linearly to zero) smooths the map and
    gave 2.5 to 3.6 times the Metro mean distance (face map 0.64 vs 0.25 %, bun000
    0.59 vs 0.16 % of the diagonal): the baseline uses the better of the two. After
    training, a node that is the best match of no point is *dead*
    (:attr:`SomMap.dead`).

    Parameters
    ----------
    points : Scan or (N, 3) array
        Training points, world units; ``N >= n_nodes``.
    n_nodes : int
        Wanted node count (>= 4); the grid has :func:`som_grid` ``(n_nodes)`` nodes.
    seed : int
        Seeds the training order: the same seed gives the same nodes, bit for bit.
    iterations : int, optional
        Training steps. Default ``500 * rows * cols``: Kohonen's rule of thumb (at
        least 500 steps per node). Fewer cost the SOM accuracy (bun000, 1,560 nodes:
        100 steps per node give a Metro mean distance of 0.19 % vs 0.16 %). The
        compiled loop runs 4-13 us a step for 730-3,190 nodes, 25-30 times faster
        than MiniSom's Python steps (110-380 us; ``scripts/bench_som.py``): 1.3-21 s
        at the default instead of 1-10 min.
    progress : bool, optional
        Progress bar on stderr (default: on a terminal, for runs over 50,000 steps).

    Returns
    -------
    SomMap
        Nodes in world units, dead nodes (best match of no point) flagged.

    Raises
    ------
    AsrbfError
            Bad points (ScanError: not (N, 3), NaN, all equal, fewer than ``n_nodes``),
        ``n_nodes`` < 4, bad ``seed`` or ``iterations``.

    Notes
    -----
    T. Kohonen, *Self-Organizing Maps*, 3rd ed., Springer 2001 (section 3.8: the
    number of steps "must be at least 500 times the number of network units");
    G. Vettigli, MiniSom (https://github.com/JustGlowing/minisom): the same
    initialization, schedule and update, run here in one compiled loop
    (:mod:`asrbf_mesh.evaluate._som_kernels`); ``tests/test_som.py`` checks that the
    weights equal MiniSom's bit for bit. The paper's baseline is its reference [29]
    (Kohonen's SOM).

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> xy = rng.random((2000, 2))
    >>> pts = np.c_[xy, 0.1 * np.sin(3 * xy[:, 0])]
    >>> som = train_som(pts, 25, seed=0, iterations=5000)
    >>> som.shape, som.nodes.shape
    ((5, 5), (25, 3))
    """
    p = check_points(points)
    n_nodes = check_int(n_nodes, "n_nodes", 4)
    seed = check_seed(seed)
    if len(p) < n_nodes:
        raise ScanError(f"a SOM of {n_nodes} nodes needs at least {n_nodes} points, "
                        f"got {len(p)}")
    rows, cols = som_grid(n_nodes)
    steps = STEPS_PER_NODE * rows * cols if iterations is None else check_int(
        iterations, "iterations", 1)
    t0 = time.perf_counter()
    centre = p.mean(axis=0)
    scale = math.sqrt(float(np.linalg.eigvalsh(np.cov(p.T)).max()))
    if not scale > 0:
        raise ScanError("the points all coincide: nothing for a SOM to learn")
    x = np.ascontiguousarray((p - centre) / scale)
    sigma = SIGMA
    w = _pca_init(x, rows, cols)
    order = np.arange(steps, dtype=np.int64) % len(x)
    np.random.default_rng(seed).shuffle(order)
    tick = progress_bar(steps, progress, "SOM")
    chunk = 200_000
    for start in range(0, steps, chunk):
        stop = min(start + chunk, steps)
        train_online(w, x, order, start, stop, steps, sigma, LEARNING_RATE)
        if tick is not None:
            tick(stop - start)
    weights = w.reshape(-1, 3)
    dist, best = cKDTree(weights).query(x)
    hits = np.bincount(best, minlength=len(weights)).astype(np.int64)
    nodes = weights * scale + centre
    return SomMap(nodes=nodes, shape=(rows, cols), dead=hits == 0, hits=hits,
                  iterations=steps, seconds=time.perf_counter() - t0,
                  quantization_error=float(dist.mean() * scale), sigma=sigma,
                  learning_rate=LEARNING_RATE, seed=seed)


# --------------------------------------------------------------------------- our vertices


def _area_samples(v: np.ndarray, f: np.ndarray, m: int, rng: np.random.Generator,
                  uv: np.ndarray) -> np.ndarray:
    """``m`` points of ``uv`` (V, 2) interpolated uniformly over the 3D area of ``(v, f)``."""
    p0, p1, p2 = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    cdf = np.cumsum(0.5 * np.linalg.norm(np.cross(p1 - p0, p2 - p0), axis=1))
    if not (cdf[-1] > 0 and np.isfinite(cdf[-1])):
        return np.empty((0, uv.shape[1]))
    idx = np.minimum(np.searchsorted(cdf, rng.random(m) * cdf[-1], side="right"), len(f) - 1)
    r1 = np.sqrt(rng.random(m))
    r2 = rng.random(m)
    q0, q1, q2 = uv[f[idx, 0]], uv[f[idx, 1]], uv[f[idx, 2]]
    return (1 - r1)[:, None] * q0 + (r1 * (1 - r2))[:, None] * q1 + (r1 * r2)[:, None] * q2


def _farthest_points(p: np.ndarray, n: int) -> np.ndarray:
    """Return the indices of ``n`` points of ``p`` by farthest-point sampling.

    Starts at the point farthest from the centroid; each next point is the one
    farthest from those chosen (Gonzalez's 2-approximation of the k-centre cover).
    """
    chosen = np.empty(n, dtype=np.int64)
    q = p - p.mean(axis=0)
    i = int(np.argmax(np.einsum("ij,ij->i", q, q)))
    d2 = np.full(len(p), np.inf)
    for k in range(n):
        chosen[k] = i
        q = p - p[i]
        np.minimum(d2, np.einsum("ij,ij->i", q, q), out=d2)
        i = int(np.argmax(d2))
    return chosen


def network_vertices(net: Network, n: int, footprint_scan: Scan | np.ndarray, *,
                     seed: int = 0) -> np.ndarray:
    """``n`` points of the network's surface spread evenly (in 3D) over a scan's footprint.

    The network is evaluated on a fine grid of the view plane (about 9 nodes per
    wanted vertex) over the cells where the scan's triangles are (its holes and the
    outside left out); those surface points, and ``10 n`` more drawn uniformly over
    the area of the fine surface mesh (seeded, lifted to the network's surface), are
    reduced to ``n`` points by farthest-point sampling in 3D.

    Even spacing in 3D is what ball pivoting, with one ball radius, needs: a grid even
    in the view plane leaves the steep parts of a range scan (silhouettes and the
    walls at occlusion edges, 11-33 % of the Stanford bunny scans' area) with vertices
    too far apart in depth for the ball, i.e. holes in the mesh. Measured on the face
    map and the four bunny scans at the SOM's node counts, against a grid even in the
    view plane: Metro mean distance 0.11-0.25 % vs 0.18-0.31 % of the diagonal, RMS
    0.22-0.54 % vs 0.51-0.91 %, Hausdorff 2.9-18 % vs 6.5-26 %.

    Parameters
    ----------
    net : Network
        The fitted network.
    n : int
        Vertex count (>= 3).
    footprint_scan : Scan or (N, 3) array
        The scan whose footprint the vertices cover, world units (a bare point set is
        triangulated in the view plane, see :class:`~asrbf_mesh._footprint.Footprint`).
    seed : int
        Seed of the area densification.

    Returns
    -------
    (n, 3) float64 array
        Points of the network's surface, world units.

    Raises
    ------
    AsrbfError
        Bad arguments, or a footprint too small for ``n`` distinct points.

    Examples
    --------
    >>> import asrbf_mesh as am
    >>> rng = np.random.default_rng(0)
    >>> xy = rng.random((3000, 2))
    >>> net = am.fit(np.c_[xy, 0.2 * xy[:, 0] ** 2], seed=0, progress=False)
    >>> network_vertices(net, 100, np.c_[xy, 0.2 * xy[:, 0] ** 2]).shape
    (100, 3)
    """
    if not isinstance(net, Network):
        raise ConfigError(f"net must be an asrbf_mesh.Network, got {type(net).__name__}")
    n = check_int(n, "n", 3)
    seed = check_seed(seed)
    pts = check_points(footprint_scan, "footprint_scan points")
    faces = footprint_scan.faces if isinstance(footprint_scan, Scan) else None
    if len(pts) < 3:
        raise ScanError(f"footprint_scan needs at least 3 points, got {len(pts)}")
    xy = np.ascontiguousarray((pts @ net.frame.rotation)[:, :2])
    fp = Footprint.of_points(xy, faces, sampling_spacing(xy), mode="scan")
    lo, hi = xy.min(axis=0), xy.max(axis=0)
    area = float(np.count_nonzero(fp.labels == 0)) * fp.cell**2
    step = math.sqrt(area / n) / 3.0
    nx, ny = np.maximum(np.ceil((hi - lo) / step).astype(np.int64) + 1, 2)
    if nx * ny > 50_000_000:
        raise ConfigError(f"n={n} is too large for this footprint")
    gx = np.linspace(lo[0], hi[0], nx)  # spans the scan's extent exactly
    gy = np.linspace(lo[1], hi[1], ny)
    centres = np.stack(np.meshgrid(0.5 * (gx[:-1] + gx[1:]), 0.5 * (gy[:-1] + gy[1:])),
                       axis=-1).reshape(-1, 2)
    keep = (fp.label_at(centres) == 0).reshape(ny - 1, nx - 1)
    if not keep.any():
        raise AsrbfError("no grid cell lands on the footprint (is it the scan of this network?)")
    grid = np.stack(np.meshgrid(gx, gy), axis=-1).reshape(-1, 2)
    # each piece on its own cells, no wall: samples stay on the pieces' surfaces
    fine, node_xy, piece = piece_grid_mesh(net, grid, int(nx), int(ny), keep, walls=False)
    verts = fine.vertices
    dense = _area_samples(verts, fine.faces, 10 * n, np.random.default_rng(seed),
                          np.column_stack([node_xy, piece]))
    if len(dense):
        which = None if net.n_pieces == 1 else np.rint(dense[:, 2]).astype(np.int64)
        candidates = np.vstack([verts, net.surface_points(dense[:, :2], piece=which)])
    else:
        candidates = verts
    if len(candidates) < n:
        raise AsrbfError(f"the footprint holds fewer than n={n} distinct points")
    return candidates[_farthest_points(candidates, n)]


# --------------------------------------------------------------------------- comparison


@dataclass(frozen=True, eq=False)
class SomComparison:
    """Our network against the SOM at equal vertex counts, both by ball pivoting.

    Attributes
    ----------
    n_neurons : int
        K of the network.
    som_nodes : int
        Nodes of the SOM grid, ``rows * cols`` (closest to K, :func:`som_grid`).
    som_shape : (rows, cols)
    som_dead : int
        Dead SOM nodes (best match of no scan point).
    dead_nodes : {"dropped", "kept"}
        What the SOM mesh did with them.
    asrbf, som : MetroResult
        Metro distances of each ball-pivoting mesh (``a``) to the raw scan mesh (``b``).
    asrbf_mesh, som_mesh : Mesh
        The two ball-pivoting meshes (their vertices: the sampled network points, the
        SOM nodes; points the ball never reached stay unreferenced).
    som_map : SomMap
        The trained SOM.
    seconds : dict of str to float
        ``fit`` (0 if the network was given), ``som`` (training), ``vertices`` (our
        sampling), ``ball_pivoting``, ``metro``.
    """

    n_neurons: int
    som_nodes: int
    som_shape: tuple[int, int]
    som_dead: int
    dead_nodes: str
    asrbf: MetroResult
    som: MetroResult
    asrbf_mesh: Mesh = field(repr=False)
    som_mesh: Mesh = field(repr=False)
    som_map: SomMap = field(repr=False)
    seconds: dict[str, float] = field(default_factory=dict)

    @property
    def asrbf_wins(self) -> dict[str, bool]:
        """Whether ours is strictly below the SOM, for ``hausdorff``, ``mean``, ``rms``."""
        return {k: getattr(self.asrbf, k) < getattr(self.som, k)
                for k in ("hausdorff", "mean", "rms")}

    def to_dict(self) -> dict[str, Any]:
        """Scalar summary for JSON: counts, both Metro dicts, mesh sizes, timings."""
        return {"n_neurons": self.n_neurons, "som_nodes": self.som_nodes,
                "som_shape": list(self.som_shape), "som_dead": self.som_dead,
                "dead_nodes": self.dead_nodes,
                "asrbf": self.asrbf.to_dict() | {"vertices": self.asrbf_mesh.n_vertices,
                                                 "faces": self.asrbf_mesh.n_faces},
                "som": self.som.to_dict() | {"vertices": self.som_mesh.n_vertices,
                                             "faces": self.som_mesh.n_faces},
                "som_training": self.som_map.to_dict(), "asrbf_wins": self.asrbf_wins,
                "seconds": dict(self.seconds)}


def _ball_pivoting(points: np.ndarray, what: str) -> Mesh:
    mesh = _meshlab.ball_pivoting(points)
    if mesh.n_faces == 0:
        raise AsrbfError(f"ball pivoting made no triangle of the {len(points)} {what}")
    return mesh


def compare_som(scan: Scan, net: Network | None = None, *, seed: int = 0,
                samples: int | None = None, iterations: int | None = None,
                keep_dead: bool = False, progress: bool | None = None) -> SomComparison:
    """Compare our network with a SOM of the same size on a scan (paper section 5.4).

    Steps: fit the network if not given (``K`` neurons); train a SOM on the scan's
    points with :func:`som_grid` ``(K)`` nodes (:func:`train_som`); drop its dead
    nodes (unless ``keep_dead``); sample as many vertices from the network over the
    scan's footprint (:func:`network_vertices`); mesh both vertex sets by ball
    pivoting with MeshLab's own radius guess (the vertex set's bounding-box diagonal
    over the square root of its size; on bun000, 1.5 to 3 times that radius made the
    SOM's mesh worse on every measure); measure each mesh against the raw scan mesh
    with :func:`~asrbf_mesh.evaluate._metro.metro`.

    Parameters
    ----------
    scan : Scan
        The range scan, with faces (the Metro reference).
    net : Network, optional
        Our network of this scan; default ``asrbf_mesh.fit(scan, seed=seed)``.
    seed : int
        Seed of the fit, the SOM and the Metro sampling.
    samples : int, optional
        Metro area samples per direction (default: see :func:`metro`).
    iterations : int, optional
        SOM training steps (default: see :func:`train_som`).
    keep_dead : bool
        Mesh the dead SOM nodes too. Default False (docs/design.md): they win no
        scan point and float between the surface's parts (across holes, folds and
        occlusion gaps). Measured on the face map and the four bunny scans (seeds 0
        and 1), keeping them moves the SOM's figures both ways: lower Hausdorff and
        mean on bun090, whose gaps they bridge, higher mean on the face map and
        bun000. Our mesh keeps the lower mean and RMS either way, and the lower
        Hausdorff distance except on bun090 with seed 1 (SOM with its dead nodes
        8.9 %, ours 11.0 % of the diagonal).
    progress : bool, optional
        Progress bars of the fit and the SOM.

    Returns
    -------
    SomComparison

    Raises
    ------
    ScanError
        A scan without faces, or unusable points.
    AsrbfError
        Bad arguments, a network with fewer than 4 neurons, or a ball-pivoting mesh
        without faces.
    """
    from .._fit import fit

    if not isinstance(scan, Scan):
        raise ScanError(f"scan must be an asrbf_mesh.Scan, got {type(scan).__name__}")
    if scan.faces is None:
        raise ScanError(f"{scan.source or 'scan'}: the SOM comparison needs a scan with faces "
                        "(the Metro reference)")
    if net is not None and not isinstance(net, Network):
        raise ConfigError(f"net must be an asrbf_mesh.Network, got {type(net).__name__}")
    seconds: dict[str, float] = {"fit": 0.0}
    if net is None:
        t0 = time.perf_counter()
        net = fit(scan, seed=seed, progress=progress)
        seconds["fit"] = time.perf_counter() - t0
    k = net.n_neurons
    if k < 4:
        raise AsrbfError(f"the network has {k} neurons; a SOM comparison needs at least 4")
    som = train_som(scan, k, seed=seed, iterations=iterations, progress=progress)
    seconds["som"] = som.seconds
    som_vertices = som.nodes if keep_dead else som.live_nodes
    t0 = time.perf_counter()
    ours = network_vertices(net, len(som_vertices), scan, seed=seed)
    seconds["vertices"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    som_mesh = _ball_pivoting(som_vertices, "SOM nodes")
    asrbf_mesh = _ball_pivoting(ours, "network vertices")
    seconds["ball_pivoting"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    reference = scan.to_mesh()
    asrbf = metro(asrbf_mesh, reference, samples=samples, seed=seed)
    som_metro = metro(som_mesh, reference, samples=samples, seed=seed)
    seconds["metro"] = time.perf_counter() - t0
    return SomComparison(n_neurons=k, som_nodes=som.n_nodes, som_shape=som.shape,
                         som_dead=som.n_dead, dead_nodes="kept" if keep_dead else "dropped",
                         asrbf=asrbf, som=som_metro, asrbf_mesh=asrbf_mesh, som_mesh=som_mesh,
                         som_map=som, seconds=seconds)
