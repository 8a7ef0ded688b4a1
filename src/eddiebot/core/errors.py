"""Errors of the runtime."""

from __future__ import annotations


class RuntimeErrorBase(Exception):
    """Base class of runtime errors."""


class TopicTypeMismatchError(RuntimeErrorBase, TypeError):
    """A message of one type published or subscribed on a topic that carries another."""

    def __init__(self, topic: str, expected: str, got: str) -> None:
        super().__init__(f"topic {topic!r} carries {expected!r}, not {got!r}")
        self.topic = topic
        self.expected = expected
        self.got = got


class InvalidNameError(RuntimeErrorBase, ValueError):
    """A node, namespace or topic name that ROS 2 would not accept."""


class ServiceUnavailableError(RuntimeErrorBase):
    """No server answers the service."""


class ServiceCallTimeoutError(RuntimeErrorBase, TimeoutError):
    """A service call that got no response in time."""


class ParameterError(RuntimeErrorBase):
    """Base class of parameter errors; ``where`` names the file/line/node/key when known."""

    def __init__(self, message: str, *, where: str = "") -> None:
        super().__init__(f"{where}: {message}" if where else message)
        self.where = where


class ParameterNotDeclaredError(ParameterError, AttributeError):
    """Access to or an override of a parameter that the node did not declare."""


class ParameterAlreadyDeclaredError(ParameterError):
    """A parameter declared twice."""


class InvalidParameterTypeError(ParameterError, TypeError):
    """A value whose type differs from the declared parameter type."""


class InvalidParameterValueError(ParameterError, ValueError):
    """A value an on-set callback or a range rejected."""


class ParameterFileError(ParameterError):
    """A malformed parameter file."""


class ExecutorShutdownError(RuntimeErrorBase):
    """Work handed to an executor that has shut down."""
