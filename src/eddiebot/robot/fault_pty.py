"""An emulated board on a real pty, with faults on the wire: for tests and benchmarks that
must exercise the real serial path (pyserial, the reader thread, reconnection).

:class:`FaultyPtyBoard` serves a :class:`~eddiebot.robot.emulator.FirmwareEmulator` on a
pseudo-terminal (with the wire's timing and the DTR reboot on open, as
:class:`~eddiebot.robot.pty_server.PtyServer` does), reachable through a stable symlink
(:attr:`port`) the way udev names a board ``/dev/eddie``. It logs every line that reaches
the board with its wall time (:attr:`lines`) and can

* lose the next line(s) that match (``lose(b"STOP 0")``),
* go mute (``mute = True``: nothing reaches the board, nothing comes back),
* vanish and come back (:meth:`vanish` closes the pty, :meth:`restore` serves a new one at
  the same symlink: the port disappears and returns, as an unplugged USB cable does).
"""

from __future__ import annotations

import os
import tempfile
import threading
import time
from pathlib import Path

from eddiebot.robot.constants import FIRMWARE_1_1, FirmwareProfile
from eddiebot.robot.emulator import FirmwareEmulator
from eddiebot.robot.pty_server import PtyServer

__all__ = ["FaultyPtyBoard"]


class FaultyPtyBoard:
    """The emulated board behind a pty, with a log of what reached it and wire faults."""

    def __init__(self, profile: FirmwareProfile = FIRMWARE_1_1, *,
                 directory: str | Path | None = None) -> None:
        self.emulator = FirmwareEmulator(profile)
        self.lines: list[tuple[float, bytes]] = []
        self.mute = False
        self._lose: list[bytes] = []
        self._lock = threading.Lock()
        self._dir = Path(directory) if directory is not None else Path(tempfile.mkdtemp())
        self.port = str(self._dir / "eddie")
        feed = self.emulator.feed

        def faulty_feed(data: bytes) -> bytes:
            now = time.monotonic()
            parts = [p.strip() for p in data.split(b"\r") if p.strip()]
            with self._lock:
                self.lines.extend((now, p) for p in parts)
                lost = [p for p in parts if p in self._lose]
                for p in lost:
                    self._lose.remove(p)
            if self.mute or lost:
                return b""
            return feed(data)

        self.emulator.feed = faulty_feed  # type: ignore[method-assign]
        self._server: PtyServer | None = None
        self._thread: threading.Thread | None = None
        self.restore()

    def lose(self, line: bytes, count: int = 1) -> None:
        """Lose the next ``count`` lines equal to ``line`` on their way to the board."""
        with self._lock:
            self._lose.extend([line] * count)

    def first(self, words: tuple[bytes, ...], after: float, timeout_s: float = 5.0) -> float | None:
        """Wall time of the first logged line in ``words`` (exact match, or a prefix ending
        in a space) at or after ``after``, waiting up to ``timeout_s``; None if none came."""
        deadline = time.monotonic() + timeout_s
        while True:
            with self._lock:
                for t, line in self.lines:
                    if t >= after and any(line == w or line.startswith(w + b" ") for w in words):
                        return t
            if time.monotonic() >= deadline:
                return None
            time.sleep(0.002)

    def vanish(self) -> None:
        """Close the pty and remove the symlink: the port is gone."""
        server, self._server = self._server, None
        if server is not None:
            server.stop()
        if self._thread is not None:
            self._thread.join(2.0)
            self._thread = None
        if os.path.lexists(self.port):
            os.unlink(self.port)

    def restore(self) -> None:
        """Serve the board on a new pty behind the same symlink (a DTR reboot on open)."""
        if self._server is not None:
            return
        self._server = PtyServer(self.emulator)
        tmp = self.port + ".new"
        if os.path.lexists(tmp):
            os.unlink(tmp)
        os.symlink(self._server.device_path, tmp)
        os.replace(tmp, self.port)
        self._thread = threading.Thread(target=self._server.serve_forever, daemon=True,
                                        name="faulty-pty-board")
        self._thread.start()

    def close(self) -> None:
        """Stop serving (idempotent)."""
        self.vanish()
