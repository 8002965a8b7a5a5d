"""Gridded range data as people have it: depth images, GeoTIFF tiles, elevation arrays.

:class:`RangeGrid` holds one grid of measurements (``NaN`` = no measurement), the
pixel-to-world mapping and what is needed to write a modified grid back in kind
(:func:`~asrbf_mesh._range_write.write_like`): the source format and dtype, the depth scale, the "no
measurement" value and, for GeoTIFF, the georeferencing tags.

World coordinates (right-handed; the scan is a height field ``z(x, y)`` seen from +z):

* depth image with pinhole intrinsics ``(fx, fy, cx, cy)`` (pixels; pixel ``(u, v)`` =
  (column, row), centres at integers): OpenCV camera coordinates ``X = (u - cx) Z / fx``,
  ``Y = (v - cy) Z / fy``, ``Z = depth`` in metres, turned by 180 degrees about the
  x axis (OpenGL convention): world ``(X, -Y, -Z)``. The camera sits at the origin
  looking down -z, image up is +y, nearer surfaces have larger z.
* depth image without intrinsics: ``x = column``, ``y = -row`` (pixels) and
  ``z = -depth`` (metres): the same orientation, in mixed units.
* elevation grid: ``x`` east and ``y`` north in metres, ``z`` = elevation; row 0 is the
  north edge (north-up). Geographic grids (degrees) are projected equirectangularly at
  the tile's centre latitude with the WGS84 lengths of one degree,
  ``111132.954 - 559.822 cos 2φ + 1.175 cos 4φ`` m of latitude and
  ``111412.84 cos φ - 93.5 cos 3φ + 0.118 cos 5φ`` m of longitude.

:meth:`RangeGrid.to_scan` triangulates pixel adjacency and cuts triangles across depth
jumps: an edge between neighbouring cells is cut when the difference of their depths
(or elevations) exceeds ``jump`` times the lateral footprint of the edge (``Z / f`` per
pixel for depth images, the cell size for elevation grids), i.e. when the surface is
steeper than ``atan(jump)`` against the image plane. The default :data:`DEFAULT_JUMP`
= 10 (84 degrees) was measured: a 60 degree ramp has ratio ``tan 60 = 1.73`` and keeps
every triangle; on a real Kinect frame (TUM RGB-D ``desk``) the disparity quantisation
steps of flat surfaces reach ratios of 6 to 9 at 4 to 9 m, and the histogram of ratios
drops by a factor of 4 between 9 and 10, above which lie the object edges (a 5 cm step at
1 m is 26, a 30 cm step 150).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ._mesh import Scan
from .errors import ConfigError, ScanError

__all__ = [
    "DEFAULT_JUMP",
    "NOMINAL_FOCAL",
    "RangeGrid",
    "degree_lengths",
    "read_depth_image",
    "read_geotiff",
    "read_grid_array",
    "read_range",
    "sniff_range_kind",
]

#: Default of ``jump`` in :meth:`RangeGrid.to_scan` (depth step / lateral footprint).
DEFAULT_JUMP = 10.0
#: Focal length (pixels) assumed for the jump test of a depth image without intrinsics
#: (the VGA Kinect / Xtion value).
NOMINAL_FOCAL = 525.0

#: TIFF tags that carry the georeferencing (copied by :func:`~asrbf_mesh._range_write.write_like`).
_GEO_TAGS = {33550: "ModelPixelScale", 33922: "ModelTiepoint", 34264: "ModelTransformation",
             34735: "GeoKeyDirectory", 34736: "GeoDoubleParams", 34737: "GeoAsciiParams",
             42112: "GDAL_METADATA", 42113: "GDAL_NODATA"}
_LINEAR_UNITS = {9001: 1.0, 9002: 0.3048, 9003: 1200.0 / 3937.0}
_TIFF = (".tif", ".tiff")


@dataclass(frozen=True, eq=False)
class RangeGrid:
    """One grid of range measurements, its pixel-to-world mapping and how to write it back.

    Parameters
    ----------
    z : (H, W) array of float
        Depth in metres (``kind="depth"``) or elevation (``kind="elevation"``); ``NaN``
        where there is no measurement. Stored as a read-only float64 copy.
    kind : {"depth", "elevation"}
        What ``z`` holds.
    intrinsics : (fx, fy, cx, cy), optional
        Pinhole intrinsics in pixels (depth images only).
    cell : (dx, dy), optional
        Cell size in metres (elevation grids; required for them).
    origin : (x0, y0)
        World x, y in metres of the centre of cell (0, 0) (elevation grids).
    source : str, optional
        The file the grid was read from.
    fmt : {"png", "tiff", "geotiff", "npy", "npz"}
        Format of the source file, which :func:`~asrbf_mesh._range_write.write_like` writes again.
    dtype : str
        The source's sample dtype (e.g. ``"uint16"``).
    scale : float, optional
        Source units per metre (depth) or per elevation unit; ``None`` = 1.
    nodata : float, optional
        The value the source used for "no measurement" (``NaN`` allowed).
    crs : {"geographic", "projected"}, optional
        Coordinate system of a georeferenced grid.
    tags : tuple
        GeoTIFF tags to copy, as ``(code, dtype, count, value)``.
    extra : tuple
        Other ``.npz`` members to copy, as ``(name, array)``.
    key : str, optional
        Name of the grid's array in a ``.npz`` source.
    compressed : bool
        Whether a TIFF source was compressed (its copy is then Deflate-compressed).
    """

    z: np.ndarray
    kind: str
    intrinsics: tuple[float, float, float, float] | None = None
    cell: tuple[float, float] | None = None
    origin: tuple[float, float] = (0.0, 0.0)
    source: str | None = None
    fmt: str = "npy"
    dtype: str = "float64"
    scale: float | None = None
    nodata: float | None = None
    crs: str | None = None
    tags: tuple = ()
    extra: tuple = ()
    key: str | None = None
    compressed: bool = False

    def __post_init__(self) -> None:
        """Check the fields and freeze ``z``."""
        where = f"{self.source}: " if self.source else ""
        z = np.array(self.z, dtype=np.float64)
        if z.ndim != 2 or min(z.shape) < 1:
            raise ScanError(f"{where}a range grid must be 2-D, got shape {z.shape}")
        z[~np.isfinite(z)] = np.nan
        z.flags.writeable = False
        object.__setattr__(self, "z", z)
        if self.kind not in ("depth", "elevation"):
            raise ConfigError(f"kind must be 'depth' or 'elevation', got {self.kind!r}")
        if self.intrinsics is not None:
            k = tuple(float(v) for v in self.intrinsics)
            if len(k) != 4 or not all(map(math.isfinite, k)) or k[0] <= 0 or k[1] <= 0:
                raise ConfigError(f"intrinsics must be (fx, fy, cx, cy) with fx, fy > 0, "
                                  f"got {self.intrinsics!r}")
            object.__setattr__(self, "intrinsics", k)
        if self.kind == "elevation":
            object.__setattr__(self, "cell", _check_cell(self.cell, where))
        object.__setattr__(self, "origin", tuple(float(v) for v in self.origin))

    @property
    def shape(self) -> tuple[int, int]:
        """``(rows, cols)`` of the grid."""
        return self.z.shape  # type: ignore[return-value]

    def points(self) -> tuple[np.ndarray, np.ndarray]:
        """World points of the cells that hold a measurement.

        Returns
        -------
        points : (N, 3) float64 array
            In the convention of the module docstring.
        index : (N,) int64 array
            Row-major flat index of each point's cell, ascending.
        """
        index = np.flatnonzero(np.isfinite(self.z))
        rows, cols = np.divmod(index, self.shape[1])
        z = self.z.ravel()[index]
        if self.kind == "elevation":
            dx, dy = self.cell  # type: ignore[misc]
            x, y = self.origin[0] + cols * dx, self.origin[1] - rows * dy
        elif self.intrinsics is not None:
            fx, fy, cx, cy = self.intrinsics
            x, y, z = (cols - cx) * z / fx, -(rows - cy) * z / fy, -z
        else:
            x, y, z = cols.astype(np.float64), -rows.astype(np.float64), -z
        return np.column_stack((x, y, z)), index

    def to_scan(self, jump: float | None = DEFAULT_JUMP) -> Scan:
        """Triangulate the grid by pixel adjacency into a :class:`~asrbf_mesh.Scan`.

        Each 2x2 block of cells gives the triangles of one of its two diagonal splits
        whose three corners hold measurements and whose three edges cross no jump: the
        split with more such triangles, else the shorter 3-D diagonal. So a full block
        gives two triangles, a block with three measurements one. Triangles are
        counter-clockwise seen from +z.

        Parameters
        ----------
        jump : float or None
            Cut an edge whose depth difference exceeds ``jump`` times its lateral
            footprint (see the module docstring); ``None`` cuts nothing.

        Returns
        -------
        Scan
            The valid cells as points (in :meth:`points` order), the triangles, the
            source and ``grid_shape``.
        """
        if jump is not None and not (isinstance(jump, (int, float)) and jump > 0):
            raise ConfigError(f"jump must be a positive number or None, got {jump!r}")
        points, index = self.points()
        rows, cols = self.shape
        vid = np.full(rows * cols, -1, dtype=np.int64)
        vid[index] = np.arange(len(index))
        faces = _block_faces(vid.reshape(rows, cols), self._edge_ok(jump), points)
        return Scan(points, faces if len(faces) else None, source=self.source,
                    grid_shape=(rows, cols))

    def _edge_ok(self, jump: float | None) -> dict[str, np.ndarray]:
        """Whether each edge joins two measurements without a jump, by direction.

        Keys ``h`` (r, c)-(r, c+1), ``v`` (r, c)-(r+1, c), ``d03`` (r, c)-(r+1, c+1) and
        ``d12`` (r, c+1)-(r+1, c).
        """
        z = self.z
        if self.kind == "elevation":
            sx, sy = self.cell  # type: ignore[misc]
        elif self.intrinsics is not None:
            sx, sy = 1.0 / self.intrinsics[0], 1.0 / self.intrinsics[1]
        else:
            sx = sy = 1.0 / NOMINAL_FOCAL
        pairs = {"h": (z[:, :-1], z[:, 1:], 1, 0), "v": (z[:-1, :], z[1:, :], 0, 1),
                 "d03": (z[:-1, :-1], z[1:, 1:], 1, 1), "d12": (z[:-1, 1:], z[1:, :-1], 1, 1)}
        out = {}
        with np.errstate(invalid="ignore"):
            for key, (a, b, dc, dr) in pairs.items():
                ok = np.isfinite(a) & np.isfinite(b)
                if jump is not None:
                    lateral = math.hypot(dc * sx, dr * sy)
                    if self.kind == "depth":
                        lateral = lateral * np.abs(a + b) / 2
                    ok &= np.abs(a - b) <= jump * lateral
                out[key] = ok
        return out


def _check_cell(cell: Any, where: str = "") -> tuple[float, float]:
    """``(dx, dy)`` from a cell size (one number or two), both finite and positive."""
    if cell is None:
        raise ScanError(f"{where}the cell size is unknown (pass cell=metres)")
    try:
        c = np.broadcast_to(np.asarray(cell, dtype=np.float64).ravel(), (2,))
    except (TypeError, ValueError):
        raise ConfigError(f"cell must be one or two numbers, got {cell!r}") from None
    if not (np.isfinite(c).all() and (c > 0).all()):
        raise ConfigError(f"cell sizes must be finite and positive, got {cell!r}")
    return float(c[0]), float(c[1])


def _block_faces(vid: np.ndarray, ok: dict[str, np.ndarray], points: np.ndarray) -> np.ndarray:
    """Triangles of the 2x2 blocks of a grid of vertex ids (see :meth:`RangeGrid.to_scan`)."""
    if vid.shape[0] < 2 or vid.shape[1] < 2 or len(points) == 0:
        return np.empty((0, 3), dtype=np.int64)
    v = (vid[:-1, :-1].ravel(), vid[:-1, 1:].ravel(), vid[1:, :-1].ravel(), vid[1:, 1:].ravel())
    top, bottom = ok["h"][:-1].ravel(), ok["h"][1:].ravel()
    left, right = ok["v"][:, :-1].ravel(), ok["v"][:, 1:].ravel()
    d03, d12 = ok["d03"].ravel(), ok["d12"].ravel()
    # corners 0 (r, c), 1 (r, c+1), 2 (r+1, c), 3 (r+1, c+1); CCW in (x, y) = (c, -r)
    tris = {  # the triangle without corner k: (corners, its three edges)
        0: ((1, 2, 3), d12 & bottom & right), 1: ((0, 2, 3), left & bottom & d03),
        2: ((0, 3, 1), d03 & right & top), 3: ((0, 2, 1), left & d12 & top),
    }
    split_a, split_b = (1, 2), (0, 3)  # diagonal 0-3, diagonal 1-2
    n_a = tris[1][1].astype(np.int8) + tris[2][1]
    n_b = tris[0][1].astype(np.int8) + tris[3][1]
    with np.errstate(invalid="ignore"):
        p = [points[np.maximum(c, 0)] for c in v]
        l03 = np.where(d03, np.sum((p[0] - p[3]) ** 2, axis=1), np.inf)
        l12 = np.where(d12, np.sum((p[1] - p[2]) ** 2, axis=1), np.inf)
    use_a = (n_a > n_b) | ((n_a == n_b) & (l03 <= l12))
    out = np.empty((len(v[0]), 2, 3), dtype=np.int64)
    keep = np.zeros((len(v[0]), 2), dtype=bool)
    for slot, (ka, kb) in enumerate(zip(split_a, split_b, strict=True)):
        for k, sel in ((ka, use_a), (kb, ~use_a)):
            corners, good = tris[k]
            s = sel & good
            out[s, slot] = np.column_stack([v[c][s] for c in corners])
            keep[s, slot] = True
    return out[keep]


# --------------------------------------------------------------------------- readers


def _open_error(path: Path, exc: Exception) -> ScanError:
    text = " ".join(str(exc).split()) or type(exc).__name__
    return ScanError(f"{path}: cannot read the image ({text[:200]})")


def _check_exists(path: Path) -> None:
    if not path.is_file():
        raise ScanError(f"{path}: no such file")


def _finish(path: Path, z: np.ndarray) -> None:
    if not np.isfinite(z).any():
        raise ScanError(f"{path}: no cell holds a measurement (all no-data)")


def _read_png(path: Path) -> np.ndarray:
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(path) as im:
            mode, bands = im.mode, len(im.getbands())
            _check_size(path, im.size, 1, True)
            arr = np.array(im) if mode in ("L", "I", "I;16", "I;16B", "I;16L", "F") else None
    except (OSError, UnidentifiedImageError, ValueError) as exc:
        raise _open_error(path, exc) from None
    if arr is None:
        raise ScanError(f"{path}: a depth image must have one channel of numbers, got mode "
                        f"{mode} ({bands} channel{'s' if bands > 1 else ''})")
    if mode == "I" and arr.size and arr.min() >= 0 and arr.max() <= 65535:
        arr = arr.astype(np.uint16)  # Pillow opens some 16-bit PNGs as 32-bit "I"
    return arr


#: Most cells a range image may hold (a 40,000 x 25,000 tile): a corrupt header claiming
#: billions of pixels is refused instead of allocating them.
MAX_CELLS = 1_000_000_000


def _check_size(path: Path, shape: tuple[int, ...], itemsize: int, compressed: bool) -> None:
    """Refuse an image whose header claims more cells than a file of its size can hold."""
    cells = int(np.prod(shape, dtype=np.float64)) if len(shape) else 0
    if cells > MAX_CELLS:
        raise ScanError(f"{path}: the image claims {cells:,} cells (shape {tuple(shape)}), "
                        f"more than {MAX_CELLS:,}: a corrupt header?")
    size = path.stat().st_size
    if not compressed and cells * itemsize > size:
        raise ScanError(f"{path}: truncated: {cells:,} cells of {itemsize} bytes in a file "
                        f"of {size:,} bytes")


def _tiff_page(path: Path) -> tuple[np.ndarray, dict[int, Any], bool]:
    """Read a TIFF's first page: array, tags ``{code: (dtype, count, value)}``, compressed.

    Pixels compressed with a codec only :mod:`imagecodecs` decodes (LZW, PackBits, ...)
    are decoded by Pillow instead when that package is missing.
    """
    import tifffile

    arr = None
    try:
        with tifffile.TiffFile(path) as tif:
            page = tif.pages.first
            tags = {t.code: (int(t.dtype), t.count, t.value) for t in page.tags.values()}
            compressed = int(page.compression) != 1
            dtype, shape = page.dtype, page.shape
            _check_size(path, shape, np.dtype(dtype).itemsize, compressed)
            try:
                arr = page.asarray()
            except ValueError as exc:
                if "imagecodecs" not in str(exc):
                    raise
                codec = str(exc)
    except (OSError, ValueError, tifffile.TiffFileError, KeyError, IndexError) as exc:
        raise _open_error(path, exc) from None
    if arr is None:
        arr = _tiff_by_pillow(path, dtype, shape, codec)
    arr = np.asarray(arr)
    if arr.ndim != 2:
        raise ScanError(f"{path}: a range grid must have one channel, got an image of "
                        f"shape {arr.shape}")
    return arr, tags, compressed


def _tiff_by_pillow(path: Path, dtype: Any, shape: tuple[int, ...], codec: str) -> np.ndarray:
    """Decode a TIFF's pixels with Pillow (when tifffile lacks the codec)."""
    from PIL import Image

    try:
        with Image.open(path) as im:
            arr = np.array(im)
    except (OSError, ValueError) as exc:
        raise ScanError(f"{path}: cannot decode the pixels ({' '.join(codec.split())}; "
                        f"Pillow: {' '.join(str(exc).split())[:100]})") from None
    out = arr.astype(dtype)
    if arr.shape != tuple(shape) or not np.array_equal(out, arr, equal_nan=True):
        raise ScanError(f"{path}: cannot decode the pixels ({' '.join(codec.split())})")
    return out


def sniff_range_kind(path: str | os.PathLike) -> str:
    """Tell which reader a gridded range file needs: ``"depth"``, ``"geotiff"`` or ``"grid"``.

    PNG files are depth images; a TIFF is a GeoTIFF when it carries a ModelPixelScale,
    ModelTiepoint, ModelTransformation or GeoKeyDirectory tag, else a depth image;
    ``.npy`` and ``.npz`` files are elevation arrays.

    Raises
    ------
    ScanError
        If the file is missing or of another format.
    """
    p = Path(path)
    _check_exists(p)
    suffix = p.suffix.lower()
    if suffix == ".png":
        return "depth"
    if suffix in (".npy", ".npz"):
        return "grid"
    if suffix in _TIFF:
        import tifffile

        try:
            with tifffile.TiffFile(p) as tif:
                codes = {t.code for t in tif.pages.first.tags.values()}
        except (OSError, ValueError, tifffile.TiffFileError) as exc:
            raise _open_error(p, exc) from None
        return "geotiff" if codes & {33550, 33922, 34264, 34735} else "depth"
    raise ScanError(f"{p}: not a range grid file (expected .png, .tif, .tiff, .npy, .npz)")


def read_depth_image(path: str | os.PathLike, depth_scale: float | None = None,
                     invalid: float | tuple[float, ...] | None = 0,
                     intrinsics: tuple[float, float, float, float] | None = None) -> RangeGrid:
    """Read a depth image: 8/16-bit PNG, integer or float TIFF.

    Parameters
    ----------
    path : str or os.PathLike
        The image (``.png``, ``.tif``, ``.tiff``), one channel.
    depth_scale : float, optional
        Stored units per metre (5000 for TUM RGB-D, 1000 for RealSense/Kinect v2).
        Required for integer images; a float TIFF without it holds metres.
    invalid : float or sequence of float or None
        Stored value(s) meaning "no measurement" (default 0); non-finite values are
        always no measurement.
    intrinsics : (fx, fy, cx, cy), optional
        Pinhole intrinsics (pixels) for metric world points.

    Returns
    -------
    RangeGrid
        ``kind="depth"``, ``z`` = depth in metres.

    Raises
    ------
    ScanError
        If the file is unreadable, not one channel, integer without ``depth_scale``, has
        negative depths or no valid pixel.
    """
    p = Path(path)
    _check_exists(p)
    suffix = p.suffix.lower()
    if suffix == ".png":
        raw, fmt, compressed = _read_png(p), "png", False
    elif suffix in _TIFF:
        raw, _, compressed = _tiff_page(p)
        fmt = "tiff"
    else:
        raise ScanError(f"{p}: not a depth image (expected .png, .tif or .tiff)")
    if raw.dtype.kind == "b" or raw.dtype.kind not in "iuf":
        raise ScanError(f"{p}: depth samples must be numbers, got dtype {raw.dtype}")
    if depth_scale is None and raw.dtype.kind in "iu":
        raise ScanError(f"{p}: {raw.dtype.itemsize * 8}-bit integer depth image needs "
                        "depth_scale (units per metre, e.g. 5000 TUM, 1000 RealSense)")
    if depth_scale is not None and not (isinstance(depth_scale, (int, float, np.number))
                                        and 0 < depth_scale < math.inf):
        raise ConfigError(f"depth_scale must be a positive number, got {depth_scale!r}")
    bad = _invalid_values(invalid)
    z = raw.astype(np.float64)
    z[np.isin(raw, bad) | ~np.isfinite(z)] = np.nan
    if depth_scale is not None:
        z /= float(depth_scale)
    _finish(p, z)
    n_neg = int(np.sum(z < 0))
    if n_neg:
        raise ScanError(f"{p}: {n_neg} pixels hold negative depths (pass invalid=... "
                        "for a no-data value)")
    nodata = float(bad[0]) if len(bad) else None
    return RangeGrid(z, "depth", intrinsics=intrinsics, source=str(p), fmt=fmt,
                     dtype=raw.dtype.name, scale=None if depth_scale is None
                     else float(depth_scale), nodata=nodata, compressed=compressed)


def _invalid_values(invalid: Any) -> np.ndarray:
    if invalid is None:
        return np.empty(0)
    try:
        out = np.atleast_1d(np.asarray(invalid, dtype=np.float64)).ravel()
    except (TypeError, ValueError):
        raise ConfigError(f"invalid must be a number or numbers, got {invalid!r}") from None
    return out


def _geokeys(path: Path, tags: dict[int, Any]) -> dict[int, int]:
    """Return the GeoKeyDirectory's keys held in the tag itself: ``{key id: short value}``."""
    if 34735 not in tags:
        return {}
    d = np.asarray(tags[34735][2], dtype=np.int64).ravel()
    if len(d) < 4 or len(d) < 4 + 4 * int(d[3]):
        raise ScanError(f"{path}: malformed GeoKeyDirectory tag ({len(d)} values)")
    keys = d[4: 4 + 4 * int(d[3])].reshape(-1, 4)
    return {int(k): int(val) for k, loc, _, val in keys if loc == 0}


def degree_lengths(lat: float) -> tuple[float, float]:
    """Metres per degree of longitude and of latitude at latitude ``lat`` (WGS84)."""
    phi = math.radians(lat)
    lon = 111412.84 * math.cos(phi) - 93.5 * math.cos(3 * phi) + 0.118 * math.cos(5 * phi)
    lat_m = 111132.954 - 559.822 * math.cos(2 * phi) + 1.175 * math.cos(4 * phi)
    return lon, lat_m


def _georef(cols: int, rows: int, x0: float, y0: float, dx: float, dy: float,
            geographic: bool) -> tuple[tuple[float, float], tuple[float, float]]:
    """Cell size and origin in metres from a north-up grid's pixel (0, 0) centre and steps."""
    if not geographic:
        return (dx, dy), (x0, y0)
    m_lon, m_lat = degree_lengths(y0 - (rows - 1) * dy / 2)
    return (dx * m_lon, dy * m_lat), (x0 * m_lon, y0 * m_lat)


def read_geotiff(path: str | os.PathLike) -> RangeGrid:
    """Read a north-up GeoTIFF elevation tile.

    The georeferencing comes from ModelPixelScaleTag + ModelTiepointTag (or a
    ModelTransformationTag without rotation), the GeoKeyDirectory (geographic degrees
    or projected, metres or feet; PixelIsArea or PixelIsPoint) and GDAL_NODATA.

    Returns
    -------
    RangeGrid
        ``kind="elevation"`` with the cell size and origin in metres and the tags to
        copy on writing.

    Raises
    ------
    ScanError
        If the file is unreadable, not georeferenced, rotated or south-up, in an unknown
        linear unit, or holds no valid cell.
    """
    p = Path(path)
    _check_exists(p)
    raw, tags, compressed = _tiff_page(p)
    if raw.dtype.kind not in "iuf":
        raise ScanError(f"{p}: elevation samples must be numbers, got dtype {raw.dtype}")
    keys = _geokeys(p, tags)
    model = keys.get(1024)
    if model == 3:
        raise ScanError(f"{p}: geocentric GeoTIFF grids are not supported")
    geographic = model == 2
    if 34264 in tags:
        m = np.asarray(tags[34264][2], dtype=np.float64).ravel()
        if len(m) != 16:
            raise ScanError(f"{p}: malformed ModelTransformationTag ({len(m)} values)")
        if m[1] != 0 or m[4] != 0:
            raise ScanError(f"{p}: rotated GeoTIFF grids are not supported")
        sx, sy, tie = m[0], -m[5], (0.0, 0.0, m[3], m[7])
    elif 33550 in tags and 33922 in tags:
        scale = np.asarray(tags[33550][2], dtype=np.float64).ravel()
        tp = np.asarray(tags[33922][2], dtype=np.float64).ravel()
        if len(scale) < 2 or len(tp) < 6:
            raise ScanError(f"{p}: malformed ModelPixelScale/ModelTiepoint tags")
        if len(tp) > 6:
            raise ScanError(f"{p}: GeoTIFF grids with several tiepoints are not supported")
        sx, sy, tie = scale[0], scale[1], (tp[0], tp[1], tp[3], tp[4])
    else:
        raise ScanError(f"{p}: no georeferencing (no ModelPixelScale + ModelTiepoint or "
                        "ModelTransformation tag)")
    if not (sx > 0 and math.isfinite(sx)) or not math.isfinite(sy) or sy == 0:
        raise ScanError(f"{p}: bad pixel scale ({sx}, {sy})")
    if sy < 0:
        raise ScanError(f"{p}: south-up GeoTIFF grids are not supported (north-up only)")
    unit = 1.0
    if not geographic and 3076 in keys:
        if keys[3076] not in _LINEAR_UNITS:
            raise ScanError(f"{p}: linear unit code {keys[3076]} is not supported "
                            "(metre, foot, US survey foot)")
        unit = _LINEAR_UNITS[keys[3076]]
    half = 0.0 if keys.get(1025) == 2 else 0.5  # PixelIsPoint: tiepoint at a pixel centre
    x0 = tie[2] + (half - tie[0]) * sx
    y0 = tie[3] - (half - tie[1]) * sy
    cell, origin = _georef(raw.shape[1], raw.shape[0], x0, y0, sx, sy, geographic)
    cell = (cell[0] * unit, cell[1] * unit)
    origin = (origin[0] * unit, origin[1] * unit)
    nodata = None
    if 42113 in tags:
        text = str(tags[42113][2]).strip("\x00 ")
        try:
            nodata = float(text)
        except ValueError:
            raise ScanError(f"{p}: bad GDAL_NODATA value {text!r}") from None
    z = raw.astype(np.float64)
    if nodata is not None and not math.isnan(nodata):
        z[raw == nodata] = np.nan
    _finish(p, z)
    copy = tuple((code, *tags[code]) for code in sorted(_GEO_TAGS) if code in tags)
    return RangeGrid(z, "elevation", cell=cell, origin=origin, source=str(p), fmt="geotiff",
                     dtype=raw.dtype.name, nodata=nodata,
                     crs="geographic" if geographic else "projected", tags=copy,
                     compressed=compressed)


def read_grid_array(path: str | os.PathLike,
                    cell: float | tuple[float, float] | None = None) -> RangeGrid:
    """Read an elevation array from ``.npy`` or ``.npz``.

    A ``.npy`` file is one 2-D array (``NaN`` = no data); ``cell`` is required. A
    ``.npz`` file holds ``elevation`` (or ``z``, or its only array) and optionally
    ``cell`` (metres, one or two numbers), ``origin`` (x, y of cell (0, 0)'s centre) and
    ``nodata``; or the layout of matplotlib's ``jacksboro_fault_dem.npz``: ``dx``, ``dy``
    and the bounds ``xmin``, ``xmax``, ``ymin``, ``ymax`` of the cell edges, in degrees
    when they lie within longitude/latitude range (that file labels its north edge
    ``ymin``: the larger latitude is taken as row 0, the north).

    Raises
    ------
    ScanError
        If the file is unreadable, the array not 2-D real numbers, the cell size
        unknown, or no cell valid.
    """
    p = Path(path)
    _check_exists(p)
    suffix = p.suffix.lower()
    try:
        data = np.load(p, allow_pickle=False)
    except (OSError, ValueError, EOFError) as exc:
        raise ScanError(f"{p}: cannot read the array ({' '.join(str(exc).split())[:200]})"
                        ) from None
    origin: tuple[float, float] = (0.0, 0.0)
    crs = nodata = None
    extra: tuple = ()
    if suffix == ".npz" or isinstance(data, np.lib.npyio.NpzFile):
        with data:
            members = {k: data[k] for k in data.files}
        key = next((k for k in ("elevation", "z") if k in members), None)
        if key is None:
            arrays = [k for k, a in members.items() if a.ndim == 2]
            if len(arrays) != 1:
                raise ScanError(f"{p}: no 'elevation' array among {sorted(members)}")
            key = arrays[0]
        raw = members[key]
        _check_2d(p, raw)
        if "nodata" in members:
            nodata = float(members["nodata"])
        if cell is None and "cell" in members:
            cell = tuple(np.asarray(members["cell"], dtype=np.float64).ravel())
        if "origin" in members:
            origin = tuple(np.asarray(members["origin"], dtype=np.float64).ravel()[:2])
        elif {"dx", "dy", "xmin", "xmax", "ymin", "ymax"} <= set(members) and cell is None:
            b = {k: float(members[k]) for k in ("dx", "dy", "xmin", "xmax", "ymin", "ymax")}
            west, north = min(b["xmin"], b["xmax"]), max(b["ymin"], b["ymax"])
            geographic = max(abs(b["xmin"]), abs(b["xmax"])) <= 180 and north <= 90 and \
                min(b["ymin"], b["ymax"]) >= -90
            cell, origin = _georef(raw.shape[1], raw.shape[0], west + b["dx"] / 2,
                                   north - b["dy"] / 2, b["dx"], b["dy"], geographic)
            crs = "geographic" if geographic else "projected"
        extra = tuple((k, a) for k, a in members.items() if k != key)
        fmt = "npz"
    else:
        raw = data
        _check_2d(p, raw)
        fmt = "npy"
    if cell is None:
        raise ScanError(f"{p}: the cell size is unknown (pass cell=metres)")
    z = raw.astype(np.float64)
    if nodata is not None and not math.isnan(nodata):
        z[raw == nodata] = np.nan
    _finish(p, z)
    return RangeGrid(z, "elevation", cell=_check_cell(cell, f"{p}: "), origin=origin,
                     source=str(p), fmt=fmt, dtype=raw.dtype.name, nodata=nodata, crs=crs,
                     extra=extra, key=key if fmt == "npz" else None)


def _check_2d(path: Path, raw: np.ndarray) -> None:
    if raw.dtype.kind not in "iuf":
        raise ScanError(f"{path}: elevation must be real numbers, got dtype {raw.dtype}")
    if raw.ndim != 2 or min(raw.shape) < 1:
        raise ScanError(f"{path}: elevation must be a 2-D array, got shape {raw.shape}")


def read_range(path: str | os.PathLike, **kwargs: Any) -> RangeGrid:
    """Read any gridded range file, choosing the reader by :func:`sniff_range_kind`.

    Keyword arguments go to that reader (``depth_scale``, ``invalid``, ``intrinsics``
    for depth images, ``cell`` for arrays).
    """
    kind = sniff_range_kind(path)
    if kind == "geotiff":
        return read_geotiff(path, **kwargs)
    if kind == "grid":
        return read_grid_array(path, **kwargs)
    return read_depth_image(path, **kwargs)
