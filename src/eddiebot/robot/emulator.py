"""Byte-for-byte emulator of the Eddie control board firmware (1.1 and 1.3).

:class:`FirmwareEmulator` consumes the bytes a host sends and returns the bytes the board
would answer, following the FW 1.1 source (``Main``/``Parse``/``NextParameter``/``ParseHex``):

* input is collected in a 255-byte buffer that includes the terminator; the byte that fills
  it (a 254th character, or a CR after 253) raises ``Overflow``, after which everything up to
  the next CR (or NUL) is discarded and ``ERROR[ - Overflow]`` is sent;
* command letters are upper-cased; space and tab (only) separate parameters; BS deletes the
  previous character; control characters 0x01-0x07, 0x0A-0x0C, 0x0E-0x1F and bytes ≥ 0x7F
  are ignored on FW 1.3 (as the command-set documents specify) but kept in the line on
  FW 1.1 (its source stores the byte before its empty ``case`` for them), so there a stray
  LF makes the command ``Invalid command`` (or its last parameter ``Invalid parameter``);
* an empty line gets no reply; a line of only blanks is an invalid command;
* parameters are up to 8 hex digits (more → ``Invalid parameter``), parsed in order, so the
  first fault found decides the reason; ``VERB 1`` appends `` - <reason>`` to ``ERROR``;
* a NUL terminates a line in checksum mode: two checksum bytes follow (big-endian sum of
  the line's bytes including the NUL); the reply is followed by NUL and its own checksum;
* ``PING`` keeps the FW 1.1 trailing space after the last value.

Profile differences (:data:`~eddiebot.robot.constants.FIRMWARE_1_1` default,
:data:`~eddiebot.robot.constants.FIRMWARE_1_3`): ``TRVL``/``TURN`` speed 1..7F vs 1..FF,
``ACC`` 0..1FF vs 1..7FF (``ACC 0`` on 1.1 freezes the speed ramp: ``GOSPD`` no longer
changes speed), ``WATCH`` absent (ERROR) vs present and on at power-on (motors off after 1 s
without serial data), ``BLNK`` vs ``BLINK`` (each build knows one spelling), control bytes
kept vs ignored, ``VER`` 0070 vs 000D.

:meth:`FirmwareEmulator.reboot` is what a reset does (a DTR pulse when the host opens the
port, or power-up): the firmware's RAM state goes back to its power-on values and the board
ignores serial input until the Propeller has booted (:attr:`FirmwareEmulator.booting`).

Motion runs on a :class:`~eddiebot.robot.plant.DrivePlant`; range sensors come from a
pluggable :class:`SensorSource` (standalone: :class:`FixedSensors`).  Time is advanced by
the caller (:meth:`FirmwareEmulator.advance_to_ns`), in real time by the pty server or on a
simulation clock.  :class:`PtyServer` serves the emulator on a pseudo-terminal, as slowly as
the real link (:mod:`eddiebot.robot.timing`), and reboots it when a client opens the port.
"""

from __future__ import annotations

import contextlib
import ctypes
import errno
import math
import os
import re
import select
import struct
import threading
import time
import tty
from collections import deque
from dataclasses import dataclass
from typing import Protocol

from eddiebot.robot.constants import (
    ADC_CHANNELS,
    BATTERY_ADC_INDEX,
    BATTERY_DIVIDER,
    BUFFER_LENGTH,
    FIRMWARE_1_1,
    FirmwareProfile,
    range_m_to_ping_units,
    volts_to_adc_counts,
)
from eddiebot.robot.plant import ControlMode, DrivePlant, PlantConfig
from eddiebot.robot.timing import (
    DEFAULT_TIMING,
    PROPELLER_BOOT_S,
    LinkTiming,
    byte_time_s,
    processing_s,
    usb_hold_s,
)

__all__ = ["FirmwareEmulator", "FixedSensors", "PtyServer", "SensorSource", "TimedWire"]

_CR = 0x0D
_BS = 0x08
_NUL = 0x00
_IGNORED = frozenset([*range(0x01, 0x08), *range(0x0A, 0x0D), *range(0x0E, 0x20),
                      *range(0x7F, 0x100)])
_HEX = frozenset(b"0123456789ABCDEFabcdef")
_BLANK = re.compile(rb"[ \t]")
_BLANKS = re.compile(rb"[ \t]+")
# A complete line of printable characters (no BS, NUL, ignored bytes) shorter than the buffer.
_SIMPLE_LINE = re.compile(rb"[\x20-\x7e]{1,%d}\r" % (BUFFER_LENGTH - 2))
_OUTPUTABLE = 0x0007FFFF
_PINGABLE = 0x0000FFFF
_INITIAL_GPIO = (1 << 16) | (1 << 17) | (1 << 18)
_HARDWARE_VERSION = 0x0002


class SensorSource(Protocol):
    """Where the emulated board's range sensors and ADC read from.

    Times are the emulator's, in seconds.  The simulator plugs in its world here.
    """

    def ping_range_m(self, pin: int, time_s: float) -> float:
        """Range in metres seen by the PING))) sensor on I/O ``pin`` (``inf``: no echo)."""
        ...

    def adc_volts(self, channel: int, time_s: float) -> float:
        """Voltage at ADC index ``channel`` (0..7) in volts."""
        ...


@dataclass
class FixedSensors:
    """Constant, plausible readings for the standalone emulator.

    PING))) pins 1 and 2 see walls at ``ping_left_m``/``ping_right_m``; other pins see no
    echo.  IR channels 0..2 read ``ir_volts`` (≈ 0.3 V: nothing within 80 cm); the battery
    (index 7) reads ``battery_v`` through the 3.21 divider; other channels read 0 V.
    """

    ping_left_m: float = 1.5
    ping_right_m: float = 2.0
    ir_volts: tuple[float, float, float] = (0.3, 0.3, 0.3)
    battery_v: float = 12.6

    def ping_range_m(self, pin: int, time_s: float) -> float:
        """Range on ``pin`` in metres."""
        if pin == 1:
            return self.ping_left_m
        if pin == 2:
            return self.ping_right_m
        return math.inf

    def adc_volts(self, channel: int, time_s: float) -> float:
        """Volts on ADC ``channel``."""
        if 0 <= channel < 3:
            return self.ir_volts[channel]
        if channel == BATTERY_ADC_INDEX:
            return self.battery_v / BATTERY_DIVIDER
        return 0.0


class _Abort(Exception):
    """A firmware ``abort @Reason``."""

    def __init__(self, reason: str) -> None:
        super().__init__(reason)
        self.reason = reason


_HEX_FORMATS = {n: (f"0{n}X", (1 << (4 * n)) - 1) for n in (3, 4, 8)}


def _hex(value: int, digits: int) -> str:
    fmt, mask = _HEX_FORMATS[digits]
    return format(value & mask, fmt)


def _sext(value: int, bits: int) -> int:
    value &= (1 << bits) - 1
    return value - (1 << bits) if value & (1 << (bits - 1)) else value


def _tdiv(a: int, b: int) -> int:
    """Spin's ``/``: integer division truncating towards zero."""
    q = abs(a) // abs(b)
    return q if (a >= 0) == (b >= 0) else -q


def _tmod(a: int, b: int) -> int:
    """Spin's ``//``: remainder with the sign of the dividend."""
    return a - b * _tdiv(a, b)


def _as_long(value: int) -> int:
    """A 32-bit Spin long as a signed Python int."""
    return _sext(value, 32)


class _Params:
    """Sequential parameter reader with the firmware's error order."""

    __slots__ = ("_i", "_tokens")

    def __init__(self, tokens: list[bytes]) -> None:
        self._tokens = tokens
        self._i = 0

    def next(self) -> int:
        if self._i >= len(self._tokens):
            raise _Abort("Too few parameters")
        token = self._tokens[self._i]
        self._i += 1
        if len(token) > 8 or any(c not in _HEX for c in token):
            raise _Abort("Invalid parameter")
        return int(token, 16)  # 1..8 hex digits: an unsigned 32-bit long

    def last(self) -> None:
        if self._i < len(self._tokens):
            raise _Abort("Too many parameters")


class FirmwareEmulator:
    """The control board: serial line discipline, command set, plant and sensors.

    ``feed(data)`` returns the reply bytes at the current emulator time.  Advance time with
    :meth:`advance_to_ns` / :meth:`step`; the plant moves and the 1.3 watchdog trips only
    as time advances.  A new emulator has finished booting; :meth:`reboot` resets it.
    """

    def __init__(self, profile: FirmwareProfile = FIRMWARE_1_1, *, counts_per_rev: int = 36,
                 sensors: SensorSource | None = None, plant_config: PlantConfig | None = None,
                 start_ns: int = 0) -> None:
        self.profile = profile
        config = plant_config or PlantConfig(counts_per_rev=counts_per_rev)
        config.acceleration = profile.default_acceleration
        if plant_config is None and profile.no_load_rev_per_s:
            config.max_speed_pos_s = profile.no_load_rev_per_s * config.counts_per_rev
        self.plant = DrivePlant(config, start_ns=start_ns)
        self.sensors: SensorSource = sensors if sensors is not None else FixedSensors()
        self.encoder_running = True
        """Whether the position-control loop runs; False makes motion commands fail with
        ``Encoder error`` (and ``STOP`` latches the motors off, as on the board)."""
        self._ignored = _IGNORED if profile.ignores_control_bytes else frozenset()
        self._boot_until_ns = start_ns
        self._last_command = ""
        self._offset = [0, 0]
        self._power_on_state(start_ns)
        cmds = {
            "HWVER": self._cmd_hwver, "VER": self._cmd_ver, "OUT": self._cmd_out,
            "IN": self._cmd_in, "HIGH": self._cmd_high, "LOW": self._cmd_low,
            "OUTS": self._cmd_outs, "INS": self._cmd_ins, "HIGHS": self._cmd_highs,
            "LOWS": self._cmd_lows, "READ": self._cmd_read, "ADC": self._cmd_adc,
            "PING": self._cmd_ping, "SGP": self._cmd_sgp, "SPNG": self._cmd_spng,
            "TRVL": self._cmd_trvl, "GOSPD": self._cmd_gospd, "GO": self._cmd_go,
            "STOP": self._cmd_stop, "TURN": self._cmd_turn, "ACC": self._cmd_acc,
            "SPD": self._cmd_spd, "HEAD": self._cmd_head, "DIST": self._cmd_dist,
            "RST": self._cmd_rst, "VERB": self._cmd_verb,
        }
        for name in profile.blink_names:
            cmds[name] = self._cmd_blink
        if profile.has_watch:
            cmds["WATCH"] = self._cmd_watch
        self._commands = {k.encode(): v for k, v in cmds.items()}

    def _power_on_state(self, now_ns: int) -> None:
        """The firmware's RAM as it is when ``Main`` starts (FW ``Dat`` initial values)."""
        profile = self.profile
        self.motors_latched_off = False
        self.verbose = False
        self.watch_enabled = profile.watch_default_on
        self.watchdog_tripped = False
        self._last_rx_ns = now_ns
        self._buf = bytearray()
        self._overflow = False
        self._checksum_pending: bytearray | None = None
        self._ping_mask = profile.power_on_ping_mask & _PINGABLE
        self._gpio_mask = _INITIAL_GPIO & ~self._ping_mask
        self._dira = 0
        self._outa = 0
        self._blink: tuple[int, int] | None = None

    def reboot(self, now_ns: int, *, boot_s: float = PROPELLER_BOOT_S) -> None:
        """Reset the board at ``now_ns`` (a DTR pulse on port open, or power-up).

        The plant runs up to ``now_ns``; then the motors stop at once (the PWM pins float
        during the reset) and the loop is left in power mode at zero power, as at power-on;
        ``DIST``/``HEAD`` read 0 (the firmware clears the Position Controllers on start),
        ``ACC`` is back to its default, ``VERB`` 0, the PING))) and GPIO masks, ``WATCH``
        and the line buffer are as at power-on.  Serial input is dropped without a reply
        until ``boot_s`` seconds later (:attr:`booting`).  The robot does not move: the
        plant's wheel positions and pose are kept.
        """
        self.advance_to_ns(now_ns)
        now_ns = max(now_ns, self.plant.time_ns)
        self.plant.disable()
        self.plant.cut_power()
        self.plant.set_acceleration(self.profile.default_acceleration)
        left, right = self.plant.counts
        self._offset = [-left, -right]
        self._boot_until_ns = now_ns + max(0, round(boot_s * 1e9))
        self._power_on_state(self._boot_until_ns)
        self._last_command = ""

    @property
    def booting(self) -> bool:
        """Whether the board is still starting up after :meth:`reboot` (input is lost)."""
        return self.plant.time_ns < self._boot_until_ns

    @property
    def boot_done_ns(self) -> int:
        """Emulator time at which the last (re)boot finishes, in nanoseconds."""
        return self._boot_until_ns

    @property
    def last_command(self) -> str:
        """Upper-case name of the last command line executed (``""`` before any)."""
        return self._last_command

    # --- time ------------------------------------------------------------------------------

    @property
    def time_ns(self) -> int:
        """Emulator time in nanoseconds."""
        return self.plant.time_ns

    @property
    def time_s(self) -> float:
        """Emulator time in seconds."""
        return self.plant.time_ns / 1e9

    def advance_to_ns(self, t_ns: int) -> None:
        """Run the plant up to ``t_ns`` (no-op if in the past), tripping the watchdog on time."""
        if self.watch_enabled and not self.watchdog_tripped:
            trip = self._last_rx_ns + round(self.profile.watchdog_timeout_s * 1e9)
            if trip <= t_ns:
                self.plant.advance_to_ns(trip)
                self.watchdog_tripped = True
                self.plant.disable()
        self.plant.advance_to_ns(t_ns)

    def advance_to(self, t_s: float) -> None:
        """Run the plant up to ``t_s`` seconds."""
        self.advance_to_ns(round(t_s * 1e9))

    def step(self, dt_s: float) -> None:
        """Run the plant for ``dt_s`` seconds."""
        self.advance_to_ns(self.plant.time_ns + round(dt_s * 1e9))

    # --- serial line -----------------------------------------------------------------------

    def feed(self, data: bytes) -> bytes:
        """Process bytes received from the host; return the bytes the board sends back.

        While :attr:`booting` the bytes are lost (the firmware's UART is not running yet).
        """
        if not data or self.booting:
            return b""
        self._last_rx_ns = self.plant.time_ns
        self.watchdog_tripped = False
        if (not self._buf and not self._overflow and self._checksum_pending is None
                and _SIMPLE_LINE.fullmatch(data)):
            # Fast path for the common case: one plain command line, nothing pending.
            return self._execute(data[:-1]) + b"\r"
        out = bytearray()
        buf = self._buf
        ignored = self._ignored
        for b in data:
            pending = self._checksum_pending
            if pending is not None:
                pending.append(b)
                if len(pending) == 2:
                    out += self._finish_checksum_line(int.from_bytes(pending, "big"))
                continue
            if self._overflow:
                if b == _CR:
                    out += self._error_text("Overflow") + b"\r"
                    self._reset_line()
                elif b == _NUL:
                    out += self._with_checksum(self._error_text("Overflow"))
                    self._reset_line()
                continue
            if b in ignored:
                continue
            buf.append(b)
            if len(buf) == BUFFER_LENGTH:
                self._overflow = True
                continue
            if b == _CR:
                if len(buf) > 1:
                    out += self._execute(bytes(buf[:-1])) + b"\r"
                buf.clear()
            elif b == _BS:
                buf.pop()
                if buf:
                    buf.pop()
            elif b == _NUL:
                if len(buf) > 1:
                    self._checksum_pending = bytearray()
                else:
                    buf.clear()
        return bytes(out)

    def _reset_line(self) -> None:
        self._buf.clear()
        self._overflow = False
        self._checksum_pending = None

    def _finish_checksum_line(self, remote: int) -> bytes:
        line = bytes(self._buf)  # ends with the NUL
        self._reset_line()
        if sum(line) & 0xFFFF != remote:
            return self._with_checksum(self._error_text("Bad checksum"))
        return self._with_checksum(self._execute(line[:-1]))

    @staticmethod
    def _with_checksum(text: bytes) -> bytes:
        total = sum(text) & 0xFFFF
        return text + b"\x00" + total.to_bytes(2, "big")

    def _error_text(self, reason: str) -> bytes:
        return b"ERROR - " + reason.encode() if self.verbose else b"ERROR"

    def _execute(self, line: bytes) -> bytes:
        """Parse and run one command line (without terminator); return the reply text."""
        # The command name ends at the first blank; only it is upper-cased here (parameters
        # are hex and accepted in either case).
        blank = _BLANK.search(line)
        cut = blank.start() if blank else len(line)
        name = line[:cut].upper()
        # Only space and tab separate parameters (FW NextParameter); any other byte kept in
        # the line (FW 1.1 keeps control bytes) is part of a parameter and makes it invalid.
        tokens = [t for t in _BLANKS.split(line[cut:]) if t] if blank else []
        self._last_command = name.decode("latin-1")
        handler = self._commands.get(name)
        try:
            if handler is None:
                raise _Abort("Invalid command")
            return handler(_Params(tokens)).encode()
        except _Abort as abort:
            return self._error_text(abort.reason)

    # --- commands --------------------------------------------------------------------------

    def _require_loop(self) -> None:
        if not self.encoder_running:
            raise _Abort("Encoder error")

    def _motion_allowed(self) -> bool:
        return not self.motors_latched_off

    def _cmd_hwver(self, p: _Params) -> str:
        p.last()
        return _hex(_HARDWARE_VERSION, 4)

    def _cmd_ver(self, p: _Params) -> str:
        p.last()
        return _hex(self.profile.version_word, 4)

    def _cmd_out(self, p: _Params) -> str:
        mask = p.next()
        p.last()
        self._dira |= mask & self._gpio_mask
        return ""

    def _cmd_in(self, p: _Params) -> str:
        mask = p.next()
        p.last()
        self._dira &= ~(mask & self._gpio_mask)
        return ""

    def _cmd_high(self, p: _Params) -> str:
        mask = p.next()
        p.last()
        self._outa |= mask & self._gpio_mask
        return ""

    def _cmd_low(self, p: _Params) -> str:
        mask = p.next()
        p.last()
        self._outa &= ~(mask & self._gpio_mask)
        return ""

    def _cmd_outs(self, p: _Params) -> str:
        p.last()
        return _hex(self._dira & self._gpio_mask, 8)

    def _cmd_ins(self, p: _Params) -> str:
        p.last()
        return _hex(~self._dira & self._gpio_mask, 8)

    def _cmd_highs(self, p: _Params) -> str:
        p.last()
        return _hex(self._outa & self._gpio_mask, 8)

    def _cmd_lows(self, p: _Params) -> str:
        p.last()
        return _hex(~self._outa & self._gpio_mask, 8)

    def _cmd_read(self, p: _Params) -> str:
        p.last()
        ina = self._outa & self._dira  # nothing external drives the inputs
        return _hex(ina & self._gpio_mask, 8)

    def _cmd_adc(self, p: _Params) -> str:
        p.last()
        t = self.time_s
        # MCP3008 (10-bit) read as 12-bit: the two LSBs carry no information.
        values = [volts_to_adc_counts(self.sensors.adc_volts(i, t)) & ~0x3
                  for i in range(ADC_CHANNELS)]
        return " ".join(_hex(v, 3) for v in values)

    def _cmd_ping(self, p: _Params) -> str:
        p.last()
        if not self._ping_mask:
            return ""
        t = self.time_s
        parts = [_hex(range_m_to_ping_units(self.sensors.ping_range_m(pin, t)), 3) + " "
                 for pin in range(32) if self._ping_mask >> pin & 1]
        return "".join(parts)  # the FW 1.1 source leaves the trailing space in place

    def _cmd_sgp(self, p: _Params) -> str:
        mask = p.next() & _OUTPUTABLE
        p.last()
        if mask & self._ping_mask:
            self._ping_mask &= ~mask
        self._gpio_mask = mask
        return ""

    def _cmd_spng(self, p: _Params) -> str:
        mask = p.next() & _PINGABLE
        p.last()
        self._gpio_mask &= ~mask
        self._outa &= ~mask
        self._dira &= ~mask
        self._ping_mask = mask
        return ""

    def _cmd_trvl(self, p: _Params) -> str:
        distance = p.next()
        speed = p.next()
        p.last()
        self._require_loop()
        if not self.profile.move_speed_min <= _as_long(speed) <= self.profile.move_speed_max:
            raise _Abort("Invalid parameter")
        if self._motion_allowed():
            d = _sext(distance, 16)
            self.plant.move(d, d, _as_long(speed))
        return ""

    def _cmd_turn(self, p: _Params) -> str:
        angle = p.next()
        speed = p.next()
        p.last()
        self._require_loop()
        if not self.profile.move_speed_min <= _as_long(speed) <= self.profile.move_speed_max:
            raise _Abort("Invalid parameter")
        if self._motion_allowed():
            a = _sext(angle, 16)
            half = self.plant.positions_per_spin // 2
            delta = _tdiv(a * half, 360)
            self.plant.move(delta, -delta, _as_long(speed))
        return ""

    def _cmd_gospd(self, p: _Params) -> str:
        left = p.next()
        right = p.next()
        p.last()
        self._require_loop()
        if self._motion_allowed():
            self.plant.set_velocity(_sext(left, 16), _sext(right, 16))
        return ""

    def _cmd_go(self, p: _Params) -> str:
        left = p.next()
        right = p.next()
        p.last()
        self._require_loop()
        if self._motion_allowed():
            self.plant.set_power(_sext(left, 8), _sext(right, 8))
        return ""

    def _cmd_stop(self, p: _Params) -> str:
        distance = p.next()
        p.last()
        if not self.encoder_running:
            self.motors_latched_off = True
            self.plant.disable()
            raise _Abort("Encoder error")
        if self._motion_allowed():
            self.plant.stop(_as_long(distance))
        return ""

    def _cmd_acc(self, p: _Params) -> str:
        rate = _as_long(p.next())
        p.last()
        if not self.profile.acc_min <= rate <= self.profile.acc_max:
            raise _Abort("Invalid parameter")
        self.plant.set_acceleration(rate)
        return ""

    def _cmd_spd(self, p: _Params) -> str:
        p.last()
        self._require_loop()
        left, right = self.plant.speed_report
        return f"{_hex(left, 4)} {_hex(right, 4)}"

    def _positions(self) -> tuple[int, int]:
        left, right = self.plant.counts
        return left + self._offset[0], right + self._offset[1]

    def _cmd_head(self, p: _Params) -> str:
        p.last()
        self._require_loop()
        left, right = self._positions()
        spin = self.plant.positions_per_spin
        # ((L - R) // 186) * 360 / 186 with Spin's truncating operators: may be negative.
        deg = _tdiv(_tmod(_as_long(left - right), spin) * 360, spin)
        return _hex(deg, 3)

    def _cmd_dist(self, p: _Params) -> str:
        p.last()
        self._require_loop()
        left, right = self._positions()
        return f"{_hex(left, 8)} {_hex(right, 8)}"

    def _cmd_rst(self, p: _Params) -> str:
        p.last()
        left, right = self.plant.counts
        self._offset = [-left, -right]
        return ""

    def _cmd_blink(self, p: _Params) -> str:
        pin = p.next()
        rate = p.next()
        p.last()
        bit = 1 << (pin & 31)
        if bit & _OUTPUTABLE:
            if rate:
                self._ping_mask &= ~bit
                self._gpio_mask &= ~bit
                self._outa &= ~bit
                self._dira |= bit
                self._blink = (pin, rate)
            else:
                self._blink = None
        return ""

    def _cmd_verb(self, p: _Params) -> str:
        mode = _as_long(p.next())
        p.last()
        if mode not in (0, 1):
            raise _Abort("Invalid parameter")
        self.verbose = bool(mode)
        return ""

    def _cmd_watch(self, p: _Params) -> str:
        mode = _as_long(p.next())
        p.last()
        if mode not in (0, 1):
            raise _Abort("Invalid parameter")
        self.watch_enabled = bool(mode)
        return ""

    # --- introspection for tests and the simulator ----------------------------------------

    @property
    def ping_mask(self) -> int:
        """Pins currently running PING))) sensors."""
        return self._ping_mask

    @property
    def control_mode(self) -> ControlMode:
        """The plant's control mode."""
        return self.plant.mode


def _split_after_cr(data: bytes) -> list[bytes]:
    """``data`` cut after each CR (the bytes that can complete a command line)."""
    pieces = []
    start = 0
    while (end := data.find(b"\r", start)) >= 0:
        pieces.append(data[start:end + 1])
        start = end + 1
    if start < len(data):
        pieces.append(data[start:])
    return pieces


def _ns(seconds: float) -> int:
    return round(seconds * 1e9)


class TimedWire:
    """The serial link between a host and a :class:`FirmwareEmulator`, as slow as Eddie's.

    A pure scheduler on an integer-nanosecond clock (the emulator's): the caller reports
    what the host wrote and when (:meth:`host_wrote`), and collects the replies the host
    can read by a given time (:meth:`replies_until`), which also runs the emulator.  With
    ``timing`` (:mod:`eddiebot.robot.timing`):

    * the host's bytes reach the board one USB frame plus their UART time after the write,
      and each line is fed to the emulator when its CR arrives; writes queue on the wire;
    * a ``PING`` keeps the firmware's command loop busy for ``ping_block_s``: lines that
      arrive meanwhile wait (the real UART buffers them);
    * a reply goes out on the UART when the command is done (after the previous reply) and
      is readable on the host after the FTDI latency timer (see
      :func:`~eddiebot.robot.timing.usb_hold_s`); replies stay in order.

    On an idle wire a request's reply is thus due
    :func:`~eddiebot.robot.timing.reply_delay_s` after the write.  Not modelled: the
    firmware's 16-byte receive buffer overflowing during a ``PING`` (the driver never has
    more than one request in flight) and Spin execution time of other commands.
    """

    def __init__(self, emulator: FirmwareEmulator, timing: LinkTiming = DEFAULT_TIMING) -> None:
        self.emulator = emulator
        self.timing = timing
        # Lines on their way to the board and replies on their way to the host, each with
        # the time at which it arrives; both in time order.
        self._inbound: deque[tuple[int, bytes]] = deque()
        self._outbound: deque[tuple[int, bytes]] = deque()
        self._rx_free_ns = 0  # host -> board UART busy until
        self._tx_free_ns = 0  # board -> host UART busy until
        self._board_free_ns = 0  # the firmware's command loop busy until (PING)
        self._last_due_ns = 0

    def reset(self, now_ns: int) -> None:
        """Forget everything in flight (a port closed and reopened)."""
        self._inbound.clear()
        self._outbound.clear()
        self._rx_free_ns = self._tx_free_ns = self._board_free_ns = self._last_due_ns = now_ns

    def drop_replies(self) -> None:
        """Forget the replies not yet read (the host closed the port)."""
        self._outbound.clear()

    def host_wrote(self, now_ns: int, data: bytes) -> None:
        """The host wrote ``data`` at ``now_ns``: schedule its lines' arrival at the board."""
        if not data:
            return
        timing = self.timing
        start = max(now_ns + _ns(timing.usb_frame_s), self._rx_free_ns)
        sent = 0
        for piece in _split_after_cr(data):
            sent += len(piece)
            self._inbound.append((start + _ns(byte_time_s(timing, sent)), piece))
        self._rx_free_ns = start + _ns(byte_time_s(timing, sent))

    def next_event_ns(self) -> int | None:
        """When the next line reaches the board or the next reply becomes readable."""
        dues = [self._outbound[0][0]] if self._outbound else []
        if self._inbound:
            dues.append(max(self._inbound[0][0], self._board_free_ns))
        return min(dues) if dues else None

    def replies_until(self, now_ns: int) -> list[bytes]:
        """Run the board up to ``now_ns``; return the replies readable by then, in order.

        The emulator is advanced to each line's arrival and finally to ``now_ns``.
        """
        while self._inbound:
            due, piece = self._inbound[0]
            at = max(due, self._board_free_ns)
            if at > now_ns:
                break
            self._inbound.popleft()
            self._deliver(at, piece)
        self.emulator.advance_to_ns(now_ns)
        out = []
        while self._outbound and self._outbound[0][0] <= now_ns:
            out.append(self._outbound.popleft()[1])
        return out

    def _deliver(self, at_ns: int, piece: bytes) -> None:
        """The board receives ``piece`` at ``at_ns``; queue its reply for the host."""
        self.emulator.advance_to_ns(at_ns)
        reply = self.emulator.feed(piece)
        if not reply:
            return
        timing = self.timing
        busy = _ns(processing_s(timing, self.emulator.last_command, reply))
        self._board_free_ns = at_ns + busy
        start = max(at_ns + busy, self._tx_free_ns)
        self._tx_free_ns = start + _ns(byte_time_s(timing, len(reply)))
        # The FTDI chip delivers in order: a reply never overtakes the one before it.
        due = max(self._tx_free_ns + _ns(usb_hold_s(timing, len(reply))), self._last_due_ns)
        self._last_due_ns = due
        self._outbound.append((due, reply))


_IN_OPEN = 0x20
_IN_CLOSE = 0x08 | 0x10  # IN_CLOSE_WRITE | IN_CLOSE_NOWRITE
_INOTIFY_EVENT = struct.Struct("iIII")


class _OpenWatch:
    """Opens and closes of a device file, in order, from Linux inotify (via libc).

    Unlike watching the pty master for EIO, no open or close is missed however quickly a
    client closes and reopens the port.  :meth:`create` returns ``None`` where inotify is
    not available.
    """

    def __init__(self, fd: int) -> None:
        self.fd = fd

    @classmethod
    def create(cls, path: str) -> _OpenWatch | None:
        try:
            libc = ctypes.CDLL(None, use_errno=True)
            fd = libc.inotify_init1(os.O_NONBLOCK | os.O_CLOEXEC)
            if fd < 0:
                return None
            if libc.inotify_add_watch(fd, os.fsencode(path), _IN_OPEN | _IN_CLOSE) < 0:
                os.close(fd)
                return None
        except (OSError, AttributeError):
            return None
        return cls(fd)

    def events(self) -> list[int]:
        """+1 per open, -1 per close since the last call, in order."""
        try:
            data = os.read(self.fd, 4096)
        except (BlockingIOError, InterruptedError):
            return []
        out = []
        offset = 0
        while offset + _INOTIFY_EVENT.size <= len(data):
            _, mask, _, name_len = _INOTIFY_EVENT.unpack_from(data, offset)
            offset += _INOTIFY_EVENT.size + name_len
            if mask & _IN_OPEN:
                out.append(1)
            elif mask & _IN_CLOSE:
                out.append(-1)
        return out

    def close(self) -> None:
        with contextlib.suppress(OSError):
            os.close(self.fd)


class PtyServer:
    """Serve a :class:`FirmwareEmulator` on a pseudo-terminal in real time, as slowly as the
    real link, rebooting it when a client opens the port.

    ``device_path`` is the slave side (``/dev/pts/N``) a serial client opens (e.g.
    ``serial.serial_for_url(device_path)``; pyserial sets raw mode itself, and the server
    has already made the pty raw).

    **Timing** (``timing``, see :mod:`eddiebot.robot.timing` and :class:`TimedWire`): what
    the host writes reaches the emulator after one USB frame and its UART time, and each
    reply is written to the pty only when the host could read it from the real board: a
    ``DIST`` round trip takes ≈ 19 ms, ``PING`` ≈ 43 ms, ``ADC`` ≈ 20 ms.
    :data:`~eddiebot.robot.timing.NO_TIMING` turns this off (replies at once, instant boot).

    **Port open** (``reboot_on_open``): opening a serial port raises DTR, which resets the
    real board, so when the port goes from no client to one the emulator reboots
    (:meth:`FirmwareEmulator.reboot`: counters zeroed, motors stopped, input lost for
    ``timing.boot_s``) and replies still in flight are dropped.  The server does not keep
    the slave side open itself.  Opens and closes are seen through inotify on
    ``device_path`` (Linux), in order, however quickly a client reopens the port.  Without
    inotify the server falls back to the master side: reading it fails with EIO while no
    client has the port open, so it polls every ``poll_s`` until a read does not fail;
    there a close and reopen within one poll counts as one open.  :attr:`opens` counts the
    opens seen.
    """

    def __init__(self, emulator: FirmwareEmulator, *, poll_s: float = 0.01,
                 timing: LinkTiming = DEFAULT_TIMING, reboot_on_open: bool = True) -> None:
        self.emulator = emulator
        self.poll_s = poll_s
        self.timing = timing
        self.reboot_on_open = reboot_on_open
        self.wire = TimedWire(emulator, timing)
        self.opens = 0
        """Client opens seen so far."""
        self._master, slave = os.openpty()
        tty.setraw(slave)
        tty.setraw(self._master)
        os.set_blocking(self._master, False)
        self.device_path = os.ttyname(slave)
        # Without an open slave fd of our own, a read on the master fails with EIO while no
        # client has the port open (the fallback way to see opens), and inotify reports
        # only the clients' opens. The pty and its termios settings live on as long as the
        # master is open.
        os.close(slave)
        self._watch = _OpenWatch.create(self.device_path)
        self._openers = 0
        self._client_open = False
        self._stop = threading.Event()
        self._wake_r, self._wake_w = os.pipe()
        self._t0_ns = time.monotonic_ns() - emulator.time_ns

    @property
    def client_connected(self) -> bool:
        """Whether a client has the port open (as last seen by the serve loop)."""
        return self._client_open

    @property
    def open_detection(self) -> str:
        """How opens are seen: ``"inotify"`` (every open) or ``"poll"`` (EIO, every ``poll_s``)."""
        return "inotify" if self._watch is not None else "poll"

    def stop(self) -> None:
        """Ask :meth:`serve_forever` to return (thread- and signal-safe)."""
        self._stop.set()
        with contextlib.suppress(OSError):
            os.write(self._wake_w, b"x")

    def serve_forever(self) -> None:
        """Serve until :meth:`stop`; then close the pty."""
        try:
            while not self._stop.is_set():
                now = self._now_ns()
                for reply in self.wire.replies_until(now):
                    self._write_all(reply)
                due = self.wire.next_event_ns()
                timeout = None if self._watch is not None else self.poll_s
                if due is not None:
                    wait = max(0.0, (due - now) / 1e9)
                    timeout = wait if timeout is None else min(timeout, wait)
                # select cannot wait on the master while no client has the port open (it
                # reports the hang-up at once).
                watched = [self._wake_r, self._master] if self._client_open else [self._wake_r]
                if self._watch is not None:
                    watched.append(self._watch.fd)
                ready, _, _ = select.select(watched, [], [], timeout)
                if self._wake_r in ready:
                    with contextlib.suppress(OSError):
                        os.read(self._wake_r, 64)
                if self._watch is not None:
                    self._track_opens()
                    if self._client_open and self._master in ready and not self._read_master():
                        break
                elif ((self._master in ready or not self._client_open)
                      and not self._read_master()):
                    break
        finally:
            self.close()

    def _now_ns(self) -> int:
        return time.monotonic_ns() - self._t0_ns

    def _track_opens(self) -> None:
        assert self._watch is not None
        for change in self._watch.events():
            self._openers = max(0, self._openers + change)
            if self._openers == 1 and change > 0:
                self._client_opened()
            elif self._openers == 0:
                self._client_closed()

    def _read_master(self) -> bool:
        """Read what the host wrote; without inotify also see opens and closes.

        Returns False when the pty is gone.
        """
        try:
            data = os.read(self._master, 4096)
        except (BlockingIOError, InterruptedError):
            if self._watch is None:
                self._client_opened()
            return True
        except OSError as exc:
            if exc.errno == errno.EIO:
                if self._watch is None:
                    self._client_closed()
                return True
            return False
        if not data:
            if self._watch is None:
                self._client_closed()
            return True
        if self._watch is None:
            self._client_opened()
        self.wire.host_wrote(self._now_ns(), data)
        return True

    def _client_opened(self) -> None:
        if self._client_open:
            return
        self._client_open = True
        self.opens += 1
        now = self._now_ns()
        self.wire.reset(now)
        if self.reboot_on_open:
            self.emulator.reboot(now, boot_s=self.timing.boot_s)

    def _client_closed(self) -> None:
        if self._client_open:
            self._client_open = False
            self.wire.drop_replies()

    def _write_all(self, data: bytes) -> None:
        view = memoryview(data)
        while view and self._client_open and not self._stop.is_set():
            try:
                n = os.write(self._master, view)
            except BlockingIOError:
                select.select([], [self._master], [], self.poll_s)
                continue
            except OSError:  # the client closed the port meanwhile
                self._client_closed()
                return
            view = view[n:]

    def close(self) -> None:
        """Close the pty (idempotent)."""
        if self._watch is not None:
            self._watch.close()
        for fd in (self._master, self._wake_r, self._wake_w):
            with contextlib.suppress(OSError):
                os.close(fd)
        self._master = self._wake_r = self._wake_w = -1
