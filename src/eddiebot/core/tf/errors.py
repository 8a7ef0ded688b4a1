"""tf2's exception types."""

from __future__ import annotations


class TransformException(Exception):
    """Base class of tf errors (tf2.TransformException)."""


class LookupException(TransformException):
    """A frame that is not in the buffer."""


class ConnectivityException(TransformException):
    """The two frames are in trees that are not connected."""


class ExtrapolationException(TransformException):
    """The requested time is outside the time range cached for an edge of the chain."""


class InvalidArgumentException(TransformException):
    """A malformed frame id, time or transform."""


class TimeoutException(TransformException):
    """No transform became available within the timeout; ``cause`` says why."""

    def __init__(self, message: str, cause: TransformException | None = None) -> None:
        super().__init__(message)
        self.cause = cause
