"""Eddie constants: geometry, sensor units, Sharp curve, firmware profiles."""

from __future__ import annotations

import math

import pytest

from eddiebot.robot import constants as c


def test_wheel_and_encoder_geometry() -> None:
    assert c.WHEEL_RADIUS_M == 0.0762
    assert c.WHEEL_DIAMETER_M == 2 * c.WHEEL_RADIUS_M
    assert c.POSITIONS_PER_REV == 36
    assert c.TRACK_M == 0.39
    assert pytest.approx(0.013299, abs=1e-6) == c.METRES_PER_POSITION
    assert c.POSITIONS_PER_SPIN == 186
    assert c.POSITIONS_PER_WHEEL_PER_SPIN == 93
    # 93 positions per wheel for a spin implies a track of about 0.394 m.
    implied_track = 2 * c.POSITIONS_PER_WHEEL_PER_SPIN * c.METRES_PER_POSITION / (2 * math.pi)
    assert implied_track == pytest.approx(0.3937, abs=1e-3)
    assert c.metres_per_position(144) == pytest.approx(c.METRES_PER_POSITION / 4)


def test_ping_units() -> None:
    assert pytest.approx(1.0976e-3, rel=1e-3) == c.PING_METRES_PER_UNIT
    assert c.ping_units_to_range_m(0) == math.inf
    assert c.ping_units_to_range_m(1000) == pytest.approx(1.0976, rel=1e-3)
    assert c.range_m_to_ping_units(1.0976) == 1000
    assert c.range_m_to_ping_units(2900 * c.PING_METRES_PER_UNIT) == 2900
    assert c.range_m_to_ping_units(2901 * c.PING_METRES_PER_UNIT) == 0
    assert c.range_m_to_ping_units(17 * c.PING_METRES_PER_UNIT) == 0
    assert c.range_m_to_ping_units(math.inf) == 0


def test_adc_and_battery() -> None:
    assert c.ADC_COUNTS_PER_VOLT == 819
    assert c.volts_to_adc_counts(5.0) == 0xFFF
    assert c.volts_to_adc_counts(9.0) == 0xFFF
    assert c.volts_to_adc_counts(-1.0) == 0
    assert c.adc_counts_to_volts(819) == pytest.approx(1.0)
    assert c.BATTERY_ADC_INDEX == 7
    assert c.battery_volts_from_counts(round(12.0 / 3.21 * 819)) == pytest.approx(12.0, abs=0.01)


def test_sensor_table() -> None:
    ir = {s.name: s for s in c.IR_SENSORS}
    assert [s.index for s in c.IR_SENSORS] == [0, 1, 2]
    assert ir["ir_left"].urdf_joint == "ij3" and ir["ir_left"].y_m == 0.155
    assert ir["ir_left"].yaw_rad == pytest.approx(math.pi / 4)
    assert ir["ir_center"].urdf_joint == "ij2" and ir["ir_center"].x_m == 0.210
    assert ir["ir_right"].urdf_joint == "ij1" and ir["ir_right"].yaw_rad == pytest.approx(-math.pi / 4)
    ping = {s.name: s for s in c.PING_SENSORS}
    assert (ping["ping_left"].index, ping["ping_left"].urdf_joint) == (1, "uj1")
    assert (ping["ping_right"].index, ping["ping_right"].urdf_joint) == (2, "uj2")
    assert ping["ping_left"].yaw_rad == pytest.approx(math.pi / 8)
    assert ping["ping_right"].y_m == -0.09
    assert c.PING_MASK == sum(1 << s.index for s in c.PING_SENSORS) == 6


@pytest.mark.parametrize("distance", [0.10, 0.12, 0.2, 0.33, 0.5, 0.61, 0.79, 0.80])
def test_sharp_round_trip(distance: float) -> None:
    v = c.sharp_distance_to_voltage(distance)
    assert c.sharp_voltage_to_distance(v) == pytest.approx(distance, abs=1e-9)


def test_sharp_curve_shape_and_limits() -> None:
    assert c.sharp_distance_to_voltage(0.10) == pytest.approx(2.30)
    assert c.sharp_distance_to_voltage(0.80) == pytest.approx(0.40)
    volts = [c.sharp_distance_to_voltage(d / 100) for d in range(10, 81)]
    assert all(a > b for a, b in zip(volts, volts[1:]))
    assert c.sharp_voltage_to_distance(0.2) == math.inf
    assert c.sharp_voltage_to_distance(3.0) == -math.inf
    assert c.sharp_distance_to_voltage(math.inf) == 0.0
    # The original stack's 1.7 V IR veto is about 15 cm.
    assert c.sharp_voltage_to_distance(1.7) == pytest.approx(0.145, abs=0.01)


def test_firmware_profiles() -> None:
    f11, f13 = c.FIRMWARE_1_1, c.FIRMWARE_1_3
    assert (f11.move_speed_max, f11.acc_min, f11.acc_max, f11.has_watch) == (0x7F, 0, 0x1FF, False)
    assert (f13.move_speed_max, f13.acc_min, f13.acc_max, f13.has_watch) == (0xFF, 1, 0x7FF, True)
    assert f13.watch_default_on
    assert c.profile_for_version(0x0070) is f11
    assert c.profile_for_version(0x000A) is f11
    assert c.profile_for_version(f13.version_word) is f13
    assert c.profile_for_name("1.3") is f13
