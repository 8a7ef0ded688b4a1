"""The link timing model, the timed wire around the emulator, and the pty server's timing and
reboot on open (wall clock, generous bounds)."""

from __future__ import annotations

import contextlib
import threading
import time
from collections.abc import Callable, Iterator

import pytest
import serial

from eddiebot.robot import pty_server
from eddiebot.robot.board import Board
from eddiebot.robot.emulator import FirmwareEmulator
from eddiebot.robot.links import SerialLink
from eddiebot.robot.pty_server import PtyServer, TimedWire
from eddiebot.robot.timing import (
    DEFAULT_TIMING,
    NO_TIMING,
    LinkTiming,
    byte_time_s,
    processing_s,
    reply_delay_s,
    usb_hold_s,
)

T = LinkTiming()
DIST_REPLY = b"00000000 00000000\r"  # 18 bytes
PING_REPLY = b"557 71E \r"  # two sensors, FW 1.1 trailing space: 9 bytes
ADC_REPLY = b"0F4 0F4 0F4 000 000 000 000 3D4\r"  # 32 bytes
MS = 1e-3


# --- the pure model -------------------------------------------------------------------------


def test_byte_time_is_ten_bits_at_115200_baud() -> None:
    assert T == DEFAULT_TIMING
    assert (T.baud, T.ftdi_latency_s, T.usb_frame_s, T.ping_block_s) == (115200, 0.016, 0.001,
                                                                           0.025)
    assert byte_time_s(T, 1) == pytest.approx(86.806e-6, rel=1e-4)
    assert byte_time_s(T, 18) == pytest.approx(1.5625 * MS)
    assert byte_time_s(NO_TIMING, 18) == 0.0


def test_reply_delays_of_the_polled_commands() -> None:
    # DIST: 1 ms USB frame + 5 bytes (0.434 ms) + 18 bytes (1.5625 ms) + 16 ms latency timer.
    dist = reply_delay_s(T, b"DIST\r", DIST_REPLY, "DIST")
    assert dist == pytest.approx((1 + 0.4340 + 1.5625 + 16) * MS, abs=1e-6)
    # PING adds the firmware's 25 ms wait for the echoes.
    ping = reply_delay_s(T, b"PING\r", PING_REPLY, "PING")
    assert ping == pytest.approx((1 + 0.4340 + 25 + 0.78125 + 16) * MS, abs=1e-6)
    adc = reply_delay_s(T, b"ADC\r", ADC_REPLY, "ADC")
    assert adc == pytest.approx((1 + 0.3472 + 2.7778 + 16) * MS, abs=1e-6)
    # Back to back, one at a time: ≈ 82 ms a cycle, ≈ 12 Hz at best.
    assert 1.0 / (dist + ping + adc) == pytest.approx(12.15, abs=0.05)
    assert reply_delay_s(NO_TIMING, b"PING\r", PING_REPLY, "PING") == 0.0


def test_ping_blocks_only_when_it_measures() -> None:
    assert processing_s(T, "PING", PING_REPLY) == 0.025
    assert processing_s(T, "ping", b"ERROR - Too many parameters\r") == 0.0
    assert processing_s(T, "PING", b"\r") == 0.0  # no sensor enabled
    assert processing_s(T, "DIST", DIST_REPLY) == 0.0


def test_ftdi_latency_applies_unless_the_reply_fills_whole_packets() -> None:
    assert usb_hold_s(T, 61) == 0.016
    assert usb_hold_s(T, 62) == 0.0  # one full 62-byte packet goes out at once
    assert usb_hold_s(T, 124) == 0.0
    assert usb_hold_s(T, 70) == 0.016  # the 8-byte tail waits for the timer
    assert usb_hold_s(T, 0) == 0.0
    long_reply = b"0" * 61 + b"\r"
    assert reply_delay_s(T, b"X\r", long_reply, "X") == pytest.approx(
        T.usb_frame_s + byte_time_s(T, 64), abs=1e-9)


# --- the timed wire on a simulated clock ----------------------------------------------------


def test_timed_wire_holds_each_reply_until_the_host_could_read_it() -> None:
    wire = TimedWire(FirmwareEmulator(), T)
    wire.host_wrote(0, b"DIST\r")
    due = round(reply_delay_s(T, b"DIST\r", DIST_REPLY, "DIST") * 1e9)
    assert wire.next_event_ns() == round((0.001 + 5 / 11520) * 1e9)  # the CR reaches the board
    assert wire.replies_until(due - 1) == []
    assert wire.next_event_ns() == due
    assert wire.replies_until(due) == [DIST_REPLY]
    assert wire.next_event_ns() is None


def test_timed_wire_a_ping_holds_back_the_next_command() -> None:
    emu = FirmwareEmulator()
    emu.feed(b"SPNG 6\r")
    wire = TimedWire(emu, T)
    wire.host_wrote(0, b"PING\rDIST\r")  # two requests written at once
    ping_due = round(reply_delay_s(T, b"PING\r", PING_REPLY, "PING") * 1e9)
    assert wire.replies_until(ping_due - 1) == []
    assert wire.replies_until(ping_due) == [PING_REPLY]
    # DIST waited in the UART buffer for the 25 ms, then went out after PING's reply.
    dist_due = round((1 + 0.4340 + 25 + 0.78125 + 1.5625 + 16) * 1e6)
    assert wire.replies_until(dist_due - 2_000) == []
    assert wire.replies_until(dist_due + 2_000) == [DIST_REPLY]


def test_timed_wire_writes_queue_on_the_uart() -> None:
    wire = TimedWire(FirmwareEmulator(), T)
    wire.host_wrote(0, b"VER\r")
    wire.host_wrote(0, b"VER\r")  # the second waits for the first on the wire
    first = round((0.001 + 4 / 11520 + 5 / 11520 + 0.016) * 1e9)
    assert wire.replies_until(first - 1) == []
    assert wire.replies_until(first) == [b"0070\r"]
    # The second reply goes out on the UART right after the first: 5 byte times later.
    second = first + round(5 / 11520 * 1e9)
    assert wire.replies_until(second - 1) == []
    assert wire.replies_until(second) == [b"0070\r"]


def test_timed_wire_without_timing_answers_at_once_and_drops_input_while_booting() -> None:
    emu = FirmwareEmulator()
    wire = TimedWire(emu, NO_TIMING)
    wire.host_wrote(0, b"VER\r")
    assert wire.replies_until(0) == [b"0070\r"]
    emu.reboot(1_000, boot_s=0.5)
    wire.host_wrote(2_000, b"VER\r")
    assert wire.replies_until(round(0.4e9)) == []
    wire.host_wrote(round(0.6e9), b"VER\r")
    assert wire.replies_until(round(0.6e9)) == [b"0070\r"]


# --- the pty server, wall clock ---------------------------------------------------------------


@contextlib.contextmanager
def _serving(server: PtyServer) -> Iterator[PtyServer]:
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield server
    finally:
        server.stop()
        thread.join(timeout=5)
    assert not thread.is_alive()


@pytest.fixture
def timed_server() -> Iterator[PtyServer]:
    with _serving(PtyServer(FirmwareEmulator(), poll_s=0.005,
                            timing=LinkTiming(boot_s=0.0))) as server:
        yield server


def _min_round_trip(call: Callable[[], object], n: int = 5) -> float:
    best = float("inf")
    for _ in range(n):
        t0 = time.perf_counter()
        call()
        best = min(best, time.perf_counter() - t0)
    return best


def test_round_trips_over_the_pty_take_as_long_as_on_the_board(timed_server: PtyServer) -> None:
    board = Board(SerialLink(timed_server.device_path), timeout_s=1.0)
    try:
        board.start()
        assert board.ping() == (1367, 1822)
        for call, request, reply, name in ((board.distance, b"DIST\r", DIST_REPLY, "DIST"),
                                           (board.ping, b"PING\r", PING_REPLY, "PING"),
                                           (board.adc, b"ADC\r", ADC_REPLY, "ADC")):
            model = reply_delay_s(T, request, reply, name)
            measured = _min_round_trip(call)
            # Never earlier than the model (the server only adds delay); the best of five
            # within 2x of it even on a loaded machine.
            assert 0.95 * model <= measured <= 2.0 * model, (name, measured, model)
    finally:
        board.close()


def test_no_timing_answers_at_once() -> None:
    with _serving(PtyServer(FirmwareEmulator(), poll_s=0.005, timing=NO_TIMING)) as server:
        board = Board(SerialLink(server.device_path), timeout_s=1.0)
        try:
            board.start()
            model = reply_delay_s(T, b"DIST\r", DIST_REPLY, "DIST")
            assert _min_round_trip(board.distance) < model / 2
        finally:
            board.close()


def _ask_until_answered(port: serial.Serial, line: bytes, deadline_s: float) -> tuple[bytes, float]:
    """Send ``line`` every read timeout until a reply comes; (reply, when it came).

    Then wait a little and drop anything else, so a late duplicate reply cannot be taken
    for the answer to the next request.
    """
    end = time.monotonic() + deadline_s
    timeout, port.timeout = port.timeout, 0.15
    try:
        while time.monotonic() < end:
            port.write(line)
            reply = port.read_until(b"\r")
            if reply:
                answered = time.monotonic()
                time.sleep(0.1)
                port.reset_input_buffer()
                return reply, answered
    finally:
        port.timeout = timeout
    pytest.fail(f"no reply to {line!r} within {deadline_s} s")


def _wait_for(predicate: Callable[[], bool], deadline_s: float = 2.0) -> None:
    end = time.monotonic() + deadline_s
    while not predicate():
        if time.monotonic() > end:
            pytest.fail("condition not reached")
        time.sleep(0.005)


def test_opening_the_port_reboots_the_board() -> None:
    boot_s = 0.4
    emu = FirmwareEmulator()
    emu.feed(b"TRVL 64 7F\r")  # drive 100 positions before anyone connects
    emu.step(3.0)
    assert emu.feed(b"DIST\r") == b"00000064 00000064\r"
    timing = LinkTiming(boot_s=boot_s)
    with _serving(PtyServer(emu, poll_s=0.005, timing=timing)) as server:
        opened = time.monotonic()
        port = serial.serial_for_url(server.device_path, baudrate=115200, timeout=1.0)
        try:
            port.write(b"DIST\r")  # at once: lost while the Propeller boots
            port.timeout = 0.15
            assert port.read_until(b"\r") == b""
            port.timeout = 1.0
            reply, answered = _ask_until_answered(port, b"DIST\r", 3.0)
            assert reply == b"00000000 00000000\r"  # counters zeroed by the reset
            assert answered - opened >= boot_s
            assert server.opens == 1
            port.write(b"GO 7F 7F\r")
            assert port.read_until(b"\r") == b"\r"
            time.sleep(0.3)
            port.write(b"DIST\r")
            assert port.read_until(b"\r") != b"00000000 00000000\r"  # the wheels turned
        finally:
            port.close()
        _wait_for(lambda: not server.client_connected)
        port = serial.serial_for_url(server.device_path, baudrate=115200, timeout=1.0)
        try:
            reply, _ = _ask_until_answered(port, b"DIST\r", 3.0)
            assert reply == b"00000000 00000000\r"  # reset again, and the motors stopped
            assert server.opens == 2
            time.sleep(0.1)
            port.write(b"DIST\r")
            assert port.read_until(b"\r") == b"00000000 00000000\r"
        finally:
            port.close()


def test_a_quick_close_and_reopen_still_reboots() -> None:
    emu = FirmwareEmulator()
    with _serving(PtyServer(emu, poll_s=0.005, timing=LinkTiming(boot_s=0.1))) as server:
        if server.open_detection != "inotify":
            pytest.skip("inotify not available: opens are polled")
        port = serial.serial_for_url(server.device_path, baudrate=115200, timeout=1.0)
        try:
            _ask_until_answered(port, b"DIST\r", 3.0)
            port.write(b"VER\r")  # its reply is still on the way when the port closes
        finally:
            port.close()
        port = serial.serial_for_url(server.device_path, baudrate=115200, timeout=1.0)
        try:
            _wait_for(lambda: server.opens == 2)
            reply, _ = _ask_until_answered(port, b"DIST\r", 3.0)
            assert reply == b"00000000 00000000\r"  # not the stale "0070"
        finally:
            port.close()


def test_opens_are_seen_by_polling_without_inotify(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(pty_server._OpenWatch, "create",
                        classmethod(lambda cls, path: None))
    emu = FirmwareEmulator()
    with _serving(PtyServer(emu, poll_s=0.005, timing=LinkTiming(boot_s=0.1))) as server:
        assert server.open_detection == "poll"
        for opens in (1, 2):
            port = serial.serial_for_url(server.device_path, baudrate=115200, timeout=1.0)
            try:
                reply, _ = _ask_until_answered(port, b"DIST\r", 3.0)
                assert reply == b"00000000 00000000\r"
                assert server.opens == opens
            finally:
                port.close()
            _wait_for(lambda: not server.client_connected)


def test_reboot_on_open_can_be_turned_off() -> None:
    emu = FirmwareEmulator()
    emu.feed(b"TRVL 64 7F\r")
    emu.step(3.0)
    with _serving(PtyServer(emu, poll_s=0.005, reboot_on_open=False)) as server:
        port = serial.serial_for_url(server.device_path, baudrate=115200, timeout=0.5)
        try:
            port.write(b"DIST\r")
            assert port.read_until(b"\r") == b"00000064 00000064\r"
        finally:
            port.close()
