"""Streaming fit: scans larger than memory, learned from blocks read off the disk.

The points stay in their file; :func:`fit_stream` reads them in blocks of ``chunk``
points (NPY through a memory map, binary PLY through plyfile's memory map, XYZ text
through a byte-offset index), in passes:

1. the frame: the bounds of every coordinate (and the SHA-256 of the points, the
   network's provenance), checking each block for NaN and infinity;
2. the sampling spacing that sets D_min: exact (every point, as :func:`asrbf_mesh.fit`
   does) up to :data:`EXACT_SPACING_MAX` points, above that from every point in a
   seeded set of small tiles of the footprint (about 60,000 points), which also feed
   the height-field and duplicate warnings;
3. learning, :data:`~asrbf_mesh._config.FitConfig.passes` times: the blocks in a seeded
   random order, ``mix`` blocks at a time loaded together and replayed in a random
   order (:func:`block_order` is the whole order);
4. the weight polish (two passes: normal equations, then the error) and the final
   error statistics (one pass).

Memory is O(K + mix * chunk): the learning state, one group of blocks and the polish's
sparse normal equations. Given the same order (``asrbf_mesh.fit(scan,
order=...)`` with :func:`block_order`) and the same D_min, the network is the one
:func:`asrbf_mesh.fit` learns in memory, bit for bit.

>>> import asrbf_mesh as am                                     # doctest: +SKIP
>>> net = am.fit_stream("tile_20M.npy", seed=0)                 # doctest: +SKIP
"""

from __future__ import annotations

import hashlib
import io
import math
import os
import time
import warnings
from collections.abc import Iterator
from typing import Any

import numpy as np

from . import _polish, _validate
from ._config import FitConfig
from ._frame import (
    _AXES,
    check_height_field,
    frame_from_bounds,
    sampling_spacing,
    unit_height_field,
)
from ._learn import MIN_POINTS, auto_d_min, fit_info, learn_from, polish_kind
from ._network import Network
from ._outliers import OutlierWarning
from ._readers import (
    FORMAT_NAMES,
    TEXT_PROBE,
    ParseError,
    PointBlocks,
    check_npy_points,
    check_scan_path,
    check_text,
    is_count_line,
    npy_header,
    ply_vertex,
    read_ply_data,
)
from ._validate import check_int, check_seed, one_line
from .errors import ConfigError, ScanError

__all__ = ["fit_stream", "block_order", "open_points", "PointBlocks", "STREAM_FORMATS",
           "DEFAULT_CHUNK", "DEFAULT_MIX", "EXACT_SPACING_MAX"]

#: Points per block read from disk (a multiple of the polish's row block).
DEFAULT_CHUNK = 1 << 16
#: Blocks loaded and replayed together during learning.
DEFAULT_MIX = 16
#: Up to this many points the spacing (and so D_min) is exact, as in memory.
EXACT_SPACING_MAX = 2_000_000
#: Points the tile sample aims at above :data:`EXACT_SPACING_MAX`.
TILE_SAMPLE = 60_000
#: File formats the streaming fit reads.
STREAM_FORMATS = (".npy", ".ply", ".xyz", ".pts", ".txt", ".las", ".laz")


# --------------------------------------------------------------------------- sources


class _ArrayBlocks(PointBlocks):
    """Blocks of fixed-size binary records (NPY rows, binary PLY vertices).

    Each block is read with one seek and one read into a fresh array, not through a
    memory map: the pages of a map that has been read count in the resident set until
    the kernel drops them, which is no bound at all.
    """

    def __init__(self, path: str, offset: int, dtype: np.dtype, n: int, chunk: int,
                 fields: tuple[str, ...] | None = None) -> None:
        super().__init__(path, n, chunk)
        self._offset, self._dtype, self._fields = offset, dtype, fields

    def block(self, b: int) -> np.ndarray:
        lo, hi = self.bounds(b)
        with open(self.path, "rb") as fh:
            fh.seek(self._offset + lo * self._dtype.itemsize)
            rec = np.fromfile(fh, dtype=self._dtype, count=hi - lo)
        if len(rec) != hi - lo:
            raise ScanError(f"{self.path}: truncated: block {b} holds {len(rec):,} of "
                            f"{hi - lo:,} points")
        if self._fields is None:
            return np.array(rec["v"][:, :3], dtype=np.float64)
        return np.column_stack([rec[f].astype(np.float64) for f in self._fields])


class _TextBlocks(PointBlocks):
    """Blocks of an XYZ text file, found through the byte offset of each block."""

    def __init__(self, path: str, offsets: list[int], ends: list[int], n: int,
                 chunk: int) -> None:
        super().__init__(path, n, chunk)
        self._offsets, self._ends = offsets, ends

    def block(self, b: int) -> np.ndarray:
        with open(self.path, "rb") as fh:
            fh.seek(self._offsets[b])
            data = fh.read(self._ends[b] - self._offsets[b])
        lo, hi = self.bounds(b)
        try:
            pts = np.loadtxt(io.BytesIO(data.replace(b",", b" ")), usecols=(0, 1, 2),
                             comments="#", ndmin=2, dtype=np.float64)
        except ValueError as exc:
            raise ScanError(f"{self.path}: cannot read XYZ near point {lo + 1:,}: "
                            f"{str(exc).splitlines()[0]}") from None
        if len(pts) != hi - lo:  # pragma: no cover - the index counted these lines
            raise ScanError(f"{self.path}: the file changed while it was read")
        return pts


def _ply_blocks(path: str, name: str, chunk: int) -> PointBlocks:
    try:
        with open(path, "rb") as fh:
            ply = read_ply_data(fh)
        vertex = ply_vertex(ply)
    except ParseError as exc:
        raise ScanError(f"{name}: cannot read PLY: {exc}") from None
    except Exception as exc:  # parser boundary: never leak a third-party traceback
        raise ScanError(f"{name}: cannot read PLY: {one_line(exc)}") from None
    if ply.text or not isinstance(vertex.data, np.memmap):
        raise ScanError(f"{name}: an ASCII PLY (or one with lists before its vertices) "
                        "cannot be streamed: convert it to binary PLY or NPY")
    data = vertex.data
    return _ArrayBlocks(name, int(data.offset), data.dtype, len(data), chunk, ("x", "y", "z"))


def _text_blocks(path: str, name: str, chunk: int, fmt: str) -> PointBlocks:
    offsets, ends, n = [], [], 0
    first = True
    with open(path, "rb") as fh:
        try:
            check_text(fh.read(TEXT_PROBE))
        except ParseError as exc:
            raise ScanError(f"{name}: cannot read {fmt}: {exc}") from None
        fh.seek(0)
        pos = 0
        for line in fh:
            start, pos = pos, pos + len(line)
            s = line.strip()
            if not s or s.startswith(b"#"):
                continue
            if first:
                first = False
                if is_count_line(s):  # a leading count line, as load_scan skips it
                    continue
            if n % chunk == 0:
                if ends:
                    ends[-1] = start
                offsets.append(start)
                ends.append(-1)
            n += 1
    if ends:
        ends[-1] = pos
    return _TextBlocks(name, offsets, ends, n, chunk)


def _npy_blocks(path: str, name: str, chunk: int) -> PointBlocks:
    try:
        with open(path, "rb") as fh:
            shape, fortran, dtype = npy_header(fh)
            offset = fh.tell()
        check_npy_points(shape, dtype)
    except ParseError as exc:
        raise ScanError(f"{name}: cannot read NPY: {exc}") from None
    except Exception as exc:
        raise ScanError(f"{name}: cannot read NPY: {one_line(exc)}") from None
    if fortran:
        raise ScanError(f"{name}: an NPY array in Fortran order cannot be streamed: "
                        "save it in C order (np.save(path, np.ascontiguousarray(a)))")
    row = np.dtype([("v", dtype, (shape[1],))])
    return _ArrayBlocks(name, offset, row, shape[0], chunk)


def open_points(path: str | os.PathLike[str], chunk: int = DEFAULT_CHUNK,
                options: Any = None) -> PointBlocks:
    """Open a scan file for reading in blocks (formats: :data:`STREAM_FORMATS`).

    ``options`` (:class:`~asrbf_mesh._range_io.RangeOptions` or a dict) gives a LAS/LAZ
    file's class and return filters, applied chunk by chunk as the file is read.

    The header and format checks are :func:`load_scan`'s (:mod:`asrbf_mesh._readers`).

    Raises
    ------
    ScanError
        Missing file, a directory, an empty file, another format, an ASCII PLY, an
        NPY that is not an (N, 3) real array in C order, a binary point list.
    """
    p, name = check_scan_path(path, STREAM_FORMATS,
                              "format {shown} cannot be streamed (load it with load_scan)")
    ext = p.suffix.lower()
    if ext in (".las", ".laz"):
        from ._lidar import las_blocks
        from ._range_io import RangeOptions

        opts = RangeOptions.of(options)
        return las_blocks(p, chunk, classes=opts.classes, returns=opts.returns)
    if ext == ".ply":
        return _ply_blocks(str(p), name, chunk)
    if ext == ".npy":
        return _npy_blocks(str(p), name, chunk)
    return _text_blocks(str(p), name, chunk, FORMAT_NAMES[ext])


# --------------------------------------------------------------------------- order


def block_order(n: int, chunk: int, mix: int, rng: np.random.Generator) -> np.ndarray:
    """Return the replay order of one streaming pass over ``n`` points, (n,) int64.

    The blocks (``chunk`` consecutive points each) in a random order; each run of
    ``mix`` of them in that order is one group, replayed in a random order of its
    points. The draws from ``rng`` are the streaming fit's own, so
    ``asrbf_mesh.fit(points, order=lambda rng: block_order(n, chunk, mix, rng))``
    learns exactly what :func:`fit_stream` learns from the file.

    Examples
    --------
    >>> o = block_order(10, 4, 2, np.random.default_rng(0))
    >>> sorted(o.tolist()) == list(range(10))
    True
    """
    n_blocks = -(-n // chunk)
    blocks = rng.permutation(n_blocks)
    out = []
    for g in range(0, n_blocks, mix):
        idx = np.concatenate([np.arange(b * chunk, min((b + 1) * chunk, n))
                              for b in blocks[g:g + mix]])
        out.append(idx[rng.permutation(len(idx))])
    return np.concatenate(out).astype(np.int64)


# --------------------------------------------------------------------------- fit


def _warn_far_points(name: str, sample: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> None:
    """Warn when a few points far from the rest set the scan's extent (stray returns).

    An in-memory fit leaves isolated points out (:func:`asrbf_mesh.isolated_points`); a
    streamed one cannot find them in O(K + block) memory, but it can see their effect: the
    full range of an axis reaching more than ten robust extents (1st-99th percentile range
    of the spacing sample; at least a tenth of the largest axis's) beyond that range. On the
    real scans here the full range reaches at most 1.06 robust extents beyond (the face
    map's depth).
    """
    if len(sample) < 100:
        return
    q_lo, q_hi = np.quantile(sample, [0.01, 0.99], axis=0)
    ext = q_hi - q_lo
    ext = np.maximum(ext, 0.1 * float(ext.max()))
    if not ext.max() > 0:
        return
    excess = np.maximum(q_lo - lo, hi - q_hi) / ext
    axis = int(np.argmax(excess))
    if excess[axis] > 10.0:
        warnings.warn(
            f"{name}: a few points lie far from the rest: along the view frame's "
            f"{'xyz'[axis]} axis the scan spans {hi[axis] - lo[axis]:.6g} where 98 % of it "
            f"spans {q_hi[axis] - q_lo[axis]:.6g}; a streamed fit does not leave isolated "
            "points out (its frame and surface suffer): remove them, or fit without "
            "--stream, which does", OutlierWarning, stacklevel=3)


def fit_stream(path: str | os.PathLike[str], config: FitConfig | None = None, *,
               seed: int = 0, view_axis: str = "z", chunk: int = DEFAULT_CHUNK,
               mix: int = DEFAULT_MIX, progress: bool | None = None,
               options: Any = None, **overrides: Any) -> Network:
    """Fit an ASRBF network to a scan file too large for memory, block by block.

    Parameters
    ----------
    path : str or os.PathLike
        Points file: NPY (N, 3), binary PLY (vertex x, y, z), XYZ text or LAS/LAZ
        (with ``options``' class and return filters).
    config : FitConfig, optional
        As :func:`asrbf_mesh.fit`; ``polish`` must be ``"weights"`` or ``"none"``
        (the full polish needs every point at once).
    seed : int
        Seeds the block order and the replay order within groups.
    view_axis : {"z", "x", "y"}
        Depth direction (``"pca"`` would need a pass of its own and is refused).
    chunk : int
        Points per block, a multiple of 8,192 (default 65,536).
    mix : int
        Blocks loaded and replayed together (default 16): memory ``mix * chunk``
        points, and a closer approximation of a uniform random order the larger.
    progress : bool, optional
        Progress bars on stderr (default: on a terminal).
    **overrides
        FitConfig fields.

    Returns
    -------
    Network
        ``info`` as :func:`asrbf_mesh.fit`'s, plus ``streamed`` (True), ``chunk``,
        ``mix`` and ``spacing_exact`` (False when the spacing came from the tiles).

    Raises
    ------
    ScanError
        Unreadable file, NaN or infinite coordinates (the block is named), too few
        points, no x or y extent.
    ConfigError
        Bad ``chunk``, ``mix``, ``view_axis`` or ``polish="full"``.
    """
    cfg = (config or FitConfig()).replace(**overrides) if overrides else (config or FitConfig())
    chunk = check_int(chunk, "chunk", 1)
    mix = check_int(mix, "mix", 1)
    seed = check_seed(seed)
    if chunk % _polish._CHUNK:
        raise ConfigError(f"chunk must be a multiple of {_polish._CHUNK:,} points, got {chunk:,}")
    if cfg.polish == "full":
        raise ConfigError("polish='full' needs every point in memory; a streaming fit "
                          "polishes the weights ('weights') or nothing ('none')")
    if view_axis not in _AXES:
        raise ConfigError(f"a streaming fit takes view_axis 'z', 'x' or 'y', got {view_axis!r}")
    t_start = time.perf_counter()
    src = open_points(path, chunk, options)
    name = src.path
    if src.n < MIN_POINTS:
        raise ScanError(f"{name}: only {src.n} points, a fit needs at least {MIN_POINTS}")
    rot = _AXES[view_axis].copy()

    # pass 1: bounds, finiteness, provenance
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    absmax = 0.0
    sha = hashlib.sha256()
    tick = _validate.progress(src.n, progress, "frame", unit="pt")
    for b in range(src.n_blocks):
        pts = src.block(b)
        finite = np.isfinite(pts).all(axis=1)
        if not finite.all():
            first = src.bounds(b)[0] + int(np.argmin(finite))
            raise ScanError(f"{name}: point {first + 1:,} has NaN or infinite coordinates")
        sha.update(pts.tobytes())
        local = pts @ rot
        np.minimum(lo, local.min(axis=0), out=lo)
        np.maximum(hi, local.max(axis=0), out=hi)
        absmax = max(absmax, float(np.abs(local).max()))
        if tick:
            tick(len(pts))

    def unit_block(b: int) -> tuple[np.ndarray, np.ndarray]:
        return unit_height_field(frame, src.block(b) @ rot)

    # pass 2: the spacing (exact, or from tiles) and the warnings
    exact = src.n <= EXACT_SPACING_MAX
    try:
        frame = frame0 = frame_from_bounds(rot, lo, hi, absmax, view_axis)
    except ScanError as exc:
        raise ScanError(f"{name}: {exc}") from None
    sample_local, sample_xy, all_xy = [], [], []
    tiles = None
    if not exact:
        side = 64
        want = math.ceil(TILE_SAMPLE / (src.n / side**2))
        tiles = np.zeros(side * side, bool)
        tiles[np.random.default_rng(0).choice(side * side, min(want, side * side),
                                              replace=False)] = True
    for b in range(src.n_blocks):
        pts = src.block(b)
        local = pts @ rot
        xy, _ = unit_height_field(frame0, local)
        if exact:
            all_xy.append(xy)
            keep = np.random.default_rng(b).random(len(xy)) < TILE_SAMPLE / src.n
        else:
            cell = (np.minimum((xy[:, 1] * 64).astype(np.int64), 63) * 64
                    + np.minimum((xy[:, 0] * 64).astype(np.int64), 63))
            keep = tiles[cell]
        sample_local.append(local[keep])
        sample_xy.append(xy[keep])
    local_s = np.concatenate(sample_local)
    _warn_far_points(name, local_s, lo, hi)
    try:
        frame = frame_from_bounds(rot, lo, hi, absmax, view_axis,
                                  np.concatenate(all_xy) if exact else local_s[:, :2])
    except ScanError as exc:
        raise ScanError(f"{name}: {exc}") from None
    if exact:
        spacing = sampling_spacing(np.concatenate(all_xy))
        del all_xy
    else:
        spacing = sampling_spacing(np.concatenate(sample_xy))
    fold = 0.0
    if len(local_s) > 10:
        fold = check_height_field(local_s, local_s @ rot.T, view_axis, stacklevel=2)
    d_min = cfg.d_min if cfg.d_min is not None else auto_d_min(spacing, cfg.error_threshold)

    # passes 3..: learning, groups of blocks in a seeded order
    rng = np.random.default_rng(seed)

    def batches() -> Iterator[tuple[np.ndarray, np.ndarray, np.ndarray]]:
        for _ in range(cfg.passes):
            order = rng.permutation(src.n_blocks)
            for g in range(0, src.n_blocks, mix):
                parts = [unit_block(int(b)) for b in order[g:g + mix]]
                X = np.concatenate([p[0] for p in parts])
                Z = np.concatenate([p[1] for p in parts])
                yield X, Z, rng.permutation(len(Z)).astype(np.int64)

    learned = learn_from(batches(), src.n, cfg, d_min, progress=progress)
    a0, centers, widths, weights = learned.a0, learned.centers, learned.widths, learned.weights
    tp = time.perf_counter()
    pr = None
    if polish_kind(fold, cfg.polish) == "weights":
        pr = _polish.polish_weights_blocks(
            lambda: (unit_block(b) for b in range(src.n_blocks)), src.n, a0, centers, widths,
            weights, cfg.support, cfg.polish_ridge)
        a0, centers, widths, weights = pr.a0, pr.centers, pr.widths, pr.weights
    polish_seconds = time.perf_counter() - tp
    net = Network(a0, centers, widths, weights, frame, cfg, learned.log)

    # last pass: the error statistics
    s_abs = s_mm = s_mm2 = 0.0
    for b in range(src.n_blocks):
        xy, z = unit_block(b)
        r = np.abs(z - net.evaluate(xy, unit=True))
        mm = r * frame.scale[2]
        s_abs += float(r.sum())
        s_mm += float(mm.sum())
        s_mm2 += float((mm * mm).sum())
    n = src.n
    ebar = s_abs / n
    mean_mm = s_mm / n
    info = fit_info(n, net, name, sha.hexdigest(), seed, spacing, learned, pr, ebar, mean_mm,
                    math.sqrt(max(s_mm2 / n - mean_mm * mean_mm, 0.0)), polish_seconds,
                    time.perf_counter() - t_start, streamed=True, chunk=chunk, mix=mix,
                    spacing_exact=exact)
    return Network(a0, centers, widths, weights, frame, cfg, learned.log, info.to_dict())
