"""Exception family of asrbf-mesh.

Every error a user can cause derives from :class:`AsrbfError`; the command line
turns them into one line on stderr and exit code 2.
"""

from __future__ import annotations

__all__ = ["AsrbfError", "ConfigError", "FitError", "NetworkFileError", "ScanError"]


class AsrbfError(Exception):
    """Base class of every error asrbf-mesh raises on bad input or bad usage."""


class ScanError(AsrbfError, ValueError):
    """A scan (point cloud or mesh file) is missing, unreadable or unusable."""


class ConfigError(AsrbfError, ValueError):
    """A learning or reconstruction parameter is out of its valid range."""


class FitError(AsrbfError):
    """Sequential learning could not produce a usable network."""


class NetworkFileError(AsrbfError):
    """A ``.asrbf`` network file is missing, corrupt or of another format version."""
