"""Real byte streams: the pty server with the serial link, a socket:// link that reconnects,
and the ``eddie board`` / ``eddie emulator`` commands."""

from __future__ import annotations

import argparse
import contextlib
import socket
import threading
from collections.abc import Iterator

import pytest

from eddiebot.cli import board as board_cli
from eddiebot.cli import emulator as emulator_cli
from eddiebot.robot import errors
from eddiebot.robot.board import Board, BoardEvent
from eddiebot.robot.constants import FIRMWARE_1_3
from eddiebot.robot.emulator import FirmwareEmulator
from eddiebot.robot.links import SerialLink
from eddiebot.robot.pty_server import PtyServer
from eddiebot.robot.timing import NO_TIMING


@pytest.fixture
def pty_server() -> Iterator[PtyServer]:
    # Instant boot and no link delays: these tests are about the driver and the CLI; the
    # link model and the reboot on open are tested in test_robot_timing.py.
    server = PtyServer(FirmwareEmulator(), poll_s=0.005, timing=NO_TIMING)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    yield server
    server.stop()
    thread.join(timeout=5)
    assert not thread.is_alive()


def test_pty_round_trip_with_serial_link(pty_server: PtyServer) -> None:
    assert pty_server.device_path.startswith("/dev/")
    link = SerialLink(pty_server.device_path)
    board = Board(link, timeout_s=1.0)
    try:
        assert board.start().name == "1.1"
        assert board.version() == 0x70
        assert board.distance() == (0, 0)
        assert board.ping() == (1367, 1822)
        assert len(board.adc()) == 8
        board.go_speed(10, 10)
        board.stop(0)
        assert board.raw("BOGUS") == "ERROR - Invalid command"
        for _ in range(50):
            assert board.version() == 0x70
    finally:
        board.close()


def test_board_cli_against_pty(pty_server: PtyServer, capsys: pytest.CaptureFixture[str]) -> None:
    parser = argparse.ArgumentParser()
    board_cli.add_arguments(parser)
    assert board_cli.run(parser.parse_args(["--port", pty_server.device_path, "VER"])) == 0
    assert capsys.readouterr().out == "0070\n"
    args = parser.parse_args(["--port", pty_server.device_path, "-v", "GOSPD", "1"])
    assert board_cli.run(args) == 1
    assert capsys.readouterr().out == "ERROR - Too few parameters\n"
    assert board_cli.run(parser.parse_args(["--port", "/dev/nonexistent-eddie", "VER"])) == 2


def test_emulator_cli_arguments() -> None:
    parser = argparse.ArgumentParser()
    emulator_cli.add_arguments(parser)
    args = parser.parse_args(["--firmware", "1.3"])
    assert args.firmware == "1.3" and args.counts_per_rev == 36
    with pytest.raises(SystemExit):
        parser.parse_args(["--firmware", "2.0"])


class _TcpBoard:
    """An emulated board behind a TCP port; ``drop()`` cuts the current connection."""

    def __init__(self) -> None:
        self.emulator = FirmwareEmulator(FIRMWARE_1_3)
        self.emulator.watch_enabled = False
        self.listener = socket.create_server(("127.0.0.1", 0))
        self.port = self.listener.getsockname()[1]
        self.conn: socket.socket | None = None
        self.accepting = threading.Event()
        self.accepting.set()
        self.connections = 0
        self._stop = False
        self.thread = threading.Thread(target=self._serve, daemon=True)
        self.thread.start()

    def _serve(self) -> None:
        self.listener.settimeout(0.05)
        while not self._stop:
            if not self.accepting.is_set():
                self.accepting.wait(0.05)
                continue
            try:
                conn, _ = self.listener.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            if not self.accepting.is_set():
                conn.close()
                continue
            self.conn = conn
            self.connections += 1
            conn.settimeout(0.05)
            while not self._stop:
                try:
                    data = conn.recv(4096)
                except TimeoutError:
                    continue
                except OSError:
                    break
                if not data:
                    break
                reply = self.emulator.feed(data)
                if reply:
                    with contextlib.suppress(OSError):
                        conn.sendall(reply)
            with contextlib.suppress(OSError):
                conn.close()

    def drop(self) -> None:
        self.accepting.clear()
        if self.conn is not None:
            with contextlib.suppress(OSError):
                self.conn.shutdown(socket.SHUT_RDWR)

    def close(self) -> None:
        self._stop = True
        self.drop()
        self.listener.close()
        self.thread.join(timeout=5)


def test_socket_link_reconnects_when_the_port_returns() -> None:
    tcp = _TcpBoard()
    events: list[BoardEvent] = []
    link = SerialLink(f"socket://127.0.0.1:{tcp.port}", reconnect_interval_s=0.05)
    board = Board(link, timeout_s=0.5, resync_quiet_s=0.05,
                  on_event=lambda e, d: events.append(e))
    try:
        assert board.start().name == "1.3"
        assert board.version() == 0x0D
        tcp.drop()
        failures = 0
        for _ in range(100):  # until the reader notices the closed socket
            try:
                board.version()
            except (errors.LinkLost, errors.BoardTimeout):
                failures += 1
                break
            threading.Event().wait(0.02)
        assert failures == 1
        tcp.accepting.set()
        for _ in range(200):
            try:
                assert board.version() == 0x0D
                break
            except (errors.LinkLost, errors.BoardTimeout):
                threading.Event().wait(0.02)
        else:
            pytest.fail("link never came back")
        assert tcp.connections == 2
        assert link.generation == 2
        assert BoardEvent.LINK_RESTORED in events
        assert board.distance() == (0, 0)
    finally:
        board.close()
        tcp.close()


def test_emulator_command_prints_path_first_and_stops_on_sigterm() -> None:
    import signal
    import subprocess
    import sys

    proc = subprocess.Popen([sys.executable, "-m", "eddiebot.cli.emulator", "--firmware", "1.3"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None
        path = proc.stdout.readline().strip()
        assert path.startswith("/dev/")
        link = SerialLink(path)
        core_board = Board(link, timeout_s=0.5, resync_quiet_s=0.05)
        try:
            # Opening the port reboots the board (DTR): it ignores input for 1.5 s.
            for _ in range(10):
                try:
                    assert core_board.start().name == "1.3"
                    break
                except errors.BoardTimeout:
                    continue
            else:
                pytest.fail("the emulated board never answered after its boot")
        finally:
            core_board.close()
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=10) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
