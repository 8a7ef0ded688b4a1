"""Typed failures of the perception cores."""

from __future__ import annotations


class PerceptionError(Exception):
    """Base class of every perception failure."""


class UnsupportedEncodingError(PerceptionError, ValueError):
    """An image encoding the conversion cannot read (names the encoding and the accepted ones)."""


class ImageSizeError(PerceptionError, ValueError):
    """An image whose size disagrees with its CameraInfo or with its own data buffer."""


class ScanHeightError(PerceptionError, ValueError):
    """``scan_height`` asks for more rows than fit around the principal point."""
