"""Range data as scans: depth images, elevation grids and LiDAR behind :func:`load_scan`.

:func:`~asrbf_mesh._io.load_scan` hands these files here:

- depth images (16-bit PNG, 16-bit or float TIFF) and elevation grids (GeoTIFF, ``.npz``,
  and ``.npy`` with a cell size) are read as a :class:`~asrbf_mesh._range.RangeGrid`
  and triangulated by pixel adjacency, cut at depth jumps
  (:meth:`~asrbf_mesh._range.RangeGrid.to_scan`);
- LAS/LAZ point clouds (the ``lidar`` extra) are read with their class and return
  filters (:func:`~asrbf_mesh._lidar.read_las`) as a point cloud.

:class:`RangeOptions` carries what those formats need and the others do not: the depth
scale, the "no measurement" value, pinhole intrinsics, the cell size of a bare array,
the LiDAR classes and returns. :func:`load_range` also returns the grid or the LAS
header, which the commands need to write their output in kind.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ._mesh import Scan
from ._validate import one_line, quiet_logger
from .errors import AsrbfError, ConfigError, ScanError

__all__ = ["GRID_SUFFIXES", "LIDAR_SUFFIXES", "RangeOptions", "is_range_path", "load_range"]

#: Gridded range files (``.npy`` only with a cell size: otherwise an (N, 3) point array).
GRID_SUFFIXES = (".png", ".tif", ".tiff", ".npz")
#: LiDAR point clouds.
LIDAR_SUFFIXES = (".las", ".laz")


@dataclass(frozen=True)
class RangeOptions:
    """How to read range data (every field optional; see ``asrbf fit --help``).

    Attributes
    ----------
    depth_scale : float, optional
        Depth image units per metre (5000 for the TUM RGB-D benchmark, 1000 for most
        RealSense devices); required for integer images.
    invalid : tuple of float, optional
        Depth values meaning "no measurement" (default 0).
    intrinsics : (fx, fy, cx, cy), optional
        Pinhole intrinsics in pixels: the scan is then in metric camera coordinates;
        otherwise x, y are pixel columns and rows and z the depth in metres.
    cell : float, optional
        Cell size of a bare ``.npy``/``.npz`` elevation array (metres).
    classes : tuple of int, optional
        LAS classification codes to keep (2 = ground).
    returns : str or tuple of int, optional
        LAS returns to keep: ``"first"``, ``"last"``, ``"single"`` or return numbers.
    """

    depth_scale: float | None = None
    invalid: tuple[float, ...] | None = None
    intrinsics: tuple[float, float, float, float] | None = None
    cell: float | None = None
    classes: tuple[int, ...] | None = None
    returns: str | tuple[int, ...] | None = None

    @classmethod
    def of(cls, value: RangeOptions | dict[str, Any] | None) -> RangeOptions:
        """Return a RangeOptions from itself, a dict of its fields (None: dropped) or None."""
        if value is None:
            return cls()
        if isinstance(value, cls):
            return value
        if not isinstance(value, dict):
            raise ConfigError(f"range options must be a dict, got {type(value).__name__}")
        unknown = set(value) - set(cls.__dataclass_fields__)
        if unknown:
            raise ConfigError(f"unknown range option(s): {', '.join(sorted(unknown))}")
        return cls(**{k: v for k, v in value.items() if v is not None})

    def grid_kwargs(self, kind: str) -> dict[str, Any]:
        """Keyword arguments of the reader of ``kind`` (``depth``, ``geotiff``, ``grid``)."""
        if kind == "depth":
            kw: dict[str, Any] = {"depth_scale": self.depth_scale,
                                  "intrinsics": self.intrinsics}
            if self.invalid is not None:
                kw["invalid"] = self.invalid
            return kw
        if kind == "grid":
            return {"cell": self.cell}
        return {}


def is_range_path(path: str | os.PathLike, options: RangeOptions | None = None) -> str | None:
    """``"grid"``, ``"lidar"`` or None (another scan format) for a scan path."""
    suffix = Path(path).suffix.lower()
    if suffix in LIDAR_SUFFIXES:
        return "lidar"
    if suffix in GRID_SUFFIXES or (suffix == ".npy" and options is not None
                                   and options.cell is not None):
        return "grid"
    return None


def load_range(path: str | os.PathLike, options: RangeOptions | None = None, *,
               scan: bool = True) -> tuple[Scan | None, Any]:
    """Read a range file as a scan; also the grid (RangeGrid) or the LAS header (LasMeta).

    ``scan=False`` skips triangulating a grid (the grid fill needs only the grid): the
    scan is then None for a grid.

    Raises
    ------
    ScanError
        One line naming the file: unreadable, an image that is not single-channel, an
        integer image without ``depth_scale``, a rotated GeoTIFF, a LAS without the
        requested class, a LAZ without lazrs, ...
    """
    options = options or RangeOptions()
    try:
        with quiet_logger("tifffile"):
            if is_range_path(path, options) == "lidar":
                from ._lidar import read_las

                return read_las(path, classes=options.classes, returns=options.returns)
            from ._range import read_range, sniff_range_kind

            grid = read_range(path, **options.grid_kwargs(sniff_range_kind(path)))
            return (grid.to_scan() if scan else None), grid
    except (AsrbfError, MemoryError):
        raise
    except Exception as exc:  # parser boundary: a corrupt file never leaks a traceback
        name = os.fsdecode(path)
        raise ScanError(f"{name}: cannot read {Path(name).suffix.lstrip('.').upper()}: "
                        f"{one_line(exc)}") from None
