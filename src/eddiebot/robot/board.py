"""Driver of the Eddie control board: a transport-free protocol core and a typed API.

:class:`ProtocolCore` sends one request at a time over a :class:`~eddiebot.robot.links.Link`,
frames the reply on CR and enforces the timeout on an injected clock (a callable returning
integer nanoseconds; ``time.monotonic_ns`` on hardware, the simulation clock in the
simulator).  It never pairs a request with an earlier reply: input left over from before is
discarded before every request, and after a timeout, a garbled reply or a reconnect it
*resynchronises* — sends a lone CR (which ends any partial line on the board; an empty line
gets no answer) and discards input until the line has been quiet for ``resync_quiet_s``
(default: the request timeout).  Only a reply later than the timeout plus that quiet window
could still be taken for the next request's; the decoders check each reply's shape as well.

:class:`Board` is the API the base nodes call.  It reads ``VER`` at start and adopts that
firmware's parameter ranges, so out-of-range commands are refused before they are sent.
It converts the firmware's clockwise ``TURN``/``HEAD`` to REP-103 (counter-clockwise
positive, radians) — the only place in eddiebot where that happens.  Every other quantity is
in the firmware's units (positions, positions/s, raw PING units, raw ADC counts); convert
them with :mod:`eddiebot.robot.constants`.

Faults are logged once per episode: the first timeout of a run of timeouts is a warning,
the rest are debug messages, and the first success afterwards logs the recovery.
"""

from __future__ import annotations

import enum
import logging
import math
import re
import threading
import time
from collections.abc import Callable
from typing import TypeVar

from eddiebot.robot import protocol
from eddiebot.robot.constants import FIRMWARE_1_1, PING_MASK, FirmwareProfile, profile_for_version
from eddiebot.robot.errors import (
    BoardInterrupted,
    BoardTimeout,
    FirmwareError,
    LinkLost,
    ParameterRangeError,
    ReplyFormatError,
)
from eddiebot.robot.links import Link

__all__ = ["Board", "BoardEvent", "ProtocolCore"]

T = TypeVar("T")
_PRINTABLE = re.compile(rb"[\x20-\x7e]*")
_log = logging.getLogger(__name__)


class BoardEvent(enum.Enum):
    """What :class:`ProtocolCore` reports through ``on_event(event, detail)``."""

    TIMEOUT = "timeout"
    GARBLED = "garbled"
    LINK_LOST = "link_lost"
    LINK_RESTORED = "link_restored"
    FIRMWARE_ERROR = "firmware_error"
    RECOVERED = "recovered"
    RESYNC = "resync"


EventCallback = Callable[[BoardEvent, str], None]


class _Episodes:
    """Log each kind of fault once per episode; log the recovery once."""

    def __init__(self, logger: logging.Logger, on_event: EventCallback | None) -> None:
        self.logger = logger
        self.on_event = on_event
        self.active: dict[str, int] = {}

    def fault(self, kind: str, event: BoardEvent, message: str) -> None:
        count = self.active.get(kind, 0)
        self.active[kind] = count + 1
        if count == 0:
            self.logger.warning("%s", message)
            if self.on_event is not None:
                self.on_event(event, message)
        else:
            self.logger.debug("%s (again, %d in this episode)", message, count + 1)

    def recovered(self, *kinds: str) -> None:
        if not self.active:
            return
        for kind in kinds:
            count = self.active.pop(kind, 0)
            if count:
                message = f"{kind} cleared after {count} failure(s)"
                self.logger.info("%s", message)
                if self.on_event is not None:
                    self.on_event(BoardEvent.RECOVERED, message)


def _command_name(line: str) -> str:
    parts = line.split(None, 1)
    return parts[0].upper() if parts else ""


class ProtocolCore:
    """One request in flight, CR framing, timeouts on an injected clock, resynchronisation.

    Thread-safe: concurrent callers are serialised.  ``clock`` returns integer nanoseconds.
    """

    def __init__(self, link: Link, *, clock: Callable[[], int] = time.monotonic_ns,
                 timeout_s: float = 0.25, resync_quiet_s: float | None = None,
                 poll_s: float = 0.02, logger: logging.Logger | None = None,
                 on_event: EventCallback | None = None) -> None:
        self.link = link
        self.clock = clock
        self.timeout_s = timeout_s
        self.resync_quiet_s = timeout_s if resync_quiet_s is None else resync_quiet_s
        self.poll_s = poll_s
        self.logger = logger or _log
        self._episodes = _Episodes(self.logger, on_event)
        self._lock = threading.RLock()
        self._rx = bytearray()
        self._dirty = False
        self._generation_seen = link.generation
        self._reconnected = False
        self._interrupt = threading.Event()

    # --- state -----------------------------------------------------------------------------

    def interrupt(self) -> None:
        """Abandon the request in flight (thread-safe; no lock taken): it raises
        :class:`BoardInterrupted` within one read slice (``poll_s``). The flag stays set
        until the next :meth:`request` with ``urgent=True`` or :meth:`clear_interrupt`."""
        self._interrupt.set()

    def clear_interrupt(self) -> None:
        """Forget an :meth:`interrupt` that found nothing to abandon."""
        self._interrupt.clear()

    def mark_dirty(self) -> None:
        """Force a resynchronisation before the next request."""
        self._dirty = True

    def rearm_reconnect(self) -> None:
        """Make :meth:`take_reconnect` report the reconnect again (handshake failed)."""
        self._reconnected = True

    def take_reconnect(self) -> bool:
        """True once after the link reconnected (the board may have been power-cycled)."""
        with self._lock:
            self._check_generation()
            flag, self._reconnected = self._reconnected, False
            return flag

    @property
    def faults(self) -> dict[str, int]:
        """Fault kinds of the current episode and how often each has happened."""
        return dict(self._episodes.active)

    def _check_generation(self) -> None:
        generation = self.link.generation
        if generation != self._generation_seen:
            if self._generation_seen:
                self._reconnected = True
                self._dirty = True
                self._episodes.recovered("link")
                if self._episodes.on_event is not None:
                    self._episodes.on_event(BoardEvent.LINK_RESTORED, f"generation {generation}")
            self._generation_seen = generation

    # --- requests --------------------------------------------------------------------------

    def raw(self, line: str, *, timeout_s: float | None = None) -> str:
        """Send ``line`` and return the reply text without its CR (``ERROR`` is not raised)."""
        return self.request(line, lambda reply: reply, timeout_s=timeout_s)

    def request(self, line: str, parse: Callable[[str], T], *,
                timeout_s: float | None = None, urgent: bool = False) -> T:
        """Send ``line`` (no CR), wait for one CR-terminated reply and ``parse`` it.

        Raises :class:`BoardTimeout`, :class:`LinkLost`, :class:`ReplyFormatError` (garbled
        reply; the core resynchronises before the next request), :class:`BoardInterrupted`
        (see :meth:`interrupt`) or whatever ``parse`` raises (typically a
        :class:`FirmwareError`).

        ``urgent`` (stops): no resynchronisation quiet window first. The line goes out at
        once behind a CR that ends any partial line on the board, and replies that ``parse``
        rejects — a late reply to an abandoned request, an ``ERROR`` for the partial line —
        are skipped until one it accepts arrives or the timeout passes.
        """
        if "\r" in line or "\x00" in line:
            raise ValueError("a request line must not contain CR or NUL")
        timeout = self.timeout_s if timeout_s is None else timeout_s
        command = _command_name(line)
        with self._lock:
            self._check_generation()
            if urgent:
                self._interrupt.clear()
                return self._urgent(line, command, parse, timeout)
            try:
                if self._dirty:
                    self._resync()
                else:
                    self.link.discard_input()
                self._rx.clear()
                self.link.write(line.encode("ascii") + b"\r")
                reply = self._read_reply(command, timeout)
            except LinkLost as exc:
                self._dirty = True
                self._episodes.fault("link", BoardEvent.LINK_LOST, f"board link lost: {exc}")
                raise
            except BoardTimeout as exc:
                self._dirty = True
                self._episodes.fault("timeout", BoardEvent.TIMEOUT, str(exc))
                raise
            except (ReplyFormatError, BoardInterrupted) as exc:
                self._dirty = True
                if isinstance(exc, ReplyFormatError):
                    self._episodes.fault("garbled", BoardEvent.GARBLED, str(exc))
                raise
            self._episodes.recovered("link", "timeout")
            try:
                result = parse(reply)
            except ReplyFormatError as exc:
                self._dirty = True
                self._episodes.fault("garbled", BoardEvent.GARBLED, str(exc))
                raise
            except FirmwareError as exc:
                self._episodes.recovered("garbled")
                self._episodes.fault(f"firmware {command}", BoardEvent.FIRMWARE_ERROR,
                                     str(exc))
                raise
            self._episodes.recovered("garbled", f"firmware {command}")
            return result

    def _urgent(self, line: str, command: str, parse: Callable[[str], T], timeout_s: float) -> T:
        was_dirty = self._dirty
        self._dirty = True  # until a reply proves the line is in step again
        self._rx.clear()
        try:
            self.link.discard_input()
            self.link.write(b"\r" + line.encode("ascii") + b"\r")
            deadline = self.clock() + round(timeout_s * 1e9)
            rejected: Exception | None = None
            while True:
                remaining = (deadline - self.clock()) / 1e9
                try:
                    frame = self._read_reply(command, max(remaining, 0.0), interruptible=False)
                except BoardTimeout:
                    if isinstance(rejected, FirmwareError):
                        raise rejected from None
                    raise
                try:
                    result = parse(frame)
                except (ReplyFormatError, FirmwareError) as exc:
                    rejected = exc  # a late reply, or the board's answer to a partial line
                    if self.link.synchronous and not self._rx:
                        raise
                    continue
                if not self._rx:
                    self._dirty = False
                elif not was_dirty:
                    self._dirty = True
                self._episodes.recovered("link", "timeout", "garbled")
                return result
        except LinkLost as exc:
            self._episodes.fault("link", BoardEvent.LINK_LOST, f"board link lost: {exc}")
            raise
        except BoardTimeout as exc:
            self._episodes.fault("timeout", BoardEvent.TIMEOUT, str(exc))
            raise

    def _take_frame(self, command: str) -> str | None:
        end = self._rx.find(b"\r")
        if end < 0:
            return None
        frame = bytes(self._rx[:end])
        if len(self._rx) > end + 1:
            self._dirty = True  # more than one reply: resync before the next request
        del self._rx[:end + 1]
        return self._decode_frame(command, frame)

    def _read_reply(self, command: str, timeout_s: float, *, interruptible: bool = True) -> str:
        if self.link.synchronous:
            # The reply (if any) was produced inside the write.
            self._rx += self.link.read(0.0)
            frame = self._take_frame(command)
            if frame is None:
                raise BoardTimeout(command, timeout_s)
            return frame
        start = self.clock()
        deadline = start + round(timeout_s * 1e9)
        stalled = 0
        last_now = start
        while True:
            frame = self._take_frame(command)
            if frame is not None:
                return frame
            if interruptible and self._interrupt.is_set():
                raise BoardInterrupted(command)
            now = self.clock()
            if now >= deadline:
                raise BoardTimeout(command, timeout_s)
            remaining = (deadline - now) / 1e9
            data = self.link.read(min(self.poll_s, remaining))
            if data:
                self._rx += data
                if len(self._rx) > 4096:
                    raise ReplyFormatError(command, self._rx[:64].decode("latin-1"),
                                           "a CR within 4096 bytes")
                continue
            # Guard against a clock that does not move (never hang).
            stalled = stalled + 1 if now == last_now else 0
            last_now = now
            if stalled > 10_000:
                raise BoardTimeout(command, timeout_s)

    @staticmethod
    def _decode_frame(command: str, frame: bytes) -> str:
        if not _PRINTABLE.fullmatch(frame):
            raise ReplyFormatError(command, frame.decode("latin-1"), "printable ASCII")
        return frame.decode("ascii")

    def _resync(self) -> None:
        """Terminate any partial line on the board and discard input until quiet."""
        self.link.discard_input()
        self.link.write(b"\r")
        quiet_ns = round(self.resync_quiet_s * 1e9)
        now = self.clock()
        quiet_until = now + quiet_ns
        give_up = now + 4 * quiet_ns
        discarded = 0
        stalled = 0
        while not self.link.synchronous:
            if self._interrupt.is_set():
                raise BoardInterrupted("resync")
            now = self.clock()
            if now >= quiet_until or now >= give_up:
                break
            data = self.link.read(min(self.poll_s, (quiet_until - now) / 1e9))
            if data:
                discarded += len(data)
                quiet_until = self.clock() + quiet_ns
                stalled = 0
            else:
                stalled += 1
                if stalled > 10_000:
                    break
        self.link.discard_input()
        self._rx.clear()
        self._dirty = False
        self.logger.debug("resynchronised, %d stale byte(s) discarded", discarded)
        if discarded and self._episodes.on_event is not None:
            self._episodes.on_event(BoardEvent.RESYNC, f"{discarded} stale byte(s) discarded")


class Board:
    """The typed control-board API the base nodes call.

    Units: wheel distances in positions, speeds in positions/s, acceleration in
    positions/s², ``ping()`` in raw firmware units (0 = no echo), ``adc()`` in raw counts;
    ``turn``/``heading`` in radians, counter-clockwise positive (REP-103).

    Call :meth:`start` first; it reads ``VER`` and adopts the firmware's ranges.  After a
    reconnect the handshake (``VER``, ``VERB``, ``SPNG`` and the last ``ACC``) is repeated
    automatically before the next command; motion commands are not replayed.
    """

    def __init__(self, link: Link, *, clock: Callable[[], int] = time.monotonic_ns,
                 timeout_s: float = 0.25, resync_quiet_s: float | None = None,
                 poll_s: float = 0.02, logger: logging.Logger | None = None,
                 on_event: EventCallback | None = None,
                 profile: FirmwareProfile = FIRMWARE_1_1) -> None:
        self.link = link
        self.core = ProtocolCore(link, clock=clock, timeout_s=timeout_s,
                                 resync_quiet_s=resync_quiet_s, poll_s=poll_s, logger=logger,
                                 on_event=on_event)
        self.profile = profile
        self.firmware_version: int | None = None
        self._verbose_errors = True
        self._ping_mask: int | None = PING_MASK
        self._acceleration: int | None = None
        self._lock = threading.RLock()
        self._in_handshake = False
        #: profile to use whatever ``VER`` answers (a board with a custom version word)
        self.forced_profile: FirmwareProfile | None = None
        #: send ``WATCH 1`` in the handshake on firmware that has it
        self.watchdog = True

    # --- lifecycle -------------------------------------------------------------------------

    def start(self, *, verbose_errors: bool = True,
              ping_mask: int | None = PING_MASK) -> FirmwareProfile:
        """Open the link, read ``VER`` and adopt that firmware's parameter ranges.

        With ``verbose_errors`` the board is put in ``VERB 1`` so errors carry reasons;
        ``ping_mask`` (default ``SPNG 6``: Eddie's two PING))) sensors) is applied unless
        ``None``.  Returns the adopted profile.
        """
        self._verbose_errors = verbose_errors
        self._ping_mask = ping_mask
        self.link.open()
        with self._lock:
            self.core.take_reconnect()
            self._handshake()
        return self.profile

    def close(self) -> None:
        """Close the link (does not stop the motors; call :meth:`stop` first)."""
        self.link.close()

    def _handshake(self) -> None:
        self._in_handshake = True
        try:
            version = self.core.request(protocol.encode_ver(),
                                        lambda r: protocol.decode_word("VER", r))
            self.firmware_version = version
            self.profile = self.forced_profile or profile_for_version(version)
            if self._verbose_errors:
                self.core.request(protocol.encode_verb(1),
                                  lambda r: protocol.decode_empty("VERB", r))
            if self._ping_mask is not None:
                self.core.request(protocol.encode_spng(self._ping_mask),
                                  lambda r: protocol.decode_empty("SPNG", r))
            if self.profile.has_watch and self.watchdog:
                # FW 1.3 arms WATCH at power-on; say so explicitly, a reboot may not have run
                self.core.request(protocol.encode_watch(True, self.profile),
                                  lambda r: protocol.decode_empty("WATCH", r))
            if self._acceleration is not None:
                # A reconnect may follow a power cycle, which resets ACC to its default.
                try:
                    line = protocol.encode_acc(self._acceleration, self.profile)
                except ParameterRangeError:
                    self._acceleration = None  # not valid on the firmware now connected
                else:
                    self.core.request(line, lambda r: protocol.decode_empty("ACC", r))
        finally:
            self._in_handshake = False

    def _call(self, line: str, parse: Callable[[str], T]) -> T:
        with self._lock:
            if not self._in_handshake and self.core.take_reconnect():
                try:
                    self._handshake()
                except Exception:
                    self.core.rearm_reconnect()
                    raise
            return self.core.request(line, parse)

    def _action(self, line: str) -> None:
        name = _command_name(line)
        self._call(line, lambda r: protocol.decode_empty(name, r))

    # --- queries ---------------------------------------------------------------------------

    def version(self) -> int:
        """``VER``: the firmware version word."""
        return self._call(protocol.encode_ver(), lambda r: protocol.decode_word("VER", r))

    def hardware_version(self) -> int:
        """``HWVER``: the board's hardware version word."""
        return self._call(protocol.encode_hwver(), lambda r: protocol.decode_word("HWVER", r))

    def distance(self) -> tuple[int, int]:
        """``DIST``: (left, right) positions since the last reset, forward positive."""
        return self._call(protocol.encode_dist(), protocol.decode_dist)

    def speed(self) -> tuple[int, int]:
        """``SPD``: (left, right) speeds in positions/s, averaged over 0.5 s."""
        return self._call(protocol.encode_spd(), protocol.decode_spd)

    def heading_degrees_cw(self) -> int:
        """``HEAD`` as the firmware reports it: degrees, clockwise positive, (−360, 360)."""
        return self._call(protocol.encode_head(), protocol.decode_head)

    def heading(self) -> float:
        """Heading since the last reset in radians, REP-103 (counter-clockwise positive),
        wrapped to (−π, π].  Resolution ≈ 1.94° (one position of L−R)."""
        angle = math.radians(-self.heading_degrees_cw())
        wrapped = math.atan2(math.sin(angle), math.cos(angle))
        return math.pi if wrapped == -math.pi else wrapped

    def ping(self) -> tuple[int, ...]:
        """``PING``: raw readings per enabled pin, lowest pin first (Eddie: left, right).

        Units ≈ 1.1 mm; 0 = no echo (convert with ``ping_units_to_range_m``)."""
        return self._call(protocol.encode_ping(), protocol.decode_ping)

    def adc(self) -> tuple[int, ...]:
        """``ADC``: 8 raw counts, 0..0xFFF ↔ 0..5 V (IR on 0..2, battery/3.21 on 7)."""
        return self._call(protocol.encode_adc(), protocol.decode_adc)

    # --- motion ----------------------------------------------------------------------------

    def go_speed(self, left: int, right: int) -> None:
        """``GOSPD``: closed-loop wheel speeds in positions/s (forward positive)."""
        self._action(protocol.encode_gospd(left, right))

    def stop_now(self) -> None:
        """``STOP 0`` as an urgent request: no resynchronisation wait and no reconnect
        handshake first (see :meth:`ProtocolCore.request`); cuts motor power."""
        with self._lock:
            self.core.request(protocol.encode_stop(0),
                              lambda r: protocol.decode_empty("STOP", r), urgent=True)

    def hold_now(self) -> None:
        """``GOSPD 0 0`` as an urgent request: closed-loop hold at zero speed, ramped at ACC."""
        with self._lock:
            self.core.request(protocol.encode_gospd(0, 0),
                              lambda r: protocol.decode_empty("GOSPD", r), urgent=True)

    def go_power(self, left: int, right: int) -> None:
        """``GO``: open-loop motor power, −127..127 per wheel."""
        self._action(protocol.encode_go(left, right))

    def stop(self, distance: int = 0) -> None:
        """``STOP``: stop within ``distance`` positions; 0 cuts motor power (ramped, ≤ 0.32 s)."""
        self._action(protocol.encode_stop(distance))

    def travel(self, distance: int, speed: int) -> None:
        """``TRVL``: drive straight ``distance`` positions (signed) at ``speed`` positions/s."""
        self._action(protocol.encode_trvl(distance, speed, self.profile))

    def turn(self, angle_rad: float, speed: int) -> None:
        """Spin in place by ``angle_rad`` (REP-103: positive = counter-clockwise).

        Sent as ``TURN`` with the angle negated and rounded to whole degrees; ``speed`` is the
        wheel speed in positions/s (1..127 on FW 1.1, 1..255 on FW 1.3).
        """
        degrees_cw = -round(math.degrees(angle_rad))
        self._action(protocol.encode_turn(degrees_cw, speed, self.profile))

    def set_acceleration(self, rate: int) -> None:
        """``ACC``: speed-change limit in positions/s² (re-applied after a reconnect)."""
        self._action(protocol.encode_acc(rate, self.profile))
        self._acceleration = rate

    def reset(self) -> None:
        """``RST``: zero the distance counters and the heading."""
        self._action(protocol.encode_rst())

    def watch(self, enabled: bool) -> None:
        """``WATCH``: arm/disarm the 1 s serial watchdog (FW 1.3 only; refused on 1.1)."""
        self._action(protocol.encode_watch(enabled, self.profile))

    def set_ping_mask(self, mask: int) -> None:
        """``SPNG``: pins running PING))) sensors (kept across reconnects)."""
        self._action(protocol.encode_spng(mask))
        self._ping_mask = mask

    def raw(self, line: str) -> str:
        """Send any command line; return the reply without CR (``ERROR`` returned as text)."""
        return self._call(line, lambda reply: reply)
