"""Typed failures (and the one warning) of the map io package."""

from __future__ import annotations

__all__ = ["LegacyMapWarning", "MapError", "MapFormatError", "MapWriteError"]


class MapError(Exception):
    """Base class of every map io failure."""


class MapFormatError(MapError, ValueError):
    """A map YAML or image is missing, unreadable or has an invalid key.

    The message names the file and, where one is at fault, the key.
    """


class MapWriteError(MapError, OSError):
    """A map could not be written; any previous map at the target path is intact."""


class LegacyMapWarning(UserWarning):
    """A map file written by an older eddiebot (``free_thresh`` 0.25: unknown cells would
    read as free) was loaded with its unknown cells kept unknown; saving it again fixes it."""
