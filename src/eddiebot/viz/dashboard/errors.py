"""Typed failures of the dashboard."""

from __future__ import annotations

__all__ = ["CommandError", "DashboardBindError", "DashboardError", "RateLimitedError"]


class DashboardError(Exception):
    """Base class of dashboard failures."""


class CommandError(DashboardError):
    """A browser command that is malformed, out of range or not allowed; the text goes back
    to the browser (``op`` names the command when it is known)."""

    def __init__(self, message: str, op: str | None = None) -> None:
        super().__init__(message)
        self.op = op


class RateLimitedError(CommandError):
    """A command arrived faster than its rate limit allows."""


class DashboardBindError(DashboardError, OSError):
    """The dashboard cannot listen on its address (the port is taken, or the address is
    not this machine's); the message names host and port."""
