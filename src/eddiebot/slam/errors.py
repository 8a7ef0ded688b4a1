"""Typed failures of the 2D SLAM package."""

from __future__ import annotations

__all__ = [
    "CarmenFormatError",
    "ConfigError",
    "GraphEditError",
    "MergeError",
    "PoseGraphFormatError",
    "SessionError",
    "SessionVersionError",
    "SlamError",
]


class SlamError(Exception):
    """Base class of every SLAM failure."""


class ConfigError(SlamError, ValueError):
    """A SLAM parameter is unknown or invalid; the message names the file and key."""


class CarmenFormatError(SlamError, ValueError):
    """A CARMEN log line cannot be parsed; the message names the file and line number."""


class GraphEditError(SlamError, ValueError):
    """An interactive edit of the graph is refused (unknown node, not in interactive mode);
    the message names the node or the reason."""


class MergeError(SlamError, ValueError):
    """A second session cannot be merged (unreadable, another laser mount, not placed)."""


class PoseGraphFormatError(SlamError, ValueError):
    """A g2o or TORO file cannot be parsed; the message names the file and line number."""


class SessionError(SlamError, ValueError):
    """A saved SLAM session is missing, corrupt or cannot be written."""


class SessionVersionError(SessionError):
    """A saved SLAM session was written by an incompatible format version."""
