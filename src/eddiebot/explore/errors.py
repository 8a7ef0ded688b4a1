"""Typed exploration failures."""

from __future__ import annotations

__all__ = ["ExploreConfigError", "ExploreError", "NoWorldError"]


class ExploreError(Exception):
    """Base class of every exploration failure."""


class ExploreConfigError(ExploreError, ValueError):
    """A parameter value that cannot be explored with; the message names it."""


class NoWorldError(ExploreError):
    """Exploration asked of a running robot, which is not supported yet."""
