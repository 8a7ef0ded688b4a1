"""Errors of the message layer."""

from __future__ import annotations


class MessageError(Exception):
    """Base class of message-layer errors."""


class UnknownTypeError(MessageError, KeyError):
    """A message, service or action type that is not registered."""

    def __init__(self, name: str, kind: str) -> None:
        super().__init__(f"unknown {kind} type {name!r}")
        self.name = name
        self.kind = kind

    def __str__(self) -> str:
        return str(self.args[0])
