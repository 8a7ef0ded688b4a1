"""The one failure of the bag package: a bag that cannot be opened, written or played."""

from __future__ import annotations

__all__ = ["BagError"]


class BagError(Exception):
    """A bag that cannot be opened, written or played at all."""
