"""The command codec: formatting, range checks, reply decoding, typed errors, fuzzing."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from eddiebot.robot import errors, protocol
from eddiebot.robot.constants import FIRMWARE_1_1, FIRMWARE_1_3


def test_encode_formats_upper_case_twos_complement() -> None:
    assert protocol.encode_acc(30) == "ACC 1E"
    assert protocol.encode_gospd(-1, 255) == "GOSPD FFFF FF"
    assert protocol.encode_gospd(-32768, 32767) == "GOSPD 8000 7FFF"
    assert protocol.encode_go(-127, 127) == "GO 81 7F"
    assert protocol.encode_trvl(-100, 0x7F) == "TRVL FF9C 7F"
    assert protocol.encode_turn(360, 0x7F) == "TURN 168 7F"
    assert protocol.encode_stop(0) == "STOP 0"
    assert protocol.encode_spng(6) == "SPNG 6"
    assert protocol.encode_verb(True) == "VERB 1"
    assert protocol.encode_blink(5, 10, FIRMWARE_1_1) == "BLNK 5 A"
    assert protocol.encode_blink(5, 10, FIRMWARE_1_3) == "BLINK 5 A"
    assert protocol.encode_watch(1, FIRMWARE_1_3) == "WATCH 1"
    assert protocol.encode_high(0xFFFFFFFF) == "HIGH FFFFFFFF"
    no_args = [protocol.encode_hwver, protocol.encode_ver, protocol.encode_ins,
               protocol.encode_outs, protocol.encode_lows, protocol.encode_highs,
               protocol.encode_read, protocol.encode_ping, protocol.encode_adc,
               protocol.encode_spd, protocol.encode_head, protocol.encode_dist,
               protocol.encode_rst]
    assert [f() for f in no_args] == ["HWVER", "VER", "INS", "OUTS", "LOWS", "HIGHS", "READ",
                                      "PING", "ADC", "SPD", "HEAD", "DIST", "RST"]
    assert set(protocol.COMMANDS) >= {f() for f in no_args}


def test_gospd_40000_refused_naming_command_parameter_and_range() -> None:
    with pytest.raises(errors.ParameterRangeError) as info:
        protocol.encode_gospd(40000, 0)
    err = info.value
    assert (err.command, err.parameter, err.value, err.low, err.high) == (
        "GOSPD", "left", 40000, -32768, 32767)
    assert "GOSPD" in str(err) and "left" in str(err) and "-32768..32767" in str(err)


@pytest.mark.parametrize(("call", "parameter"), [
    (lambda: protocol.encode_trvl(10, 0x80, FIRMWARE_1_1), "speed"),
    (lambda: protocol.encode_trvl(10, 0, FIRMWARE_1_3), "speed"),
    (lambda: protocol.encode_turn(40000, 10), "angle"),
    (lambda: protocol.encode_acc(0x200, FIRMWARE_1_1), "rate"),
    (lambda: protocol.encode_acc(0, FIRMWARE_1_3), "rate"),
    (lambda: protocol.encode_go(-128, 0), "left"),
    (lambda: protocol.encode_stop(-1), "distance"),
    (lambda: protocol.encode_stop(0x10000), "distance"),
    (lambda: protocol.encode_verb(2), "mode"),
    (lambda: protocol.encode_in(-1), "mask"),
])
def test_range_errors(call: object, parameter: str) -> None:
    with pytest.raises(errors.ParameterRangeError) as info:
        call()  # type: ignore[operator]
    assert info.value.parameter == parameter


def test_profile_ranges_differ() -> None:
    assert protocol.encode_trvl(1, 0xFF, FIRMWARE_1_3) == "TRVL 1 FF"
    assert protocol.encode_acc(0x7FF, FIRMWARE_1_3) == "ACC 7FF"
    assert protocol.encode_acc(1, FIRMWARE_1_1) == "ACC 1"
    assert protocol.encode_acc(0x1FF, FIRMWARE_1_1) == "ACC 1FF"
    with pytest.raises(errors.UnsupportedCommandError):
        protocol.encode_watch(1, FIRMWARE_1_1)


def test_acc_0_refused_on_firmware_1_1_where_it_freezes_gospd() -> None:
    # FW 1.1 accepts ACC 0 (0..511), but then the speed ramp never moves again.
    with pytest.raises(errors.ParameterRangeError) as info:
        protocol.encode_acc(0, FIRMWARE_1_1)
    err = info.value
    assert (err.command, err.parameter, err.value, err.low, err.high) == ("ACC", "rate", 0, 1,
                                                                           0x1FF)
    assert "ACC 0 freezes GOSPD on FW 1.1" in str(err)


def test_decoders() -> None:
    assert protocol.decode_dist("5086D72A 00CE838F") == (0x5086D72A, 0x00CE838F)
    assert protocol.decode_dist("FFFFFFFF 80000000") == (-1, -(2**31))
    assert protocol.decode_spd("FFF6 0010") == (-10, 16)
    assert protocol.decode_head("FF6") == -10
    assert protocol.decode_head("05A") == 90
    assert protocol.decode_word("VER", "0070") == 0x70
    assert protocol.decode_mask("INS", "0007FFF0") == 0x7FFF0
    assert protocol.decode_ping("000 557 71E 000 ") == (0, 0x557, 0x71E, 0)
    assert protocol.decode_ping("0C8 0FA") == (200, 250)
    assert protocol.decode_ping("") == ()
    adc = protocol.decode_adc("0F4 0F4 0F4 000 000 000 000 C8C")
    assert adc[7] == 0xC8C
    assert protocol.adc_counts_to_volts(adc[7]) == pytest.approx(3.921, abs=1e-3)
    assert protocol.ping_units_to_range_m(0) == math.inf
    protocol.decode_empty("GOSPD", "")
    assert protocol.to_signed(0xFF, 8) == -1


@pytest.mark.parametrize(("reply", "cls"), [
    ("ERROR", errors.FirmwareError),
    ("ERROR - Invalid command", errors.InvalidCommandError),
    ("ERROR - Invalid parameter", errors.InvalidParameterError),
    ("ERROR - Too few parameters", errors.TooFewParametersError),
    ("ERROR - Too many parameters", errors.TooManyParametersError),
    ("ERROR - Overflow", errors.BufferOverflowError),
    ("ERROR - Bad checksum", errors.BadChecksumError),
    ("ERROR - Encoder error", errors.EncoderError),
])
def test_error_replies_are_typed(reply: str, cls: type[errors.FirmwareError]) -> None:
    with pytest.raises(cls) as info:
        protocol.decode_dist(reply)
    assert type(info.value) is cls
    assert info.value.reply == reply and info.value.command == "DIST"


@pytest.mark.parametrize("reply", ["", "0000005D", "0000005D FFFFFFA3 ", "0000005G FFFFFFA3",
                                   "0000005D  FFFFFFA3", "\x00"])
def test_malformed_dist(reply: str) -> None:
    with pytest.raises(errors.ReplyFormatError):
        protocol.decode_dist(reply)


_DECODERS = [protocol.decode_dist, protocol.decode_spd, protocol.decode_head,
             protocol.decode_ping, protocol.decode_adc,
             lambda r: protocol.decode_word("VER", r), lambda r: protocol.decode_empty("GO", r)]


@settings(max_examples=300, deadline=None)
@given(st.text(max_size=60), st.integers(0, len(_DECODERS) - 1))
def test_reply_decoders_never_crash(reply: str, which: int) -> None:
    try:
        _DECODERS[which](reply)
    except (errors.ReplyFormatError, errors.FirmwareError):
        pass


@settings(max_examples=200, deadline=None)
@given(st.integers(-40000, 40000), st.integers(-40000, 40000))
def test_gospd_encodes_or_refuses(left: int, right: int) -> None:
    if not (-32768 <= left <= 32767 and -32768 <= right <= 32767):
        with pytest.raises(errors.ParameterRangeError):
            protocol.encode_gospd(left, right)
        return
    line = protocol.encode_gospd(left, right)
    _, a, b = line.split()
    assert protocol.to_signed(int(a, 16), 16) == left
    assert protocol.to_signed(int(b, 16), 16) == right
    assert line == line.upper()
