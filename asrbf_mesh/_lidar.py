"""Airborne lidar point clouds: LAS and LAZ files in, LAS and LAZ files with the fill out.

Needs the optional ``lidar`` extra (``pip install 'asrbf-mesh[lidar]'``: laspy, and lazrs
for compressed LAZ); without it every function here raises a one-line
:class:`~asrbf_mesh.errors.ScanError` saying so.

* :func:`read_las` reads the points of one LAS/LAZ file in its real coordinates (the
  integer records times the header's scales plus its offsets), kept by classification
  code and by return, as a :class:`~asrbf_mesh.Scan`, with the :class:`LasMeta` a writer
  needs (version, point format, scales, offsets, CRS).
* :func:`las_blocks` gives the same points block by block (a
  :class:`~asrbf_mesh._stream.PointBlocks`) for a streaming fit, reading the file in
  chunks: memory O(chunk), whatever the size of the file.
* :func:`write_las_with_fill` writes the input file's point records unchanged, followed
  by the fill points flagged synthetic, in the same point format, scales, offsets and
  (extended) variable-length records, CRS included.

Filters
-------
``classes``
    ASPRS classification codes to keep (``(2,)``: ground; ``(2, 9)``: ground and water);
    ``None`` keeps every class. The code is the record's classification field (5 bits in
    point formats 0-5, 8 bits in formats 6-10; the synthetic, key-point and withheld
    flags are not part of it).
``returns``
    ``"first"``: return number 1; ``"last"``: return number equal to the number of
    returns of its pulse; ``"single"``: pulses of one return (number of returns 1);
    an iterable of return numbers keeps those (``(1, 2)``: first and second returns);
    ``None`` keeps every return. A record whose return fields are 0 (invalid, but
    found in some files) is neither first, last nor single.

Both filters together keep the points that pass each.

>>> scan, meta = read_las("tile.laz", classes=(2,), returns="last")   # doctest: +SKIP
>>> write_las_with_fill("tile.laz", meta, fill, "tile_filled.laz")  # doctest: +SKIP
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from ._atomic import atomic_path, check_output_path
from ._learn import MIN_POINTS
from ._mesh import Scan
from ._readers import PointBlocks, check_scan_path
from ._validate import check_int, check_points, one_line, plural, quiet_logger
from .errors import ConfigError, ScanError

__all__ = ["LIDAR_FORMATS", "LasBlocks", "LasMeta", "VlrRecord", "las_blocks", "read_las",
           "write_las_with_fill"]

#: File extensions read and written here.
LIDAR_FORMATS = (".las", ".laz")
#: Named return filters (see the module's documentation).
RETURN_FILTERS = ("first", "last", "single")
#: Points per chunk read from the file by :func:`read_las` and the writer.
READ_CHUNK = 1 << 20

#: ASPRS standard classes (LAS 1.4 R15), for messages.
CLASS_NAMES = {
    0: "never classified", 1: "unclassified", 2: "ground", 3: "low vegetation",
    4: "medium vegetation", 5: "high vegetation", 6: "building", 7: "low noise",
    8: "model key point", 9: "water", 10: "rail", 11: "road surface", 12: "overlap",
    13: "wire guard", 14: "wire conductor", 15: "transmission tower", 16: "wire connector",
    17: "bridge deck", 18: "high noise",
}

_EXTRA = "pip install 'asrbf-mesh[lidar]'"
_I32 = (-(2**31), 2**31 - 1)


# --------------------------------------------------------------------------- metadata


class VlrRecord(NamedTuple):
    """One variable-length record, verbatim.

    Attributes
    ----------
    user_id : str
    record_id : int
    description : str
    data : bytes
        The record's payload, byte for byte.
    extended : bool
        An extended VLR (after the points, LAS 1.4).
    """

    user_id: str
    record_id: int
    description: str
    data: bytes
    extended: bool


@dataclass(frozen=True, eq=False)
class LasMeta:
    """What a LAS/LAZ file was and what :func:`read_las` kept of it.

    Attributes
    ----------
    source : str
        The file read.
    version : str
        LAS version, e.g. ``"1.4"``.
    point_format : int
        Point data record format (0-10).
    scales, offsets : tuple of 3 float
        Coordinate ``= integer record * scale + offset``, for x, y, z.
    compressed : bool
        LAZ (compressed points).
    crs : pyproj.CRS or None
        The coordinate reference system from ``header.parse_crs()``; ``None`` without
        a CRS record, when it is not understood, or without pyproj installed.
    crs_vlrs : tuple of VlrRecord
        The CRS records (user id ``LASF_Projection``: GeoTIFF keys, OGC WKT), verbatim,
        whether or not pyproj can parse them.
    n_read : int
        Points in the file (every one is read).
    n_kept : int
        Points kept by the filters.
    class_counts : tuple of (int, int)
        ``(code, points)`` of every classification code in the file, by code.
    classes : tuple of int or None
        The class filter applied.
    returns : str, tuple of int or None
        The return filter applied.
    """

    source: str
    version: str
    point_format: int
    scales: tuple[float, float, float]
    offsets: tuple[float, float, float]
    compressed: bool
    crs: Any
    crs_vlrs: tuple[VlrRecord, ...]
    n_read: int
    n_kept: int
    class_counts: tuple[tuple[int, int], ...]
    classes: tuple[int, ...] | None = None
    returns: str | tuple[int, ...] | None = None

    @property
    def has_crs(self) -> bool:
        """Whether the file carries a CRS record."""
        return bool(self.crs_vlrs) or self.crs is not None


# --------------------------------------------------------------------------- laspy


def _laspy(verb: str = "reading") -> Any:
    """Import laspy, or raise the one-line error naming the ``lidar`` extra."""
    try:
        import laspy
    except ImportError:
        raise ScanError(f"{verb} LAS needs the lidar extra: {_EXTRA}") from None
    return laspy


def _laz_backends(laspy: Any, name: str, verb: str = "reading") -> Any:
    """Return the LAZ backends available, or raise the one-line error naming lazrs."""
    try:
        available = tuple(laspy.LazBackend.detect_available())
    except Exception:  # a broken backend install counts as none
        available = ()
    if not available:
        raise ScanError(f"{name}: {verb} LAZ (compressed LAS) needs lazrs: pip install lazrs "
                        f"(or {_EXTRA})")
    return available


def _check_header(path: Path, name: str) -> None:
    """Check the public header block's counts against the file's size before laspy reads it.

    laspy trusts the header: a corrupt count of variable-length records (3 billion in a
    952-byte file, found by fuzzing) made it loop for ever. The counts and offsets must
    fit in the file: header size <= offset to the points <= file size, every VLR (54
    bytes of header at least) between the two, and LAS 1.4's extended VLRs (60 bytes at
    least) inside the file.
    """
    import struct

    size = path.stat().st_size
    with open(path, "rb") as fh:
        head = fh.read(375)
    if len(head) < 227 or head[:4] != b"LASF":
        raise ScanError(f"{name}: not a LAS file (no LASF signature and 227-byte header)")
    minor = head[25]
    header_size, offset, n_vlr = struct.unpack_from("<HLL", head, 94)
    if not 227 <= header_size <= offset <= size:
        raise ScanError(f"{name}: corrupt LAS header: header size {header_size}, points at "
                        f"byte {offset:,}, file of {size:,} bytes")
    if n_vlr * 54 > offset - header_size:
        raise ScanError(f"{name}: corrupt LAS header: {n_vlr:,} variable-length records "
                        f"cannot fit in {offset - header_size:,} bytes")
    if minor >= 4 and header_size >= 375 and len(head) >= 375:
        start, n_evlr = struct.unpack_from("<QL", head, 235)
        if n_evlr and not (offset <= start and start + 60 * n_evlr <= size):
            raise ScanError(f"{name}: corrupt LAS header: {n_evlr:,} extended records from "
                            f"byte {start:,} in a file of {size:,} bytes")


def _open(laspy: Any, path: Path, name: str) -> Any:
    """Open ``path`` for reading (header only); LAZ checks its backend first."""
    _check_header(path, name)
    backend = None
    if path.suffix.lower() == ".laz":
        backend = _laz_backends(laspy, name)
    try:
        with quiet_logger("laspy"):
            reader = laspy.open(path, mode="r", laz_backend=backend)
    except Exception as exc:  # parser boundary: never leak a third-party traceback
        raise ScanError(f"{name}: cannot read LAS: {one_line(exc)}") from None
    header = reader.header
    try:
        if header.are_points_compressed and backend is None:
            reader.laz_backend = _laz_backends(laspy, name)
        if not header.are_points_compressed:
            count, size = int(header.point_count), int(header.point_format.size)
            need = int(header.offset_to_point_data) + count * size
            have = path.stat().st_size
            if have < need:
                whole = max(have - int(header.offset_to_point_data), 0) // size
                raise ScanError(f"{name}: truncated: the header counts {count:,} points, the "
                                f"file holds {whole:,} ({have:,} of {need:,} bytes)")
    except BaseException:
        reader.close()
        raise
    return reader


def _chunks(reader: Any, name: str, chunk: int, start: int = 0) -> Iterator[Any]:
    """Point records of ``reader`` from point ``start``, ``chunk`` at a time, checked whole."""
    total = int(reader.header.point_count)
    pos = start
    try:
        with quiet_logger("laspy"):
            if start:
                reader.seek(start)
            it = reader.chunk_iterator(chunk)
            while pos < total:
                pts = next(it, None)
                want = min(chunk, total - pos)
                got = 0 if pts is None else len(pts)
                if got != want:
                    raise ScanError(f"{name}: truncated: the header counts {total:,} points, "
                                    f"the file holds {pos + got:,}")
                pos += got
                yield pts
    except ScanError:
        raise
    except Exception as exc:
        after = f" after point {pos:,}" if pos else ""
        raise ScanError(f"{name}: corrupt or truncated point data{after}: "
                        f"{one_line(exc)}") from None


def _vlr_record(vlr: Any, extended: bool) -> VlrRecord:
    data = vlr.record_data_bytes() if hasattr(vlr, "record_data_bytes") else vlr.record_data
    return VlrRecord(str(vlr.user_id), int(vlr.record_id), str(vlr.description), bytes(data),
                     extended)


def _crs(header: Any) -> tuple[Any, tuple[VlrRecord, ...]]:
    """Return the parsed CRS (None without pyproj) and the CRS records verbatim."""
    records = [_vlr_record(v, False) for v in header.vlrs if v.user_id == "LASF_Projection"]
    if header.evlrs is not None:
        records += [_vlr_record(v, True) for v in header.evlrs
                    if v.user_id == "LASF_Projection"]
    crs = None
    if records:
        try:
            with quiet_logger("laspy"):
                crs = header.parse_crs()
        except Exception:  # pyproj missing, or a CRS it does not understand
            crs = None
    return crs, tuple(records)


# --------------------------------------------------------------------------- filters


def _codes(values: Any, name: str, item: str, lo: int, hi: int,
           expected: str) -> tuple[int, ...]:
    """Sorted distinct ints in [lo, hi] from an int or an iterable of them; ConfigError."""
    if isinstance(values, (int, np.integer)) and not isinstance(values, bool):
        values = (values,)
    try:
        codes = tuple(sorted({check_int(c, f"a {item}", lo, hi) for c in values}))
    except TypeError:
        raise ConfigError(f"{name} must be {expected}, got {values!r}") from None
    if not codes:
        raise ConfigError(f"{name} is empty: give at least one {item}, or None for all")
    return codes


def _check_classes(classes: Iterable[int] | None) -> tuple[int, ...] | None:
    if classes is None:
        return None
    return _codes(classes, "classes", "class code", 0, 255,
                  "an iterable of class codes (0-255)")


def _check_returns(returns: str | Iterable[int] | None) -> str | tuple[int, ...] | None:
    if returns is None:
        return None
    if isinstance(returns, str):
        if returns not in RETURN_FILTERS:
            raise ConfigError(f"returns must be one of {', '.join(RETURN_FILTERS)} or return "
                              f"numbers, got {returns!r}")
        return returns
    return _codes(returns, "returns", "return number", 1, 15,
                  "'first', 'last', 'single' or return numbers")


def _return_mask(pts: Any, returns: str | tuple[int, ...]) -> np.ndarray:
    rn = np.asarray(pts.return_number)
    if returns == "first":
        return rn == 1
    nr = np.asarray(pts.number_of_returns)
    if returns == "last":
        return (rn == nr) & (rn > 0)
    if returns == "single":
        return nr == 1
    return np.isin(rn, np.asarray(returns))


def _class_text(code: int) -> str:
    known = CLASS_NAMES.get(code)
    return f"class {code} ({known})" if known else f"class {code}"


class _Filter:
    """The class and return filters of one read, and the counts they see."""

    def __init__(self, classes: tuple[int, ...] | None,
                 returns: str | tuple[int, ...] | None) -> None:
        self.classes, self.returns = classes, returns
        self.class_hist = np.zeros(256, np.int64)
        self.n_read = self.n_class = self.n_kept = 0

    def __call__(self, pts: Any) -> np.ndarray:
        """Keep mask of one chunk; counts it."""
        cls = np.asarray(pts.classification).astype(np.int64)
        self.class_hist += np.bincount(cls, minlength=256)[:256]
        keep = np.ones(len(cls), bool)
        if self.classes is not None:
            keep &= np.isin(cls, np.asarray(self.classes))
        self.n_class += int(keep.sum())
        if self.returns is not None:
            keep &= _return_mask(pts, self.returns)
        self.n_read += len(cls)
        self.n_kept += int(keep.sum())
        return keep

    def counts(self) -> tuple[tuple[int, int], ...]:
        return tuple((int(c), int(self.class_hist[c])) for c in np.flatnonzero(self.class_hist))

    def what(self) -> str:
        parts = []
        if self.classes is not None:
            parts.append("classes " + ", ".join(str(c) for c in self.classes))
        if self.returns is not None:
            parts.append(f"returns {self.returns!r}" if isinstance(self.returns, str)
                         else "return numbers " + ", ".join(str(r) for r in self.returns))
        return " and ".join(parts)

    def check(self, name: str) -> None:
        """Raise the one-line error when the filters keep no point, or too few to fit."""
        if self.n_read == 0:
            raise ScanError(f"{name}: the LAS file holds no points")
        if self.classes is not None and self.n_class == 0:
            held = ", ".join(f"{_class_text(c)}: {n:,}" for c, n in self.counts())
            wanted = ", ".join(_class_text(c) for c in self.classes)
            raise ScanError(f"{name}: no point of {wanted}; the file holds {held}")
        if self.n_kept == 0:
            which = (f"of the {plural(self.n_class, 'point')} of classes "
                     f"{', '.join(str(c) for c in self.classes)}"
                     if self.classes is not None else f"of {plural(self.n_read, 'point')}")
            raise ScanError(f"{name}: no point {which} passes returns={self.returns!r}")
        if self.n_kept < MIN_POINTS:
            kept = f" by {self.what()}" if self.what() else ""
            raise ScanError(f"{name}: only {plural(self.n_kept, 'point')} of "
                            f"{self.n_read:,} kept{kept}, a fit needs at least {MIN_POINTS}")


def _xyz(pts: Any, keep: np.ndarray) -> np.ndarray:
    """Real coordinates of the kept records, (m, 3) float64."""
    return np.column_stack([np.asarray(pts.x, dtype=np.float64)[keep],
                            np.asarray(pts.y, dtype=np.float64)[keep],
                            np.asarray(pts.z, dtype=np.float64)[keep]])


def _meta(name: str, header: Any, flt: _Filter) -> LasMeta:
    crs, crs_vlrs = _crs(header)
    return LasMeta(
        source=name, version=str(header.version), point_format=int(header.point_format.id),
        scales=tuple(float(s) for s in header.scales),
        offsets=tuple(float(o) for o in header.offsets),
        compressed=bool(header.are_points_compressed), crs=crs, crs_vlrs=crs_vlrs,
        n_read=flt.n_read, n_kept=flt.n_kept, class_counts=flt.counts(),
        classes=flt.classes, returns=flt.returns)


def _check_path(path: str | os.PathLike[str]) -> tuple[Path, str]:
    return check_scan_path(path, LIDAR_FORMATS, "format {shown} is not LAS/LAZ")


# --------------------------------------------------------------------------- read


def read_las(path: str | os.PathLike[str], classes: Iterable[int] | None = None,
             returns: str | Iterable[int] | None = None) -> tuple[Scan, LasMeta]:
    """Read the points of a LAS/LAZ file, kept by class and by return.

    Parameters
    ----------
    path : str or os.PathLike
        ``.las`` or ``.laz`` file (LAS 1.0-1.4, point formats 0-10).
    classes : iterable of int, optional
        Classification codes to keep, e.g. ``(2,)`` for ground; default every class.
    returns : {"first", "last", "single"} or iterable of int, optional
        Returns to keep (module documentation); default every return.

    Returns
    -------
    scan : Scan
        The kept points in the file's real coordinates (no faces); ``source`` is ``path``.
    meta : LasMeta
        Header, CRS and counts, for :func:`write_las_with_fill`.

    Raises
    ------
    ScanError
        One line: laspy missing, a LAZ without lazrs, a missing, empty, corrupt or
        truncated file, a class filter keeping no point (the classes present are
        named with their counts), fewer than 10 points kept.
    ConfigError
        A bad ``classes`` or ``returns``.
    """
    flt = _Filter(_check_classes(classes), _check_returns(returns))
    laspy = _laspy()
    p, name = _check_path(path)
    reader = _open(laspy, p, name)
    parts = []
    with reader:
        for pts in _chunks(reader, name, READ_CHUNK):
            keep = flt(pts)
            if keep.any():
                parts.append(_xyz(pts, keep))
        header = reader.header
    flt.check(name)
    return (Scan(np.concatenate(parts), source=name), _meta(name, header, flt))


# --------------------------------------------------------------------------- stream


class LasBlocks(PointBlocks):
    """The filtered points of a LAS/LAZ file, by block, read in chunks off the file.

    Block ``b`` holds the kept points ``b * chunk`` to ``(b + 1) * chunk`` (in file
    order). Opening reads the file once, keeping per chunk of records only how many
    points pass the filters; each :meth:`block` reads the chunks of records that hold
    its points (with a seek; in a LAZ, from the compressed chunk that holds the first).

    Attributes
    ----------
    meta : LasMeta
        As :func:`read_las` returns it.
    """

    def __init__(self, path: Path, name: str, chunk: int, flt: _Filter,
                 kept_before: np.ndarray, meta: LasMeta) -> None:
        super().__init__(name, int(kept_before[-1]), chunk)
        self.meta = meta
        self._file, self._flt, self._kept_before = path, flt, kept_before

    def block(self, b: int) -> np.ndarray:
        """Points of block ``b``, (m, 3) float64."""
        b = check_int(b, "block", 0, self.n_blocks - 1)
        lo, hi = self.bounds(b)
        r = int(np.searchsorted(self._kept_before, lo, side="right")) - 1
        skip = lo - int(self._kept_before[r])
        flt = _Filter(self._flt.classes, self._flt.returns)
        laspy = _laspy()
        parts, have = [], 0
        with (_open(laspy, self._file, self.path) as reader,
              contextlib.closing(_chunks(reader, self.path, self.chunk, r * self.chunk)) as it):
            for pts in it:
                xyz = _xyz(pts, flt(pts))
                if skip:
                    xyz, skip = xyz[skip:], max(skip - len(xyz), 0)
                parts.append(xyz[:hi - lo - have])
                have += len(parts[-1])
                if have == hi - lo:
                    break
        if have != hi - lo:
            raise ScanError(f"{self.path}: the file changed while it was read")
        return np.concatenate(parts)


def las_blocks(path: str | os.PathLike[str], chunk: int, classes: Iterable[int] | None = None,
               returns: str | Iterable[int] | None = None) -> LasBlocks:
    """Open a LAS/LAZ file for reading its filtered points in blocks of ``chunk``.

    The file is read once here, a chunk of records at a time, to count the points that
    pass the filters; no more than one chunk of records is in memory at any time, here
    or in :meth:`LasBlocks.block`. The blocks hold, in order, the points
    :func:`read_las` returns with the same filters.

    Parameters
    ----------
    path : str or os.PathLike
    chunk : int
        Points per block (and records per chunk read from the file), at least 1.
    classes, returns
        As :func:`read_las`.

    Returns
    -------
    LasBlocks

    Raises
    ------
    ScanError
        As :func:`read_las`.
    ConfigError
        A bad ``chunk``, ``classes`` or ``returns``.
    """
    chunk = check_int(chunk, "chunk", 1)
    flt = _Filter(_check_classes(classes), _check_returns(returns))
    laspy = _laspy()
    p, name = _check_path(path)
    counts = [0]
    with _open(laspy, p, name) as reader:
        for pts in _chunks(reader, name, chunk):
            counts.append(int(flt(pts).sum()))
        header = reader.header
    flt.check(name)
    return LasBlocks(p, name, chunk, flt, np.cumsum(counts), _meta(name, header, flt))


# --------------------------------------------------------------------------- write


def _fill_records(fill: np.ndarray, meta: LasMeta, name: str) -> np.ndarray:
    """Integer records (n, 3) of the fill points; ScanError if one is out of range."""
    scales, offsets = np.asarray(meta.scales), np.asarray(meta.offsets)
    with np.errstate(all="ignore"):
        rec = np.rint((fill - offsets) / scales)
    bad = ~((rec >= _I32[0]) & (rec <= _I32[1])).all(axis=1)
    if bad.any():
        lo = np.asarray(_I32[0]) * scales + offsets
        hi = np.asarray(_I32[1]) * scales + offsets
        i = int(np.argmax(bad))
        span = ", ".join(f"{a} in [{lo[k]:.6g}, {hi[k]:.6g}]" for k, a in enumerate("xyz"))
        raise ScanError(f"{name}: {plural(int(bad.sum()), 'fill point')} cannot be stored with "
                        f"the file's scales and offsets (fill point {i + 1:,} is "
                        f"{tuple(float(v) for v in fill[i])}; representable: {span})")
    return rec.astype(np.int32)


def write_las_with_fill(src_path: str | os.PathLike[str], meta: LasMeta, fill_points: Any,
                        out_path: str | os.PathLike[str], *,
                        classification: int | None = None) -> Path:
    """Write a LAS/LAZ file: the input's points unchanged, then the fill points, synthetic.

    Every record of ``src_path`` is copied as it is (all fields; whatever the filters of
    :func:`read_las` kept), then one record per fill point: its coordinates as integer
    records with the file's scales and offsets (rounded to the nearest), the synthetic
    flag set, ``classification``, return 1 of 1 and every other field 0. The header
    keeps the version, point format, scales, offsets, and every VLR and extended VLR
    (the CRS among them) byte for byte; its point counts and bounds are updated. The
    output appears atomically, compressed when ``out_path`` ends in ``.laz``.

    Parameters
    ----------
    src_path : str or os.PathLike
        The file :func:`read_las` read (never modified).
    meta : LasMeta
        :func:`read_las`'s metadata of ``src_path``.
    fill_points : (M, 3) array_like
        Fill points in the file's real coordinates (not modified).
    out_path : str or os.PathLike
        ``.las`` or ``.laz``; not ``src_path``.
    classification : int, optional
        Class code of the fill points; default the class :func:`read_las` kept when it
        kept exactly one, else 0 (never classified).

    Returns
    -------
    Path
        ``out_path``.

    Raises
    ------
    ScanError
        laspy missing, a LAZ without lazrs, an unreadable ``src_path`` or one that is not
        the file ``meta`` describes, fill points that are not (M, 3) finite numbers or
        that the scales and offsets cannot represent.
    ConfigError
        ``out_path`` is not ``.las``/``.laz``, or a bad ``classification``.
    AsrbfError
        ``out_path`` in a missing or read-only folder, or naming ``src_path``.
    """
    laspy = _laspy("writing")
    p, name = _check_path(src_path)
    out = Path(out_path)
    if out.suffix.lower() not in LIDAR_FORMATS:
        raise ConfigError(f"{out}: a LAS output must end in .las or .laz, not "
                          f"{out.suffix or '(no extension)'!r}")
    check_output_path(out, p)
    fill = check_points(fill_points, "fill_points", min_points=0)
    if classification is None:
        classification = (meta.classes[0] if meta.classes is not None
                          and len(meta.classes) == 1 else 0)
    classification = check_int(classification, "classification", 0,
                               31 if meta.point_format < 6 else 255)
    records = _fill_records(fill, meta, name)
    compress = out.suffix.lower() == ".laz"
    backend = _laz_backends(laspy, str(out), "writing") if compress else None

    with _open(laspy, p, name) as reader:
        header = reader.header
        if (int(header.point_format.id) != meta.point_format
                or tuple(float(s) for s in header.scales) != tuple(meta.scales)
                or tuple(float(o) for o in header.offsets) != tuple(meta.offsets)):
            raise ScanError(f"{name}: not the file the metadata describes (point format, "
                            "scales or offsets differ): read it again with read_las")
        with atomic_path(out) as tmp:
            try:
                with quiet_logger("laspy"), laspy.open(
                        tmp, mode="w", header=header, do_compress=compress,
                        laz_backend=backend) as writer:
                    for pts in _chunks(reader, name, READ_CHUNK):
                        writer.write_points(pts)
                    if len(records):
                        new = laspy.ScaleAwarePointRecord.zeros(len(records), header=header)
                        new.X, new.Y, new.Z = records[:, 0], records[:, 1], records[:, 2]
                        new.classification = np.full(len(records), classification, np.uint8)
                        new.synthetic = np.ones(len(records), np.uint8)
                        new.return_number = np.ones(len(records), np.uint8)
                        new.number_of_returns = np.ones(len(records), np.uint8)
                        writer.write_points(new)
                    if header.evlrs:
                        writer.write_evlrs(header.evlrs)
            except ScanError:
                raise
            except Exception as exc:
                raise ScanError(f"{out}: cannot write LAS: {one_line(exc)}") from None
    return out
