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
simulation clock.  :class:`~eddiebot.robot.pty_server.PtyServer` serves the emulator on a
pseudo-terminal, as slowly as the real link (:mod:`eddiebot.robot.timing`), and reboots it
when a client opens the port.
"""

from __future__ import annotations

import re

from eddiebot.robot.constants import (
    ADC_CHANNELS,
    BUFFER_LENGTH,
    FIRMWARE_1_1,
    FirmwareProfile,
    range_m_to_ping_units,
    volts_to_adc_counts,
)
from eddiebot.robot.emulator_sensors import FixedSensors, SensorSource
from eddiebot.robot.plant import ControlMode, DrivePlant, PlantConfig
from eddiebot.robot.timing import (
    PROPELLER_BOOT_S,
)

__all__ = ["FirmwareEmulator", "FixedSensors", "SensorSource"]

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

