"""Every way `eddie launch bringup` can end puts a stop on the wire: a real process, a real
serial link (the emulator on a pty, with the wire's timing), a real signal."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time

import pytest

from eddiebot.robot.constants import FIRMWARE_1_1
from eddiebot.robot.emulator import FirmwareEmulator
from eddiebot.robot.pty_server import PtyServer


class _Recorder:
    """The emulator behind the pty, logging (wall time, line) of what reached it."""

    def __init__(self) -> None:
        self.emulator = FirmwareEmulator(FIRMWARE_1_1)
        self.lines: list[tuple[float, bytes]] = []
        feed = self.emulator.feed

        def recording_feed(data: bytes) -> bytes:
            now = time.monotonic()
            self.lines.extend((now, part.strip()) for part in data.split(b"\r") if part.strip())
            return feed(data)

        self.emulator.feed = recording_feed  # type: ignore[method-assign]
        self.server = PtyServer(self.emulator)
        self.thread = threading.Thread(target=self.server.serve_forever, daemon=True)
        self.thread.start()

    def wait_for(self, word: bytes, after: float, timeout_s: float) -> float | None:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            for t, line in list(self.lines):
                if t >= after and line.startswith(word):
                    return t
            time.sleep(0.005)
        return None

    def close(self) -> None:
        self.server.stop()
        self.thread.join(timeout=2.0)


@pytest.mark.parametrize("sig", [signal.SIGHUP, signal.SIGQUIT, signal.SIGINT, signal.SIGTERM],
                         ids=lambda s: signal.Signals(s).name)
def test_each_signal_puts_a_stop_on_the_wire(sig):
    board = _Recorder()
    env = dict(os.environ, EDDIE_TRANSPORT="none")
    proc = subprocess.Popen(
        [sys.executable, "-m", "eddiebot.cli.main", "launch", "bringup",
         f"port:={board.server.device_path}"],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=env)
    try:
        assert board.wait_for(b"DIST", 0.0, 60.0) is not None, "the driver never polled"
        board.emulator.plant.set_velocity(40, 40)  # the board runs a GOSPD
        time.sleep(0.3)
        sent = time.monotonic()
        proc.send_signal(sig)
        stopped = board.wait_for(b"STOP 0", sent, 5.0)
        assert stopped is not None, f"no STOP 0 after {signal.Signals(sig).name}"
        assert stopped - sent < 1.0  # 0.3 s is the target; docs/benchmarks/robot.md has figures
        assert proc.wait(timeout=20) in (0, -sig, 128 + sig)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        board.close()
