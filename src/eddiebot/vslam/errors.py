"""Typed failures of the RGB-D SLAM package."""

from __future__ import annotations

__all__ = [
    "DatabaseCorruptError",
    "DatabaseError",
    "DatabaseLockedError",
    "DatabaseVersionError",
    "DepthScaleError",
    "ParameterError",
    "TumFormatError",
    "VslamError",
]


class VslamError(Exception):
    """Base class of every failure raised by `eddiebot.vslam`."""


class ParameterError(VslamError, ValueError):
    """An RTAB-Map parameter has an unknown name, a bad value or an unsupported choice."""


class DatabaseError(VslamError):
    """The session database cannot be opened or written."""


class DatabaseCorruptError(DatabaseError):
    """The file is not a readable eddiebot session database (bad header or failed integrity check)."""


class DatabaseLockedError(DatabaseError):
    """Another process holds the session database open."""


class DatabaseVersionError(DatabaseError):
    """The database was written by a newer schema version than this code understands."""


class TumFormatError(VslamError, ValueError):
    """A TUM RGB-D folder or file is missing or malformed."""


class DepthScaleError(VslamError, ValueError):
    """Depth read with a units-per-metre scale that puts the scene at an implausible distance."""
