"""Writing a range grid back in kind: same format, size, dtype, scale and georeferencing.

:func:`write_like` writes a modified :class:`~asrbf_mesh._range.RangeGrid` (a filled depth
image, a filled elevation tile) in the format it was read from; :func:`write_mask` the
image of the cells a fill gave a value.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

from ._atomic import atomic_path
from ._range import _TIFF, RangeGrid
from .errors import ConfigError

__all__ = ["write_like", "write_mask"]

_SUFFIXES = {"png": (".png",), "tiff": _TIFF, "geotiff": _TIFF, "npy": (".npy",),
             "npz": (".npz",)}


def _stored(grid: RangeGrid, z: np.ndarray) -> tuple[np.ndarray, float, bool]:
    """``z`` in the source's units and dtype; the no-data value; whether it is new."""
    dtype = np.dtype(grid.dtype)
    vals = z * grid.scale if grid.scale is not None else z.copy()
    missing = ~np.isfinite(vals)
    nodata, new = grid.nodata, False
    if nodata is None:
        new = bool(missing.any())
        if dtype.kind == "f":
            nodata = math.nan
        else:
            nodata = float(np.iinfo(dtype).min if grid.kind == "elevation" else 0)
    if dtype.kind == "f":
        out = vals.astype(dtype)
        out[missing] = nodata
        return out, nodata, new
    info = np.iinfo(dtype)
    rounded = np.clip(np.rint(np.where(missing, 0.0, vals)), info.min, info.max)
    clash = ~missing & (rounded == nodata)  # a measurement that would read as no data
    rounded[clash] += 1 if nodata < info.max else -1
    rounded[missing] = nodata
    return rounded.astype(dtype), nodata, new


def _save_image(tmp: Path, arr: np.ndarray, suffix: str, extratags: list | None = None,
                compress: bool = False) -> None:
    if suffix == ".png":
        from PIL import Image

        Image.fromarray(arr).save(tmp, format="PNG")
    else:
        import tifffile

        tifffile.imwrite(tmp, arr, photometric="minisblack", metadata=None,
                         extratags=extratags or None, compression="zlib" if compress else None)


def write_like(grid: RangeGrid, z_new: np.ndarray, path: str | os.PathLike,
               mask: str | os.PathLike | None = None) -> None:
    """Write ``z_new`` in the format, size, dtype and scale of ``grid``'s source file.

    Values go back to the source units (depth times ``scale``, rounded and clipped for
    integer images); ``NaN`` cells are written as the source's "no measurement" value
    (when it had none: ``NaN`` for floats, 0 for integer depth, the dtype's minimum for
    integer elevation, recorded as GDAL_NODATA or an ``.npz`` ``nodata`` member). A
    GeoTIFF gets the source's georeferencing tags; an ``.npz`` its other members. Both
    files are written atomically.

    Parameters
    ----------
    grid : RangeGrid
        The grid as read (:func:`read_depth_image`, :func:`read_geotiff`,
        :func:`read_grid_array`).
    z_new : (H, W) array of float
        New values, in the units of ``grid.z``.
    path : str or os.PathLike
        Output file, with the source format's extension.
    mask : str or os.PathLike, optional
        Also write a uint8 image (``.png`` or ``.tif``), 255 where a cell had no
        measurement in ``grid`` and has one in ``z_new`` (the filled cells), else 0.

    Raises
    ------
    ConfigError
        If ``z_new`` has another shape or a path the wrong extension.
    AsrbfError
        If the output cannot be written or names the source file.
    """
    from ._atomic import check_output_path

    z = np.asarray(z_new, dtype=np.float64)
    if z.shape != grid.shape:
        raise ConfigError(f"z_new must have the grid's shape {grid.shape}, got {z.shape}")
    out = check_output_path(path, grid.source)
    suffix = out.suffix.lower()
    if suffix not in _SUFFIXES[grid.fmt]:
        raise ConfigError(f"{out}: a {grid.fmt} grid must be written to a "
                          f"{' or '.join(_SUFFIXES[grid.fmt])} file")
    if mask is not None:
        _mask_path(mask, grid)
    arr, nodata, new = _stored(grid, z)
    with atomic_path(out) as tmp:
        if grid.fmt in ("png", "tiff"):
            _save_image(tmp, arr, suffix, compress=grid.compressed)
        elif grid.fmt == "geotiff":
            tags = [(code, dtype, count, value, True) for code, dtype, count, value in grid.tags
                    if not (new and code == 42113)]
            if new and not math.isnan(nodata):
                tags.append((42113, 2, 0, f"{nodata:g}", True))
            _save_image(tmp, arr, suffix, tags, compress=grid.compressed)
        elif grid.fmt == "npy":
            with open(tmp, "wb") as fh:
                np.save(fh, arr)
        else:
            members = dict(grid.extra)
            members[grid.key or "elevation"] = arr
            if new and not math.isnan(nodata) and "nodata" not in members:
                members["nodata"] = np.asarray(nodata)
            with open(tmp, "wb") as fh:
                np.savez(fh, **members)
    if mask is not None:
        write_mask(grid, z, mask)


def _mask_path(mask: str | os.PathLike, grid: RangeGrid) -> Path:
    from ._atomic import check_output_path

    out = check_output_path(mask, grid.source)
    if out.suffix.lower() not in (".png", *_TIFF):
        raise ConfigError(f"{out}: the mask must be a .png or .tif file")
    return out


def write_mask(grid: RangeGrid, z_new: np.ndarray, mask: str | os.PathLike) -> None:
    """Write a uint8 image (``.png``/``.tif``): 255 where ``grid`` had no data and ``z_new`` has."""
    out = _mask_path(mask, grid)
    z = np.asarray(z_new, dtype=np.float64)
    if z.shape != grid.shape:
        raise ConfigError(f"z_new must have the grid's shape {grid.shape}, got {z.shape}")
    filled = (np.isnan(grid.z) & np.isfinite(z)).astype(np.uint8) * np.uint8(255)
    with atomic_path(out) as tmp:
        _save_image(tmp, filled, out.suffix.lower())
