"""Codec of the Eddie control board's ASCII command set (firmware 1.1 and 1.3).

Encoders build one command line *without* its terminating CR (the transport adds it); every
numeric parameter is upper-case hex, negative values in two's complement of the
parameter's width.  Ranges are checked per :class:`~eddiebot.robot.constants.FirmwareProfile`
and violations raise :class:`~eddiebot.robot.errors.ParameterRangeError` naming the command,
the parameter and the allowed range — before anything is sent.

Decoders take one reply line *without* its CR.  ``ERROR[ - reason]`` replies become typed
:class:`~eddiebot.robot.errors.FirmwareError` subclasses; replies of the wrong shape raise
:class:`~eddiebot.robot.errors.ReplyFormatError`.

Units are the firmware's: positions (encoder counts), positions per second, positions per
second squared, degrees **clockwise positive** for ``TURN`` and ``HEAD``.  The conversion to
REP-103 happens in :class:`eddiebot.robot.board.Board` only.
"""

from __future__ import annotations

import re
from collections.abc import Callable

from eddiebot.robot.constants import (
    ADC_CHANNELS,
    FIRMWARE_1_1,
    FirmwareProfile,
    adc_counts_to_volts,
    ping_units_to_range_m,
)
from eddiebot.robot.errors import (
    ParameterRangeError,
    ReplyFormatError,
    UnsupportedCommandError,
    firmware_error_for_reply,
)

__all__ = [
    "COMMANDS",
    "adc_counts_to_volts",
    "check_reply",
    "decode_adc",
    "decode_dist",
    "decode_empty",
    "decode_head",
    "decode_mask",
    "decode_ping",
    "decode_spd",
    "decode_word",
    "decoder_for",
    "encode_acc",
    "encode_adc",
    "encode_blink",
    "encode_dist",
    "encode_go",
    "encode_gospd",
    "encode_head",
    "encode_high",
    "encode_highs",
    "encode_hwver",
    "encode_in",
    "encode_ins",
    "encode_low",
    "encode_lows",
    "encode_out",
    "encode_outs",
    "encode_ping",
    "encode_read",
    "encode_rst",
    "encode_sgp",
    "encode_spd",
    "encode_spng",
    "encode_stop",
    "encode_trvl",
    "encode_turn",
    "encode_ver",
    "encode_verb",
    "encode_watch",
    "format_hex",
    "is_error_reply",
    "ping_units_to_range_m",
    "to_signed",
]

COMMANDS: tuple[str, ...] = (
    "HWVER", "VER", "VERB", "WATCH", "BLINK", "IN", "OUT", "LOW", "HIGH", "INS", "OUTS",
    "LOWS", "HIGHS", "READ", "SPNG", "SGP", "PING", "ADC", "GO", "GOSPD", "STOP", "TRVL",
    "TURN", "ACC", "SPD", "HEAD", "DIST", "RST",
)
"""Every command of the command set (CS11, CS12).  FW 1.1 knows BLINK only as ``BLNK``."""

_INT16 = (-0x8000, 0x7FFF)
_UINT16 = (0, 0xFFFF)
_UINT32 = (0, 0xFFFFFFFF)

# --- number formatting --------------------------------------------------------------------


def format_hex(value: int, bits: int) -> str:
    """``value`` as upper-case hex; negative values as ``bits``-wide two's complement.

    Non-negative values are not padded (``30`` → ``"1E"``); ``-1`` with 16 bits → ``"FFFF"``.
    The firmware sign-extends the parameter's width, so both forms decode correctly.
    """
    if value < 0:
        return f"{value & ((1 << bits) - 1):0{bits // 4}X}"
    return f"{value:X}"


def to_signed(value: int, bits: int) -> int:
    """Interpret the low ``bits`` of ``value`` as a two's complement number."""
    value &= (1 << bits) - 1
    return value - (1 << bits) if value & (1 << (bits - 1)) else value


def _check(command: str, parameter: str, value: int, low: int, high: int,
           profile: FirmwareProfile | None = None) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise TypeError(f"{command} {parameter} must be an int, got {type(value).__name__}")
    if not low <= value <= high:
        raise ParameterRangeError(command, parameter, value, low, high,
                                  profile.name if profile else "")
    return value


# --- encoders -----------------------------------------------------------------------------


def encode_hwver() -> str:
    """``HWVER``: query the hardware version (reply: 4 hex digits)."""
    return "HWVER"


def encode_ver() -> str:
    """``VER``: query the firmware version (reply: 4 hex digits)."""
    return "VER"


def encode_verb(verbose: bool | int) -> str:
    """``VERB 0|1``: with 1 the board appends `` - <reason>`` to ``ERROR``."""
    return f"VERB {_check('VERB', 'mode', int(verbose), 0, 1)}"


def encode_watch(enabled: bool | int, profile: FirmwareProfile = FIRMWARE_1_1) -> str:
    """``WATCH 0|1`` (FW 1.3 only): arm/disarm the 1 s serial watchdog."""
    if not profile.has_watch:
        raise UnsupportedCommandError("WATCH", profile.name)
    return f"WATCH {_check('WATCH', 'mode', int(enabled), 0, 1, profile)}"


def encode_blink(pin: int, rate_decihertz: int, profile: FirmwareProfile = FIRMWARE_1_1) -> str:
    """``BLINK pin rate``: toggle I/O ``pin`` (0..31) at ``rate`` tenths of a hertz (0 = off).

    FW 1.1 knows only the spelling ``BLNK``; the profile's first spelling is sent.
    """
    name = profile.blink_names[0]
    _check(name, "pin", pin, 0, 31, profile)
    _check(name, "rate", rate_decihertz, *_UINT16, profile)
    return f"{name} {format_hex(pin, 8)} {format_hex(rate_decihertz, 16)}"


def _mask_command(command: str, mask: int) -> str:
    return f"{command} {format_hex(_check(command, 'mask', mask, *_UINT32), 32)}"


def encode_in(mask: int) -> str:
    """``IN mask``: make the GPIO pins in ``mask`` inputs."""
    return _mask_command("IN", mask)


def encode_out(mask: int) -> str:
    """``OUT mask``: make the GPIO pins in ``mask`` outputs."""
    return _mask_command("OUT", mask)


def encode_low(mask: int) -> str:
    """``LOW mask``: drive the GPIO pins in ``mask`` low."""
    return _mask_command("LOW", mask)


def encode_high(mask: int) -> str:
    """``HIGH mask``: drive the GPIO pins in ``mask`` high."""
    return _mask_command("HIGH", mask)


def encode_spng(mask: int) -> str:
    """``SPNG mask``: run PING))) sensors on the pins in ``mask`` (Eddie: ``SPNG 6``)."""
    return _mask_command("SPNG", mask)


def encode_sgp(mask: int) -> str:
    """``SGP mask``: make the pins in ``mask`` general-purpose I/O."""
    return _mask_command("SGP", mask)


def encode_ins() -> str:
    """``INS``: mask of GPIO pins that are inputs (reply: 8 hex digits)."""
    return "INS"


def encode_outs() -> str:
    """``OUTS``: mask of GPIO pins that are outputs (reply: 8 hex digits)."""
    return "OUTS"


def encode_lows() -> str:
    """``LOWS``: mask of GPIO pins set low (reply: 8 hex digits)."""
    return "LOWS"


def encode_highs() -> str:
    """``HIGHS``: mask of GPIO pins set high (reply: 8 hex digits)."""
    return "HIGHS"


def encode_read() -> str:
    """``READ``: state of the GPIO pins (reply: 8 hex digits)."""
    return "READ"


def encode_ping() -> str:
    """``PING``: one 3-digit reading per enabled PING))) pin, lowest pin first."""
    return "PING"


def encode_adc() -> str:
    """``ADC``: 8 readings of 3 hex digits, 0..FFF ↔ 0..5 V."""
    return "ADC"


def encode_go(left: int, right: int) -> str:
    """``GO left right``: open-loop motor power, −127..127 each (±100 % duty)."""
    _check("GO", "left", left, -127, 127)
    _check("GO", "right", right, -127, 127)
    return f"GO {format_hex(left, 8)} {format_hex(right, 8)}"


def encode_gospd(left: int, right: int) -> str:
    """``GOSPD left right``: closed-loop wheel speeds in positions/s, signed 16-bit each."""
    _check("GOSPD", "left", left, *_INT16)
    _check("GOSPD", "right", right, *_INT16)
    return f"GOSPD {format_hex(left, 16)} {format_hex(right, 16)}"


def encode_stop(distance: int) -> str:
    """``STOP distance``: decelerate to a stop over ``distance`` positions (0 = cut power)."""
    return f"STOP {format_hex(_check('STOP', 'distance', distance, *_UINT16), 16)}"


def encode_trvl(distance: int, speed: int, profile: FirmwareProfile = FIRMWARE_1_1) -> str:
    """``TRVL distance speed``: drive ``distance`` positions (signed) at ``speed`` positions/s."""
    _check("TRVL", "distance", distance, *_INT16, profile)
    _check("TRVL", "speed", speed, profile.move_speed_min, profile.move_speed_max, profile)
    return f"TRVL {format_hex(distance, 16)} {format_hex(speed, 16)}"


def encode_turn(angle_deg: int, speed: int, profile: FirmwareProfile = FIRMWARE_1_1) -> str:
    """``TURN angle speed``: spin in place ``angle_deg`` degrees, **clockwise positive**.

    Each wheel moves ``angle·93/360`` positions (left +, right −) at ``speed`` positions/s.
    """
    _check("TURN", "angle", angle_deg, *_INT16, profile)
    _check("TURN", "speed", speed, profile.move_speed_min, profile.move_speed_max, profile)
    return f"TURN {format_hex(angle_deg, 16)} {format_hex(speed, 16)}"


def encode_acc(rate: int, profile: FirmwareProfile = FIRMWARE_1_1) -> str:
    """``ACC rate``: speed-change limit in positions/s² for GOSPD/TRVL/TURN.

    ``ACC 0`` is refused where the firmware accepts it but then freezes the speed ramp
    (FW 1.1: ``GOSPD`` no longer changes speed, ``TRVL``/``TURN`` do not move).
    """
    _check("ACC", "rate", rate, profile.acc_min, profile.acc_max, profile)
    if rate == 0 and profile.acc_zero_freezes:
        error = ParameterRangeError("ACC", "rate", rate, 1, profile.acc_max, profile.name)
        error.args = (f"{error.args[0]}; ACC 0 freezes GOSPD on FW {profile.name} "
                      "(the speed ramp never moves)",)
        raise error
    return f"ACC {format_hex(rate, 16)}"


def encode_spd() -> str:
    """``SPD``: wheel speeds in positions/s, averaged over 0.5 s."""
    return "SPD"


def encode_head() -> str:
    """``HEAD``: heading in degrees since ``RST``, clockwise positive, 12-bit signed."""
    return "HEAD"


def encode_dist() -> str:
    """``DIST``: positions each wheel travelled since ``RST``, signed 32-bit, forward +."""
    return "DIST"


def encode_rst() -> str:
    """``RST``: zero ``DIST`` and ``HEAD``."""
    return "RST"


# --- decoders -----------------------------------------------------------------------------

_HEX_FIELD = "[0-9A-Fa-f]"
_RE_WORD = {n: re.compile(f"{_HEX_FIELD}{{{n}}}") for n in (3, 4, 8)}
_RE_DIST = re.compile(f"({_HEX_FIELD}{{8}}) ({_HEX_FIELD}{{8}})")
_RE_SPD = re.compile(f"({_HEX_FIELD}{{4}}) ({_HEX_FIELD}{{4}})")
_RE_ADC = re.compile(" ".join([f"({_HEX_FIELD}{{3}})"] * ADC_CHANNELS))
# The FW 1.1 source leaves a trailing space after the last PING value.
_RE_PING = re.compile(f"(?:{_HEX_FIELD}{{3}}(?: {_HEX_FIELD}{{3}})*)? ?")


def is_error_reply(reply: str) -> bool:
    """Whether ``reply`` is an ``ERROR`` reply (with or without a reason)."""
    return reply.startswith("ERROR")


def check_reply(command: str, reply: str) -> str:
    """Raise the typed :class:`FirmwareError` if ``reply`` is ``ERROR[ - reason]``."""
    if reply.startswith("ERROR"):
        raise firmware_error_for_reply(command, reply)
    return reply


def _match(command: str, pattern: re.Pattern[str], reply: str, expected: str) -> re.Match[str]:
    check_reply(command, reply)
    m = pattern.fullmatch(reply)
    if m is None:
        raise ReplyFormatError(command, reply, expected)
    return m


def decode_empty(command: str, reply: str) -> None:
    """Acknowledgement of an action command: the reply must be empty."""
    check_reply(command, reply)
    if reply != "":
        raise ReplyFormatError(command, reply, "an empty reply")


def decode_word(command: str, reply: str, digits: int = 4) -> int:
    """A single unsigned hex word of ``digits`` digits (``VER``, ``HWVER``: 4; masks: 8)."""
    return int(_match(command, _RE_WORD[digits], reply, f"{digits} hex digits").group(0), 16)


def decode_mask(command: str, reply: str) -> int:
    """``INS``/``OUTS``/``LOWS``/``HIGHS``/``READ``: a 32-bit pin mask."""
    return decode_word(command, reply, 8)


def decode_dist(reply: str) -> tuple[int, int]:
    """``DIST`` → (left, right) positions since ``RST``, signed 32-bit, forward positive."""
    m = _match("DIST", _RE_DIST, reply, "two 8-digit hex fields")
    return to_signed(int(m.group(1), 16), 32), to_signed(int(m.group(2), 16), 32)


def decode_spd(reply: str) -> tuple[int, int]:
    """``SPD`` → (left, right) in positions/s (0.5 s average), signed 16-bit."""
    m = _match("SPD", _RE_SPD, reply, "two 4-digit hex fields")
    return to_signed(int(m.group(1), 16), 16), to_signed(int(m.group(2), 16), 16)


def decode_head(reply: str) -> int:
    """``HEAD`` → degrees since ``RST``, **clockwise positive**, 12-bit two's complement.

    ``FF6`` → −10.  The firmware's value lies in (−360, 360).
    """
    m = _match("HEAD", _RE_WORD[3], reply, "3 hex digits")
    return to_signed(int(m.group(0), 16), 12)


def decode_ping(reply: str) -> tuple[int, ...]:
    """``PING`` → raw readings (firmware units ≈ 1.1 mm), one per enabled pin.

    0 means no echo within 18..2900 units; convert with :func:`ping_units_to_range_m`
    (0 → ``inf``).  A trailing space (FW 1.1) is accepted.
    """
    _match("PING", _RE_PING, reply, "3-digit hex fields")
    return tuple(int(f, 16) for f in reply.split())


def decode_adc(reply: str) -> tuple[int, ...]:
    """``ADC`` → 8 raw counts (0..0xFFF ↔ 0..5 V); see :func:`adc_counts_to_volts`."""
    m = _match("ADC", _RE_ADC, reply, "eight 3-digit hex fields")
    return tuple(int(g, 16) for g in m.groups())


def decoder_for(command: str) -> Callable[[str], object]:
    """The decoder of a command's reply, by command name (for generic tooling)."""
    name = command.upper()
    table: dict[str, Callable[[str], object]] = {
        "HWVER": lambda r: decode_word("HWVER", r),
        "VER": lambda r: decode_word("VER", r),
        "INS": lambda r: decode_mask("INS", r),
        "OUTS": lambda r: decode_mask("OUTS", r),
        "LOWS": lambda r: decode_mask("LOWS", r),
        "HIGHS": lambda r: decode_mask("HIGHS", r),
        "READ": lambda r: decode_mask("READ", r),
        "PING": decode_ping,
        "ADC": decode_adc,
        "SPD": decode_spd,
        "HEAD": decode_head,
        "DIST": decode_dist,
    }
    return table.get(name, lambda r: decode_empty(name, r))

