"""The emulated board on a real serial path: :class:`TimedWire`, the link between a host and
a :class:`~eddiebot.robot.emulator.FirmwareEmulator` as slow as Eddie's (115,200 baud, the
FTDI latency timer, PING's 25 ms; :mod:`eddiebot.robot.timing`), and :class:`PtyServer`,
which serves the emulator on a pseudo-terminal through that wire and reboots it when a
client opens the port, as the DTR line does on the real board.
"""

from __future__ import annotations

import contextlib
import ctypes
import errno
import os
import select
import struct
import threading
import time
import tty
from collections import deque

from eddiebot.robot.emulator import FirmwareEmulator
from eddiebot.robot.timing import (
    DEFAULT_TIMING,
    LinkTiming,
    byte_time_s,
    processing_s,
    usb_hold_s,
)

__all__ = ["PtyServer", "TimedWire"]


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
