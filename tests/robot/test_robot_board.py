"""The driver: typed API on the in-process link, fault scenarios on the fault-injecting link."""

from __future__ import annotations

import logging
import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from eddiebot.robot import errors, protocol
from eddiebot.robot.board import Board, BoardEvent, ProtocolCore
from eddiebot.robot.constants import FIRMWARE_1_1, FIRMWARE_1_3
from eddiebot.robot.emulator import FirmwareEmulator
from eddiebot.robot.fault_link import (
    Delay,
    Drop,
    FakeClock,
    FaultyLink,
    Garbage,
    RandomFaults,
    Silence,
    Split,
    Vanish,
)
from eddiebot.robot.links import EmulatorLink


class SimClock:
    def __init__(self) -> None:
        self.now_ns = 0

    def __call__(self) -> int:
        return self.now_ns


def make_board(profile=FIRMWARE_1_1):  # type: ignore[no-untyped-def]
    clock = SimClock()
    emu = FirmwareEmulator(profile)
    board = Board(EmulatorLink(emu, clock), clock=clock)
    board.start()
    return board, emu, clock


def test_start_adopts_firmware_and_configures() -> None:
    board, emu, _ = make_board(FIRMWARE_1_1)
    assert board.profile is FIRMWARE_1_1 and board.firmware_version == 0x70
    assert emu.verbose and emu.ping_mask == 0x6
    assert board.ping() == (1367, 1822)
    board13, _, _ = make_board(FIRMWARE_1_3)
    assert board13.profile is FIRMWARE_1_3
    board13.travel(10, 0xFF)  # allowed on 1.3 only
    with pytest.raises(errors.ParameterRangeError):
        board.travel(10, 0xFF)


def test_out_of_range_is_refused_before_anything_is_sent() -> None:
    board, emu, _ = make_board()
    sent: list[bytes] = []
    feed = emu.feed

    def spy(data: bytes) -> bytes:
        sent.append(data)
        return feed(data)

    emu.feed = spy  # type: ignore[method-assign]
    with pytest.raises(errors.ParameterRangeError):
        board.go_speed(40000, 0)
    with pytest.raises(errors.UnsupportedCommandError):
        board.watch(True)
    with pytest.raises(errors.ParameterRangeError):
        board.set_acceleration(0x200)
    assert sent == []


def test_rep103_turn_and_heading_in_the_api_only() -> None:
    board, emu, clock = make_board()
    board.reset()
    board.turn(math.pi / 2, 0x40)  # counter-clockwise 90°
    clock.now_ns += 3_000_000_000
    assert board.distance() == (-23, 23)
    assert board.heading_degrees_cw() == -89  # firmware: clockwise positive
    assert board.heading() == pytest.approx(math.radians(89))
    assert emu.plant.true_pose[2] > 0
    board.turn(-math.pi, 0x40)  # clockwise 180°
    clock.now_ns += 5_000_000_000
    assert board.heading() == pytest.approx(math.radians(-89))


def test_api_round_trip_on_sim_clock() -> None:
    board, emu, clock = make_board()
    assert board.version() == 0x70
    assert board.hardware_version() == 2
    board.set_acceleration(100)
    board.go_speed(30, 30)
    clock.now_ns += 2_000_000_000
    left, right = board.speed()
    assert left == right == pytest.approx(30, abs=2)
    board.stop(0)
    board.go_power(10, -10)
    board.stop(5)
    assert len(board.adc()) == 8
    assert board.raw("FOO") == "ERROR - Invalid command"
    with pytest.raises(errors.InvalidCommandError):
        board.core.request("FOO", lambda r: board_check(r))


def board_check(reply: str) -> str:
    from eddiebot.robot.protocol import check_reply

    return check_reply("FOO", reply)


def test_firmware_errors_are_typed() -> None:
    board, emu, _ = make_board()
    emu.encoder_running = False
    with pytest.raises(errors.EncoderError):
        board.distance()
    with pytest.raises(errors.EncoderError):
        board.go_speed(1, 1)


def test_watch_on_firmware_1_3() -> None:
    board, emu, clock = make_board(FIRMWARE_1_3)
    board.watch(False)
    assert not emu.watch_enabled
    board.watch(True)
    board.go_speed(20, 20)
    clock.now_ns += 1_500_000_000
    board.distance()  # advances the emulator past the watchdog
    assert emu.plant.wheel_velocities == (0.0, 0.0)


# --- fault injection ---------------------------------------------------------------------


def faulty_board(**kw):  # type: ignore[no-untyped-def]
    clock = FakeClock()
    emu = FirmwareEmulator()
    link = FaultyLink(emu, clock, **kw)
    events: list[tuple[BoardEvent, str]] = []
    board = Board(link, clock=clock, timeout_s=0.1,
                  on_event=lambda e, d: events.append((e, d)))
    board.start()
    return board, link, clock, events


def test_reply_split_across_reads_is_reassembled() -> None:
    board, link, _, _ = faulty_board()
    link.inject(Split(5), Split(2), Split(18))
    assert board.distance() == (0, 0)
    assert board.version() == 0x70
    assert len(board.adc()) == 8


def test_late_reply_is_never_paired_with_the_next_request() -> None:
    board, link, clock, events = faulty_board()
    link.inject(Delay(0.15))  # VER answer arrives 50 ms after the timeout
    with pytest.raises(errors.BoardTimeout):
        board.raw("HWVER")
    # The next request must get its own reply, not the late "0002".
    assert board.raw("VER") == "0070"
    assert board.raw("HWVER") == "0002"
    assert clock.now_ns < 1_000_000_000
    assert BoardEvent.TIMEOUT in [e for e, _ in events]
    assert BoardEvent.RESYNC in [e for e, _ in events]


def test_garbage_and_dropped_bytes_raise_then_recover() -> None:
    board, link, _, _ = faulty_board()
    link.inject(Garbage(b"\xfe\x01"))
    with pytest.raises(errors.ReplyFormatError):
        board.distance()
    assert board.distance() == (0, 0)
    link.inject(Drop(3))
    with pytest.raises(errors.ReplyFormatError):
        board.distance()
    link.inject(Drop(cr=True))
    with pytest.raises(errors.BoardTimeout):
        board.version()
    assert board.version() == 0x70
    link.inject(Garbage(b"junk\r", before=False))
    assert board.version() == 0x70
    assert board.raw("HWVER") == "0002"


def test_silence_times_out_on_the_injected_clock() -> None:
    board, link, clock, _ = faulty_board()
    link.inject(Silence())
    t0 = clock()
    with pytest.raises(errors.BoardTimeout):
        board.distance()
    assert clock() - t0 == pytest.approx(100_000_000, abs=2_000_000)


def test_port_vanishing_mid_command_and_returning() -> None:
    board, link, clock, events = faulty_board()
    link.inject(Vanish(0.5))
    with pytest.raises(errors.LinkLost):
        board.distance()
    with pytest.raises(errors.LinkLost):
        board.distance()
    clock.advance(0.6)
    writes_before = len(link.writes)
    assert board.distance() == (0, 0)
    # After the reconnect the handshake is repeated before the command.
    resent = b"".join(link.writes[writes_before:])
    assert resent.index(b"VER\r") < resent.index(b"DIST\r")
    kinds = [e for e, _ in events]
    assert kinds.count(BoardEvent.LINK_LOST) == 1
    assert BoardEvent.LINK_RESTORED in kinds


def test_each_fault_is_logged_once_per_episode(caplog: pytest.LogCaptureFixture) -> None:
    board, link, clock, events = faulty_board()
    caplog.set_level(logging.DEBUG, logger="eddiebot.robot.board")
    link.inject(*[Silence()] * 10)
    for _ in range(10):
        with pytest.raises(errors.BoardTimeout):
            board.distance()
    warnings = [r for r in caplog.records if r.levelno == logging.WARNING]
    assert len(warnings) == 1
    assert board.distance() == (0, 0)
    infos = [r for r in caplog.records if r.levelno == logging.INFO]
    assert len(infos) == 1 and "10" in infos[0].getMessage()
    link.inject(Silence())
    with pytest.raises(errors.BoardTimeout):
        board.distance()
    assert len([r for r in caplog.records if r.levelno == logging.WARNING]) == 2
    assert [e for e, _ in events].count(BoardEvent.TIMEOUT) == 2


@settings(max_examples=100, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_random_faults_never_hang_never_mispair(seed: int) -> None:
    clock = FakeClock()
    emu = FirmwareEmulator()
    emu.feed(b"GOSPD 20 -20\r")
    link = FaultyLink(emu, clock, seed=seed, random_faults=RandomFaults(
        drop=0.08, garbage=0.08, delay=0.08, split=0.15, silence=0.05, vanish=0.03,
        delay_s=0.13, vanish_down_s=0.2))
    core = ProtocolCore(link, clock=clock, timeout_s=0.1)
    link.open()
    # VER and HWVER replies have the same shape: a mis-pairing would decode "successfully"
    # with the other command's value.  DIST has left > 0 > right (the robot spins).
    parsers = {
        "VER": lambda r: protocol.decode_word("VER", r),
        "HWVER": lambda r: protocol.decode_word("HWVER", r),
        "INS": lambda r: protocol.decode_mask("INS", r),
        "DIST": protocol.decode_dist,
    }
    expected = {"VER": 0x70, "HWVER": 0x2, "INS": 0x70000}
    ok = 0
    for i in range(60):
        command = ("VER", "HWVER", "INS", "DIST")[i % 4]
        try:
            value = core.request(command, parsers[command])
        except (errors.BoardTimeout, errors.ReplyFormatError, errors.LinkLost):
            clock.advance(0.05)
            continue
        ok += 1
        if command == "DIST":
            assert isinstance(value, tuple)
            assert value[0] >= 0 >= value[1] and value[0] == -value[1], value
        else:
            assert value == expected[command], (command, value)
    assert ok > 20
    assert clock() < 60 * 2_000_000_000  # bounded: never hangs


def test_core_rejects_cr_in_request() -> None:
    board, _, _ = make_board()
    with pytest.raises(ValueError, match="CR"):
        board.raw("VER\rDIST")


def test_handshake_after_reconnect_reapplies_acceleration_and_retries() -> None:
    board, link, clock, _ = faulty_board()
    board.set_acceleration(0x64)
    link.emulator.plant.set_acceleration(200)  # as after a power cycle
    link.vanish(0.2)
    with pytest.raises(errors.LinkLost):
        board.distance()
    clock.advance(0.3)
    link.inject(Silence())  # the handshake's VER goes unanswered: retried next time
    with pytest.raises(errors.BoardTimeout):
        board.distance()
    assert board.distance() == (0, 0)
    assert link.emulator.plant.acceleration == 0x64
    assert b"ACC 64\r" in link.writes[-3:]


def test_board_session_on_sim_clock_is_deterministic() -> None:
    def session() -> tuple[list[object], tuple[float, float, float]]:
        board, emu, clock = make_board()
        out: list[object] = []
        board.set_acceleration(150)
        board.go_speed(60, 40)
        for _ in range(40):
            clock.now_ns += 50_000_000
            out += [board.distance(), board.speed(), board.heading(), board.ping(), board.adc()]
        board.turn(-1.0, 0x30)
        for _ in range(40):
            clock.now_ns += 50_000_000
            out.append(board.distance())
        return out, emu.plant.true_pose

    first, second = session(), session()
    assert first == second
    assert first[0][-1] != (0, 0)  # the robot moved
