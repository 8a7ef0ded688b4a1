"""The firmware emulator: line discipline, command set, motion, sensors, watchdog, fuzzing."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from eddiebot.robot import protocol
from eddiebot.robot.constants import FIRMWARE_1_1, FIRMWARE_1_3, PING_METRES_PER_UNIT
from eddiebot.robot.emulator import FirmwareEmulator, FixedSensors


def ask(emu: FirmwareEmulator, line: str) -> str:
    reply = emu.feed(line.encode("latin-1") + b"\r")
    assert reply.endswith(b"\r") and reply.count(b"\r") == 1, reply
    return reply[:-1].decode("latin-1")


@pytest.fixture
def emu() -> FirmwareEmulator:
    e = FirmwareEmulator()
    e.feed(b"VERB 1\r")
    return e


# --- line discipline -----------------------------------------------------------------------


def test_basic_replies() -> None:
    e = FirmwareEmulator()
    assert e.feed(b"VER\r") == b"0070\r"
    assert e.feed(b"hwver\r") == b"0002\r"
    assert e.feed(b"\r") == b""  # empty line: no reply
    assert e.feed(b" \r") == b"ERROR\r"  # blanks only: invalid command
    assert e.feed(b"VER\tX\r") == b"ERROR\r"
    assert FirmwareEmulator(FIRMWARE_1_3).feed(b"VER\r") == b"000D\r"


def test_verbose_reasons(emu: FirmwareEmulator) -> None:
    assert ask(emu, "FOO") == "ERROR - Invalid command"
    assert ask(emu, "GO 1") == "ERROR - Too few parameters"
    assert ask(emu, "VER 1") == "ERROR - Too many parameters"
    assert ask(emu, "GO 1G 2") == "ERROR - Invalid parameter"
    assert ask(emu, "ACC 123456789") == "ERROR - Invalid parameter"  # 9 hex digits
    assert ask(emu, "GO zz") == "ERROR - Invalid parameter"  # first fault found decides
    assert ask(emu, "VERB 0") == ""
    assert ask(emu, "FOO") == "ERROR"


def test_case_separators_backspace_and_ignored_characters(emu: FirmwareEmulator) -> None:
    assert ask(emu, "gospd\t a  \t-") == "ERROR - Invalid parameter"
    assert ask(emu, "gospd\t a  \tb") == ""
    assert ask(emu, "VEX\x08R") == "0070"
    assert ask(emu, "\x08\x08VER") == "0070"
    e13 = FirmwareEmulator(FIRMWARE_1_3)
    assert ask(e13, "V\x01E\nR\x7f\xff\x1b") == "000D"  # FW 1.3 drops control bytes
    assert e13.feed(b"\n\x0b\x0c") == b""
    assert ask(e13, "GOSPD 10\n 10\n") == ""


def test_firmware_1_1_keeps_control_bytes_in_the_line(emu: FirmwareEmulator) -> None:
    # The FW 1.1 source stores every byte before its (empty) case for control characters.
    assert ask(emu, "V\x01E\nR\x7f\xff\x1b") == "ERROR - Invalid command"
    assert ask(emu, "VER\n") == "ERROR - Invalid command"  # a stray LF (CR LF line ends)
    assert ask(emu, "\nVER") == "ERROR - Invalid command"  # the LF left over from "...\r\n"
    assert ask(emu, "GOSPD 10 10\n") == "ERROR - Invalid parameter"  # not a blank: in "10\n"
    assert ask(emu, "DIST \n") == "ERROR - Too many parameters"
    assert ask(emu, "VER\n\x08") == "0070"  # BS deletes the kept byte
    assert emu.feed(b"\n\x0b\x0c") == b""  # no CR yet: no reply, but they stay ...
    assert ask(emu, "VER") == "ERROR - Invalid command"  # ... and spoil the next line
    assert FirmwareEmulator().feed(b"VER\r\n") == b"0070\r"  # LF alone waits for a CR


def test_eight_hex_digits_accepted_nine_refused(emu: FirmwareEmulator) -> None:
    assert ask(emu, "STOP 00000000") == ""
    assert ask(emu, "STOP 000000000") == "ERROR - Invalid parameter"


def test_overflow() -> None:
    e = FirmwareEmulator()
    assert e.feed(b"V" * 253 + b"\r") == b"ERROR\r"  # a 253-character line is parsed
    # The 255th byte fills the buffer (it holds 254 bytes plus terminator) → Overflow; the
    # board then discards everything up to the next CR and answers once.
    assert e.feed(b"V" * 254) == b""
    assert e.feed(b"more junk") == b""
    assert e.feed(b"\r") == b"ERROR\r"
    assert e.feed(b"VER\r") == b"0070\r"
    e.feed(b"VERB 1\r")
    assert e.feed(b"x" * 300 + b"\r") == b"ERROR - Overflow\r"


def test_checksum_mode(emu: FirmwareEmulator) -> None:
    line = b"VER\x00"
    good = sum(line).to_bytes(2, "big")
    reply = emu.feed(line + good)
    assert reply == b"0070\x00" + sum(b"0070").to_bytes(2, "big")
    bad = emu.feed(line + b"\x00\x00")
    assert bad.startswith(b"ERROR - Bad checksum\x00")


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=600))
def test_fuzz_arbitrary_bytes_never_crash(data: bytes) -> None:
    e = FirmwareEmulator()
    reply = e.feed(data)
    assert isinstance(reply, bytes)
    # The parser always returns to a clean state: after the line ends, VER works.
    e.feed(b"\r\x00\x00\r")
    assert e.feed(b"VER\r") == b"0070\r"


_NAMES = st.sampled_from([*protocol.COMMANDS, "BLNK"])
_BLANK = st.sampled_from([" ", "\t", "  ", " \t "])


@settings(max_examples=300, deadline=None)
@given(st.text(alphabet=st.characters(min_codepoint=0x21, max_codepoint=0x7E), min_size=1,
               max_size=12))
def test_fuzz_unknown_commands_get_error(name: str) -> None:
    e = FirmwareEmulator()
    line = name.encode()
    if name.upper() in set(protocol.COMMANDS) | {"BLNK"}:
        return
    assert e.feed(line + b"\r").startswith(b"ERROR")


@settings(max_examples=300, deadline=None)
@given(_NAMES, st.lists(st.text(alphabet="0123456789abcdefABCDEFxyz-+", min_size=1,
                                max_size=10), max_size=4), _BLANK)
def test_fuzz_malformed_parameters_get_error(name: str, params: list[str], blank: str) -> None:
    arity = {"HWVER": 0, "VER": 0, "VERB": 1, "WATCH": 1, "BLINK": 2, "BLNK": 2, "IN": 1,
             "OUT": 1, "LOW": 1, "HIGH": 1, "INS": 0, "OUTS": 0, "LOWS": 0, "HIGHS": 0,
             "READ": 0, "SPNG": 1, "SGP": 1, "PING": 0, "ADC": 0, "GO": 2, "GOSPD": 2,
             "STOP": 1, "TRVL": 2, "TURN": 2, "ACC": 1, "SPD": 0, "HEAD": 0, "DIST": 0,
             "RST": 0}[name]
    well_formed = len(params) == arity and all(
        len(p) <= 8 and all(ch in "0123456789abcdefABCDEF" for ch in p) for p in params)
    if well_formed:
        return
    e = FirmwareEmulator(FIRMWARE_1_3 if name == "WATCH" else FIRMWARE_1_1)
    line = blank.join([name, *params]) if params else name
    assert e.feed(line.encode() + b"\r").startswith(b"ERROR"), line


# --- commands --------------------------------------------------------------------------------


def test_turn_360_moves_each_wheel_93_positions(emu: FirmwareEmulator) -> None:
    ask(emu, "RST")
    assert ask(emu, "TURN 168 7F") == ""
    emu.step(5.0)
    assert protocol.decode_dist(ask(emu, "DIST")) == (93, -93)
    assert emu.plant.wheel_positions == pytest.approx((93.0, -93.0))
    # Ideal drive with a 0.39 m track: 186 positions of L-R is 363.4° clockwise.
    assert emu.plant.true_pose[2] == pytest.approx(math.radians(-3.4), abs=math.radians(0.1))


def test_head_after_clockwise_turn_is_positive_on_the_wire(emu: FirmwareEmulator) -> None:
    assert ask(emu, "TURN 5A 40") == ""  # 90° clockwise
    emu.step(3.0)
    head = ask(emu, "HEAD")
    assert head == "059"  # 2·23 positions → 89°
    assert protocol.decode_head(head) == 89
    assert emu.plant.true_pose[2] < 0  # clockwise is negative in REP-103
    assert ask(emu, "TURN FF4C 40") == ""  # −180° (counter-clockwise)
    emu.step(5.0)
    assert protocol.decode_head(ask(emu, "HEAD")) == -89  # 12-bit sign: FA7
    assert ask(emu, "HEAD") == "FA7"


def test_acc_bounds_the_ramp_seen_in_spd(emu: FirmwareEmulator) -> None:
    assert ask(emu, "ACC 64") == ""  # 100 positions/s²
    ask(emu, "GOSPD 50 50")  # 80 positions/s
    speeds = []
    for _ in range(20):
        emu.step(0.1)
        speeds.append(protocol.decode_spd(ask(emu, "SPD"))[0])
    steps = [b - a for a, b in zip(speeds, speeds[1:])]
    assert max(steps) <= 10 + 4  # 100 pos/s² · 0.1 s, plus count quantisation
    assert speeds[7] < 60  # still ramping after 0.8 s
    assert speeds[-1] == pytest.approx(80, abs=2)
    assert emu.plant.wheel_velocities == pytest.approx((80.0, 80.0))


def test_acc_is_range_checked_per_profile() -> None:
    e11, e13 = FirmwareEmulator(FIRMWARE_1_1), FirmwareEmulator(FIRMWARE_1_3)
    assert e11.feed(b"ACC 0\r") == b"\r"
    assert e13.feed(b"ACC 0\r") == b"ERROR\r"
    assert e11.feed(b"ACC 200\r") == b"ERROR\r"
    assert e13.feed(b"ACC 7FF\r") == b"\r"
    assert e11.feed(b"TRVL 10 80\r") == b"ERROR\r"
    assert e13.feed(b"TRVL 10 80\r") == b"\r"


def test_acc_0_on_firmware_1_1_freezes_gospd() -> None:
    e = FirmwareEmulator(FIRMWARE_1_1)
    e.feed(b"GOSPD 20 20\r")
    e.step(2.0)
    assert e.plant.wheel_velocities == pytest.approx((32.0, 32.0))
    assert e.feed(b"ACC 0\r") == b"\r"  # accepted ...
    e.feed(b"GOSPD 0 0\r")
    e.step(3.0)
    assert e.plant.wheel_velocities == pytest.approx((32.0, 32.0))  # ... but cannot slow down
    before = protocol.decode_dist(e.feed(b"DIST\r")[:-1].decode())
    e.feed(b"TRVL 10 10\r")  # 16 positions: the reference never starts moving ...
    e.step(2.0)
    after = protocol.decode_dist(e.feed(b"DIST\r")[:-1].decode())
    assert after[0] - before[0] <= 1  # ... so the wheels halt where they are
    assert e.plant.wheel_velocities == pytest.approx((0.0, 0.0))
    e.feed(b"ACC C8\r")  # a new rate unfreezes the ramp
    e.feed(b"TRVL 10 10\r")
    e.step(3.0)
    assert protocol.decode_dist(e.feed(b"DIST\r")[:-1].decode())[0] == after[0] + 16


def test_go_power_and_stop_zero_ramp(emu: FirmwareEmulator) -> None:
    ask(emu, "GO 7F 7F")
    emu.step(1.0)
    assert emu.plant.wheel_velocities[0] == pytest.approx(90.0)  # no-load 150 RPM
    ask(emu, "STOP 0")
    emu.step(0.30)
    assert emu.plant.wheel_velocities[0] > 0
    emu.step(0.04)
    assert emu.plant.wheel_velocities == pytest.approx((0.0, 0.0))  # within 0.32 s (+ one tick)


def test_stop_over_distance(emu: FirmwareEmulator) -> None:
    ask(emu, "GOSPD 40 40")
    emu.step(2.0)
    before = protocol.decode_dist(ask(emu, "DIST"))
    ask(emu, "STOP 14")  # 20 positions
    emu.step(3.0)
    after = protocol.decode_dist(ask(emu, "DIST"))
    assert emu.plant.wheel_velocities == pytest.approx((0.0, 0.0))
    assert after[0] - before[0] == pytest.approx(20, abs=1)
    assert after[1] - before[1] == pytest.approx(20, abs=1)


def test_travel_reverse_and_dist_sign(emu: FirmwareEmulator) -> None:
    ask(emu, "TRVL FF9C 7F")  # −100 positions
    emu.step(4.0)
    assert protocol.decode_dist(ask(emu, "DIST")) == (-100, -100)
    assert ask(emu, "DIST") == "FFFFFF9C FFFFFF9C"
    x, y, th = emu.plant.true_pose
    assert x == pytest.approx(-100 * emu.plant.metres_per_position)
    assert (y, th) == (0.0, 0.0)
    ask(emu, "RST")
    assert ask(emu, "DIST") == "00000000 00000000"


def test_ping_and_adc_from_sensor_source() -> None:
    sensors = FixedSensors(ping_left_m=2901 * PING_METRES_PER_UNIT,
                           ping_right_m=1000 * PING_METRES_PER_UNIT, battery_v=12.0)
    e = FirmwareEmulator(sensors=sensors)
    assert e.feed(b"SPNG 6\r") == b"\r"
    assert e.feed(b"PING\r") == b"000 3E8 \r"  # echo beyond 2900 units reads 0
    sensors.ping_left_m = 2900 * PING_METRES_PER_UNIT
    assert protocol.decode_ping(e.feed(b"PING\r")[:-1].decode()) == (2900, 1000)
    adc = protocol.decode_adc(e.feed(b"ADC\r")[:-1].decode())
    assert len(adc) == 8
    assert adc[7] * 3.21 / 819 == pytest.approx(12.0, abs=0.02)
    assert e.feed(b"SPNG 0\r") == b"\r"
    assert e.feed(b"PING\r") == b"\r"


def test_gpio_commands(emu: FirmwareEmulator) -> None:
    assert ask(emu, "SGP 3000") == ""  # pins 12, 13 as GPIO
    assert ask(emu, "OUT 1000") == ""
    assert ask(emu, "HIGH 1000") == ""
    assert ask(emu, "OUTS") == "00001000"
    assert ask(emu, "INS") == "00002000"
    assert ask(emu, "HIGHS") == "00001000"
    assert ask(emu, "READ") == "00001000"
    assert ask(emu, "LOW 1000") == ""
    assert ask(emu, "LOWS") == "00003000"
    assert ask(emu, "BLNK 5 A") == ""
    assert ask(emu, "BLNK 5 0") == ""


def test_each_firmware_knows_one_blink_spelling(emu: FirmwareEmulator) -> None:
    assert ask(emu, "BLINK 5 A") == "ERROR - Invalid command"  # FW 1.1 source: only BLNK
    e13 = FirmwareEmulator(FIRMWARE_1_3)
    assert ask(e13, "BLINK 5 A") == ""  # CS12 (FW 1.3) spells it BLINK
    assert ask(e13, "BLNK 5 A") == "ERROR"


def test_encoder_error() -> None:
    e = FirmwareEmulator()
    e.encoder_running = False
    assert e.feed(b"GOSPD 10 10\r") == b"ERROR\r"
    assert e.feed(b"DIST\r") == b"ERROR\r"
    e.feed(b"VERB 1\r")
    assert e.feed(b"STOP 0\r") == b"ERROR - Encoder error\r"
    assert e.motors_latched_off


def test_watch_is_an_error_on_firmware_1_1() -> None:
    e = FirmwareEmulator(FIRMWARE_1_1)
    assert e.feed(b"WATCH 1\r") == b"ERROR\r"
    assert e.feed(b"WATCH 0\r") == b"ERROR\r"
    e.feed(b"GOSPD 20 20\r")
    e.step(5.0)
    assert e.plant.wheel_velocities == pytest.approx((32.0, 32.0))  # no watchdog: keeps driving


def test_watchdog_on_firmware_1_3_stops_motors_after_1s_of_silence() -> None:
    e = FirmwareEmulator(FIRMWARE_1_3)
    e.feed(b"GOSPD 20 20\r")
    for _ in range(20):  # polled every 0.5 s: stays on
        e.step(0.5)
        e.feed(b"DIST\r")
    assert e.plant.wheel_velocities == pytest.approx((32.0, 32.0))
    e.step(0.99)
    assert e.plant.wheel_velocities == pytest.approx((32.0, 32.0))
    e.step(0.02)
    assert e.plant.wheel_velocities == pytest.approx((0.0, 0.0))
    assert e.watchdog_tripped
    assert e.feed(b"WATCH 0\r") == b"\r"
    e.feed(b"GOSPD 20 20\r")
    e.step(10.0)
    assert e.plant.wheel_velocities == pytest.approx((32.0, 32.0))


# --- reset ------------------------------------------------------------------------------------


def test_reboot_zeroes_counters_stops_motors_and_restores_power_on_state() -> None:
    e = FirmwareEmulator(FIRMWARE_1_1)
    for line in (b"VERB 1\r", b"SPNG 6\r", b"ACC 64\r", b"GOSPD 20 20\r"):
        assert e.feed(line) == b"\r"
    e.step(2.0)
    assert protocol.decode_dist(e.feed(b"DIST\r")[:-1].decode())[0] > 40
    e.feed(b"VE")  # half a line in the buffer when the reset comes
    e.reboot(round(2.5e9), boot_s=1.5)
    assert e.time_ns == round(2.5e9)
    pose = e.plant.true_pose
    assert pose[0] > 0.9  # driven 2.5 s at 32 positions/s before the reset
    assert e.booting and e.boot_done_ns == round(4.0e9)
    assert e.plant.wheel_velocities == (0.0, 0.0)  # the PWM stops with the Propeller
    assert e.feed(b"VER\r") == b""  # lost: the firmware is not running yet
    e.step(1.49)
    assert e.booting and e.feed(b"VER\r") == b""
    e.step(0.02)
    assert not e.booting
    assert e.feed(b"R\r") == b"ERROR\r"  # "VE" is gone, and VERB is back to 0
    assert e.feed(b"DIST\r") == b"00000000 00000000\r"
    assert e.feed(b"HEAD\r") == b"000\r"
    assert e.feed(b"PING\r").count(b" ") == 4  # power-on mask: pins 0-3
    assert e.ping_mask == FIRMWARE_1_1.power_on_ping_mask
    assert e.plant.acceleration == 200 and e.control_mode.name == "POWER"
    assert e.plant.true_pose == pose  # the robot itself stays where it stopped
    e.step(3.0)
    assert e.feed(b"DIST\r") == b"00000000 00000000\r"


def test_reboot_rearms_the_firmware_1_3_watchdog_and_clears_a_latched_stop() -> None:
    e = FirmwareEmulator(FIRMWARE_1_3)
    assert e.feed(b"WATCH 0\r") == b"\r"
    e.encoder_running = False
    e.feed(b"STOP 0\r")
    assert e.motors_latched_off and not e.watch_enabled
    e.encoder_running = True
    e.reboot(0, boot_s=0.0)
    assert not e.booting
    assert e.watch_enabled and not e.motors_latched_off
    e.feed(b"GOSPD 20 20\r")
    e.step(0.9)
    assert e.plant.wheel_velocities[0] > 0
    e.step(0.2)  # 1 s without serial data after the last command
    assert e.watchdog_tripped and e.plant.wheel_velocities == (0.0, 0.0)


def test_same_inputs_on_sim_clock_give_identical_outputs() -> None:
    script = [(0.0, b"VERB 1\r"), (0.05, b"GOSPD 40 30\r"), (0.7, b"DIST\r"), (1.3, b"SPD\r"),
              (1.31, b"TURN FF10 50\r"), (2.0, b"HEAD\r"), (2.5, b"GO 40 C0\r"),
              (3.1, b"STOP 5\r"), (4.0, b"DIST\r"), (4.0, b"HEAD\r"), (4.2, b"ADC\r")]

    def run() -> tuple[list[bytes], tuple[float, float, float], tuple[float, float]]:
        e = FirmwareEmulator()
        out = []
        for t, line in script:
            e.advance_to(t)
            out.append(e.feed(line))
        e.advance_to(5.0)
        return out, e.plant.true_pose, e.plant.wheel_positions

    assert run() == run()
