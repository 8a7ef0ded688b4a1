"""Errors of the inter-process transport."""

from __future__ import annotations

__all__ = ["RemoteServiceError", "RouterError", "TransportError"]


class TransportError(Exception):
    """Base class of transport errors."""


class RouterError(TransportError):
    """The Zenoh router could not be reached or started."""


class RemoteServiceError(TransportError):
    """A remote service answered with an error (its callback raised)."""
