"""Errors of the message layer."""

from __future__ import annotations


class MessageError(Exception):
    """Base class of message-layer errors."""


class UnknownTypeError(MessageError, KeyError):
    """A message, service or action type that is not registered and that no interface file
    found on the search path describes (``detail`` says where it looked)."""

    def __init__(self, name: str, kind: str, detail: str = "") -> None:
        text = f"unknown {kind} type {name!r}"
        super().__init__(f"{text}: {detail}" if detail else text)
        self.name = name
        self.kind = kind
        self.detail = detail

    def __str__(self) -> str:
        return str(self.args[0])
