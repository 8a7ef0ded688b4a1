"""Links that carry bytes between the board driver and a control board (real or emulated).

A :class:`Link` moves bytes only; framing, timeouts and pairing live in
:class:`eddiebot.robot.board.ProtocolCore`.

* :class:`SerialLink`: pyserial, 115200 8N1, on ``/dev/tty*``, ptys and ``socket://`` URLs
  (``serial.serial_for_url``); a reader thread collects input and reopens the port when it
  vanishes and returns.
* :class:`EmulatorLink`: in-process and synchronous: the emulator produces the reply inside
  :meth:`EmulatorLink.write`, on the caller's (simulation) clock.
* :class:`TimedEmulatorLink`: the same, and it adds up how long each exchange would take on
  Eddie's real wire (:mod:`eddiebot.robot.timing`: 115,200 baud, the FTDI latency timer,
  PING's blocking time, timeouts for replies that never come), so a scheduler on sim time
  can hold the link busy as long as the board would; it can also lose commands on the
  wire, for fault-injection tests.
"""

from __future__ import annotations

import contextlib
import logging
import os
import threading
from collections.abc import Callable
from typing import Any, Protocol

import serial

from eddiebot.robot.constants import BAUD_RATE
from eddiebot.robot.emulator import FirmwareEmulator
from eddiebot.robot.errors import LinkLost
from eddiebot.robot.timing import LinkTiming, reply_delay_s

__all__ = ["EmulatorLink", "Link", "SerialLink", "TimedEmulatorLink"]

_log = logging.getLogger(__name__)


def _keep_dtr_on_close(port: Any) -> None:
    """Clear HUPCL on a real tty, so closing the port does not drop DTR.

    Opening a tty raises DTR, and the board's reset circuit reboots the Propeller on that edge
    (counters zeroed, ~1.5 s deaf: the driver handles it). Without HUPCL the line stays up
    between a close and the next open, so a reconnect does not reboot the board again."""
    fd = getattr(port, "fd", None)
    if not isinstance(fd, int):
        return
    try:
        import termios

        attrs = termios.tcgetattr(fd)
        attrs[2] &= ~termios.HUPCL
        termios.tcsetattr(fd, termios.TCSANOW, attrs)
    except (ImportError, OSError, termios.error):  # a pty or a platform without termios
        pass


def ftdi_latency_ms(device: str) -> int | None:
    """The FTDI latency timer (ms) of a ``/dev/ttyUSB*`` device, or None if not an FTDI."""
    try:
        name = os.path.basename(os.path.realpath(device))
        with open(f"/sys/bus/usb-serial/devices/{name}/latency_timer") as f:
            return int(f.read().strip())
    except (OSError, ValueError):
        return None


def warn_ftdi_latency(device: str) -> None:
    """Warn once when an FTDI adapter runs its shipped 16 ms latency timer: every reply then
    waits up to 16 ms in the chip, and the poll rate falls to ~13 Hz."""
    latency = ftdi_latency_ms(device)
    if latency is not None and latency > 2:
        _log.warning(
            "%s: the FTDI latency timer is %d ms, so every board reply waits up to that long "
            "(poll rate ~13 Hz). Set it to 1 ms: echo 1 | sudo tee "
            "/sys/bus/usb-serial/devices/%s/latency_timer, or the udev rule in the README.",
            device, latency, os.path.basename(os.path.realpath(device)))


class Link(Protocol):
    """Byte transport to a control board.

    ``synchronous`` links produce every reply inside :meth:`write`: an empty :meth:`read`
    then means no reply will ever come.  ``generation`` increases each time the link
    (re)connects, so the protocol core can tell a board that may have been power-cycled.
    """

    @property
    def synchronous(self) -> bool:
        """True when replies are produced inside ``write``."""
        ...

    @property
    def generation(self) -> int:
        """Connection counter: 0 before the first open, +1 per (re)connect."""
        ...

    def open(self) -> None:
        """Connect; raise :class:`LinkLost` if the board cannot be reached."""
        ...

    def close(self) -> None:
        """Disconnect and stop background work (idempotent)."""
        ...

    def write(self, data: bytes) -> None:
        """Send bytes; raise :class:`LinkLost` if the link is down."""
        ...

    def read(self, max_wait_s: float) -> bytes:
        """Bytes received so far, waiting up to ``max_wait_s`` for the first one.

        Returns ``b""`` if nothing arrived; raises :class:`LinkLost` if the link is down.
        """
        ...

    def discard_input(self) -> None:
        """Drop everything received and not yet read."""
        ...


class EmulatorLink:
    """Synchronous in-process link to a :class:`FirmwareEmulator`.

    ``clock_ns`` (optional) returns the simulation time in integer nanoseconds; the emulator
    is advanced to it before each write.  Without it the emulator's time is left to the owner.
    """

    synchronous = True

    def __init__(self, emulator: FirmwareEmulator,
                 clock_ns: Callable[[], int] | None = None) -> None:
        self.emulator = emulator
        self.clock_ns = clock_ns
        self._rx = bytearray()
        self._generation = 0

    @property
    def generation(self) -> int:
        """1 once opened."""
        return self._generation

    def open(self) -> None:
        """Nothing to connect."""
        if self._generation == 0:
            self._generation = 1

    def close(self) -> None:
        """Nothing to release."""

    def write(self, data: bytes) -> None:
        """Feed the emulator; its reply becomes readable at once."""
        if self.clock_ns is not None:
            self.emulator.advance_to_ns(self.clock_ns())
        self._rx += self.emulator.feed(data)

    def read(self, max_wait_s: float) -> bytes:
        """The pending reply bytes (never waits)."""
        out = bytes(self._rx)
        self._rx.clear()
        return out

    def discard_input(self) -> None:
        """Drop pending reply bytes."""
        self._rx.clear()


class TimedEmulatorLink(EmulatorLink):
    """An :class:`EmulatorLink` that accounts for the real wire's time.

    Each :meth:`write` adds to :attr:`elapsed_ns` the time from the host's write until the
    whole reply is readable on the host (:func:`~eddiebot.robot.timing.reply_delay_s`), or
    ``reply_timeout_s`` when no reply comes, or ``resync_quiet_s`` for a lone CR (the driver
    waits for a quiet line after one). A scheduler reads it with :meth:`take_elapsed_ns`.

    Fault injection: :meth:`lose` drops the next write(s) of a command on the wire (the
    board never sees them); ``mute`` drops every write.
    """

    def __init__(self, emulator: FirmwareEmulator, clock_ns: Callable[[], int] | None = None, *,
                 timing: LinkTiming | None = None, reply_timeout_s: float = 0.25,
                 resync_quiet_s: float | None = None) -> None:
        super().__init__(emulator, clock_ns)
        self.timing = timing if timing is not None else LinkTiming()
        self.reply_timeout_s = reply_timeout_s
        self.resync_quiet_s = reply_timeout_s if resync_quiet_s is None else resync_quiet_s
        self.elapsed_ns = 0
        self.mute = False
        self.writes: list[tuple[int, bytes]] = []
        """(emulator time ns, line) of the last 200 lines that reached the board (tests)."""
        self._lose: dict[str, int] = {}

    def open(self) -> None:
        """Connect; the first open reboots the board as a DTR pulse does (unless the timing
        model is off), so it is deaf for ``timing.boot_s``."""
        first = self._generation == 0
        super().open()
        if first and self.timing.boot_s > 0:
            now = self.clock_ns() if self.clock_ns is not None else self.emulator.time_ns
            self.emulator.reboot(now, boot_s=self.timing.boot_s)

    def lose(self, command: str, count: int = 1) -> None:
        """Lose the next ``count`` writes that carry ``command`` (e.g. ``"STOP"``)."""
        self._lose[command.upper()] = self._lose.get(command.upper(), 0) + count

    def take_elapsed_ns(self) -> int:
        """Wire time accumulated since the last call; resets it."""
        out, self.elapsed_ns = self.elapsed_ns, 0
        return out

    def write(self, data: bytes) -> None:
        """Feed the emulator (unless lost) and account for the wire time."""
        lines = [part for part in data.split(b"\r") if part.strip()]
        if not lines:
            if self.clock_ns is not None:
                self.emulator.advance_to_ns(self.clock_ns())
            self.emulator.feed(data)
            self.elapsed_ns += round(self.resync_quiet_s * 1e9)
            return
        command = lines[0].split()[0].decode("latin-1").upper()
        if self.mute or self._lose.get(command, 0) > 0:
            if not self.mute:
                self._lose[command] -= 1
            self.elapsed_ns += round(self.reply_timeout_s * 1e9)
            return
        before = len(self._rx)
        super().write(data)
        reply = bytes(self._rx[before:])
        self.writes.append((self.emulator.time_ns, lines[-1]))
        del self.writes[:-200]
        if reply:
            self.elapsed_ns += round(reply_delay_s(self.timing, data, reply, command) * 1e9)
        else:
            self.elapsed_ns += round(self.reply_timeout_s * 1e9)


class SerialLink:
    """pyserial link (115200 8N1, no flow control) with a reader thread and reconnection.

    ``url`` is a device path (``/dev/ttyUSB0``, a pty) or any pyserial URL
    (``socket://host:port``).  When the port fails (unplugged, pty closed) the reader thread
    closes it, :meth:`write`/:meth:`read` raise :class:`LinkLost`, and the thread retries
    opening every ``reconnect_interval_s`` until it succeeds or :meth:`close` is called.
    """

    synchronous = False

    def __init__(self, url: str, *, baudrate: int = BAUD_RATE,
                 reconnect_interval_s: float = 0.5, write_timeout_s: float = 1.0,
                 serial_factory: Callable[..., Any] = serial.serial_for_url) -> None:
        self.url = url
        self.baudrate = baudrate
        self.reconnect_interval_s = reconnect_interval_s
        self.write_timeout_s = write_timeout_s
        self._factory = serial_factory
        self._port: Any = None
        self._rx = bytearray()
        self._cond = threading.Condition()
        self._closing = threading.Event()
        self._thread: threading.Thread | None = None
        self._generation = 0
        self._write_lock = threading.Lock()

    @property
    def generation(self) -> int:
        """Number of successful (re)connects."""
        return self._generation

    @property
    def connected(self) -> bool:
        """Whether the port is currently open."""
        return self._port is not None

    def _open_port(self) -> Any:
        port = self._factory(self.url, baudrate=self.baudrate, bytesize=serial.EIGHTBITS,
                             parity=serial.PARITY_NONE, stopbits=serial.STOPBITS_ONE,
                             timeout=0.05, write_timeout=self.write_timeout_s,
                             xonxoff=False, rtscts=False, dsrdtr=False, do_not_open=True)
        port.open()
        with contextlib.suppress(Exception):
            port.reset_input_buffer()
        _keep_dtr_on_close(port)
        return port

    def open(self) -> None:
        """Open the port and start the reader thread; :class:`LinkLost` if it cannot open."""
        if self._thread is not None:
            return
        try:
            port = self._open_port()
        except (serial.SerialException, OSError, ValueError) as exc:
            raise LinkLost(f"cannot open {self.url}: {exc}") from exc
        with self._cond:
            self._port = port
            self._generation += 1
        warn_ftdi_latency(self.url)
        self._closing.clear()
        self._thread = threading.Thread(target=self._reader, name=f"serial-{self.url}",
                                        daemon=True)
        self._thread.start()

    def close(self) -> None:
        """Stop the reader thread and close the port."""
        self._closing.set()
        thread, self._thread = self._thread, None
        if thread is not None:
            thread.join(timeout=2.0)
        self._drop_port()

    def _drop_port(self) -> None:
        with self._cond:
            port, self._port = self._port, None
            self._cond.notify_all()
        if port is not None:
            with contextlib.suppress(Exception):
                port.close()

    def _reader(self) -> None:
        while not self._closing.is_set():
            port = self._port
            if port is None:
                if self._closing.wait(self.reconnect_interval_s):
                    break
                try:
                    port = self._open_port()
                except (serial.SerialException, OSError, ValueError):
                    continue
                with self._cond:
                    self._port = port
                    self._rx.clear()
                    self._generation += 1
                    self._cond.notify_all()
                _log.info("serial port %s is back", self.url)
                continue
            try:
                data = port.read(1)
                if data:
                    waiting = port.in_waiting
                    if waiting:
                        data += port.read(waiting)
            except Exception:  # pyserial raises SerialException, OSError, TypeError
                if self._closing.is_set():
                    break
                _log.debug("serial port %s failed", self.url, exc_info=True)
                self._drop_port()
                continue
            if data:
                with self._cond:
                    self._rx += data
                    self._cond.notify_all()

    def write(self, data: bytes) -> None:
        """Write all bytes; :class:`LinkLost` if the port is gone or fails."""
        port = self._port
        if port is None:
            raise LinkLost(f"{self.url} is not connected")
        try:
            with self._write_lock:
                port.write(data)
        except Exception as exc:
            self._drop_port()
            raise LinkLost(f"write to {self.url} failed: {exc}") from exc

    def read(self, max_wait_s: float) -> bytes:
        """Received bytes, waiting up to ``max_wait_s`` for the first."""
        with self._cond:
            if not self._rx and self._port is not None and max_wait_s > 0:
                self._cond.wait(max_wait_s)
            if self._rx:
                out = bytes(self._rx)
                self._rx.clear()
                return out
            if self._port is None:
                raise LinkLost(f"{self.url} is not connected")
            return b""

    def discard_input(self) -> None:
        """Drop received bytes, including what the OS still buffers."""
        with self._cond:
            self._rx.clear()
            port = self._port
        if port is not None:
            with contextlib.suppress(Exception):
                port.reset_input_buffer()
