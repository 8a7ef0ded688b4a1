"""Typed failures of the Eddie control-board driver, codec and emulator."""

from __future__ import annotations

__all__ = [
    "BadChecksumError",
    "BoardInterrupted",
    "BoardTimeout",
    "BufferOverflowError",
    "EncoderError",
    "FirmwareError",
    "InvalidCommandError",
    "InvalidParameterError",
    "LinkLost",
    "ParameterRangeError",
    "ProtocolError",
    "ReplyFormatError",
    "RobotError",
    "TooFewParametersError",
    "TooManyParametersError",
    "UnsupportedCommandError",
    "firmware_error_for_reply",
]


class RobotError(Exception):
    """Base class of every error of ``eddiebot.robot``."""


class ProtocolError(RobotError):
    """A command could not be encoded or a reply could not be decoded."""


class ParameterRangeError(ProtocolError, ValueError):
    """A command parameter is outside what the firmware accepts; raised before sending."""

    def __init__(self, command: str, parameter: str, value: int, low: int, high: int,
                 firmware: str = "") -> None:
        on = f" on firmware {firmware}" if firmware else ""
        super().__init__(
            f"{command} {parameter}={value} is out of range{on}: allowed {low}..{high} "
            f"(0x{low & 0xFFFFFFFF:X}..0x{high & 0xFFFFFFFF:X})"
        )
        self.command = command
        self.parameter = parameter
        self.value = value
        self.low = low
        self.high = high
        self.firmware = firmware


class UnsupportedCommandError(ProtocolError):
    """The command does not exist on the connected firmware (e.g. ``WATCH`` on 1.1)."""

    def __init__(self, command: str, firmware: str) -> None:
        super().__init__(f"{command} is not supported by firmware {firmware}")
        self.command = command
        self.firmware = firmware


class ReplyFormatError(ProtocolError):
    """A reply does not have the form the command produces (garbled or mis-framed)."""

    def __init__(self, command: str, reply: str, expected: str = "") -> None:
        detail = f", expected {expected}" if expected else ""
        super().__init__(f"malformed reply to {command}: {reply!r}{detail}")
        self.command = command
        self.reply = reply
        self.expected = expected


class FirmwareError(RobotError):
    """The board answered ``ERROR``.  Subclasses name the VERB 1 reason."""

    reason: str = ""

    def __init__(self, command: str = "", reply: str = "ERROR") -> None:
        what = f"{command}: " if command else ""
        super().__init__(f"{what}board answered {reply!r}")
        self.command = command
        self.reply = reply


class InvalidCommandError(FirmwareError):
    """``ERROR - Invalid command``."""

    reason = "Invalid command"


class InvalidParameterError(FirmwareError):
    """``ERROR - Invalid parameter`` (not hex, more than 8 digits, or out of range)."""

    reason = "Invalid parameter"


class TooFewParametersError(FirmwareError):
    """``ERROR - Too few parameters``."""

    reason = "Too few parameters"


class TooManyParametersError(FirmwareError):
    """``ERROR - Too many parameters``."""

    reason = "Too many parameters"


class BufferOverflowError(FirmwareError):
    """``ERROR - Overflow``: the line exceeded the firmware's input buffer."""

    reason = "Overflow"


class BadChecksumError(FirmwareError):
    """``ERROR - Bad checksum`` (checksum mode only)."""

    reason = "Bad checksum"


class EncoderError(FirmwareError):
    """``ERROR - Encoder error``: the board's position-control loop is not running."""

    reason = "Encoder error"


_BY_REASON: dict[str, type[FirmwareError]] = {
    cls.reason: cls
    for cls in (InvalidCommandError, InvalidParameterError, TooFewParametersError,
                TooManyParametersError, BufferOverflowError, BadChecksumError, EncoderError)
}


def firmware_error_for_reply(command: str, reply: str) -> FirmwareError:
    """The typed error for an ``ERROR[ - reason]`` reply (``FirmwareError`` if no reason)."""
    reason = reply[5:].strip()
    if reason.startswith("-"):
        reason = reason[1:].strip()
    cls = _BY_REASON.get(reason, FirmwareError)
    return cls(command, reply)


class BoardTimeout(RobotError, TimeoutError):
    """No complete reply within the request timeout (measured on the injected clock)."""

    def __init__(self, command: str, timeout_s: float) -> None:
        super().__init__(f"no reply to {command!r} within {timeout_s:.3f} s")
        self.command = command
        self.timeout_s = timeout_s


class BoardInterrupted(RobotError):
    """The request was abandoned before its reply arrived, to make room for a stop."""

    def __init__(self, command: str) -> None:
        super().__init__(f"{command!r} abandoned for an urgent command")
        self.command = command


class LinkLost(RobotError, ConnectionError):
    """The serial port (or other link) is gone; the link may come back later."""
