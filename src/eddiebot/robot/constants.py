"""The one module of Parallax Eddie constants.

Everything physical about the robot that the driver, the odometry, the board node, the URDF
and the simulator need lives here, with its source in the hardware reference
(``eddie_hardware.md``).  Units are SI unless a name says otherwise; "positions" are encoder
counts as the control board reports them (36 per wheel revolution on the Position Controller
kit).  Poses of sensors are in the ``base_link`` frame (REP-103: x forward, y left, z up,
yaw counter-clockwise positive).
"""

from __future__ import annotations

import enum
import math
from bisect import bisect_left
from dataclasses import dataclass

__all__ = [
    "ADC_CHANNELS",
    "ADC_COUNTS_PER_VOLT",
    "ADC_FULL_SCALE_V",
    "ADC_MAX_COUNTS",
    "BASE_LINK_HEIGHT_M",
    "BATTERY_ADC_INDEX",
    "BATTERY_DIVIDER",
    "BAUD_RATE",
    "BUFFER_LENGTH",
    "CONTROL_LOOP_HZ",
    "FIRMWARE_1_1",
    "FIRMWARE_1_3",
    "FIRMWARE_PROFILES",
    "IR_SENSORS",
    "MAX_ON_TIME",
    "METRES_PER_POSITION",
    "PING_MASK",
    "PING_MAX_UNITS",
    "PING_METRES_PER_UNIT",
    "PING_MIN_UNITS",
    "PING_SENSORS",
    "POSITIONS_PER_REV",
    "POSITIONS_PER_SPIN",
    "POSITIONS_PER_WHEEL_PER_SPIN",
    "SHARP_MAX_RANGE_M",
    "SHARP_MIN_RANGE_M",
    "SPEED_OF_SOUND_M_S",
    "TRACK_M",
    "WHEEL_DIAMETER_M",
    "WHEEL_RADIUS_M",
    "FirmwareProfile",
    "RangeSensorMount",
    "SensorKind",
    "adc_counts_to_volts",
    "battery_volts_from_counts",
    "metres_per_position",
    "ping_units_to_range_m",
    "profile_for_name",
    "profile_for_version",
    "range_m_to_ping_units",
    "sharp_distance_to_voltage",
    "sharp_voltage_to_distance",
    "volts_to_adc_counts",
]

# --- wheels, encoders, geometry -------------------------------------------------------------

WHEEL_DIAMETER_M = 0.1524
"""6-inch tyres (PLAT).  The original code's ``WHEEL_RADIUS 0.1524`` is this diameter (bug B2)."""
WHEEL_RADIUS_M = 0.0762
"""Wheel radius in metres (PLAT, original URDF ``wheel_radius``)."""
POSITIONS_PER_REV = 36
"""Encoder positions per wheel revolution, Position Controller kit #29319 (WK36)."""
TRACK_M = 0.39
"""Wheel centre-to-centre distance, 15.4 in (PLAT "Additional Specifications")."""
METRES_PER_POSITION = math.pi * WHEEL_DIAMETER_M / POSITIONS_PER_REV
"""Distance a wheel rolls per encoder position: π·0.1524/36 ≈ 0.013299 m."""
POSITIONS_PER_SPIN = 186
"""Firmware ``POSITIONS_PER_ROTATION``: L−R position difference for a 360° spin in place."""
POSITIONS_PER_WHEEL_PER_SPIN = POSITIONS_PER_SPIN // 2
"""Positions each wheel moves (left +, right −) for a 360° ``TURN``: 93."""
BASE_LINK_HEIGHT_M = 0.10125
"""``base_footprint`` → ``base_link`` offset along z (original URDF)."""


def metres_per_position(counts_per_rev: int = POSITIONS_PER_REV) -> float:
    """Wheel travel per encoder position in metres for an encoder of ``counts_per_rev``."""
    return math.pi * WHEEL_DIAMETER_M / counts_per_rev


# --- control board ----------------------------------------------------------------------------

BAUD_RATE = 115_200
"""Serial link rate, 8N1, no flow control (CS11 p3, FW ``BAUDRATE``)."""
BUFFER_LENGTH = 255
"""Firmware input buffer in bytes, including the terminating CR (FW ``BUFFER_LENGTH``)."""
CONTROL_LOOP_HZ = 50
"""Firmware PD loop rate (FW ``DIVISOR``)."""
MAX_ON_TIME = 7520
"""Full-scale motor PWM on-time in clocks (FW motor driver); ``GO 7F`` maps to it."""

# --- range sensors and ADC -------------------------------------------------------------------

SPEED_OF_SOUND_M_S = 343.0
"""Speed of sound used for the PING))) unit (20 °C)."""
PING_SECONDS_PER_UNIT = 512 / 80_000_000
"""FW 1.1 reports the echo width in 80 MHz clocks shifted right by 9: 6.4 µs per unit."""
PING_METRES_PER_UNIT = SPEED_OF_SOUND_M_S * PING_SECONDS_PER_UNIT / 2.0
"""Range per PING unit on FW 1.1: ≈ 1.0976 mm (round trip halved)."""
PING_MIN_UNITS = 18
"""Echoes shorter than this are reported as 0 by the firmware."""
PING_MAX_UNITS = 2900
"""Echoes longer than this are reported as 0 by the firmware (≈ 3.18 m)."""
PING_MASK = 0x6
"""``SPNG`` mask for Eddie's two PING))) sensors on I/O pins 1 (left) and 2 (right) (PLAT)."""

ADC_CHANNELS = 8
"""The MCP3008 has 8 channels; ``ADC`` reports all of them, index 0..7."""
ADC_FULL_SCALE_V = 5.0
"""ADC reference voltage: 0..FFF ↔ 0..5.00 V."""
ADC_MAX_COUNTS = 0xFFF
"""Largest ADC value the firmware reports (12-bit scale; the chip's 2 LSBs are not meaningful)."""
ADC_COUNTS_PER_VOLT = 819
"""Counts per volt as the original stack converts them (0xFFF / 5 V ≈ 819)."""
BATTERY_ADC_INDEX = 7
"""ADC index of VCC_MAIN ("channel 8" in the board documents)."""
BATTERY_DIVIDER = 3.21
"""VCC_MAIN divider 619k/280k: battery volts = ADC volts · 3.21 (SCH)."""


def adc_counts_to_volts(counts: int) -> float:
    """ADC counts (0..0xFFF) → volts at the ADC pin."""
    return counts / ADC_COUNTS_PER_VOLT


def volts_to_adc_counts(volts: float) -> int:
    """Volts at the ADC pin → counts, rounded and clipped to 0..0xFFF."""
    if not math.isfinite(volts):
        return ADC_MAX_COUNTS if volts > 0 else 0
    return max(0, min(ADC_MAX_COUNTS, round(volts * ADC_COUNTS_PER_VOLT)))


def battery_volts_from_counts(counts: int) -> float:
    """ADC counts on :data:`BATTERY_ADC_INDEX` → battery voltage in volts."""
    return counts / ADC_COUNTS_PER_VOLT * BATTERY_DIVIDER


def ping_units_to_range_m(units: int) -> float:
    """A PING reading in firmware units → range in metres; 0 (no echo in range) → ``inf``.

    ``inf`` follows REP-117 ("nothing detected within range").
    """
    if units <= 0:
        return math.inf
    return units * PING_METRES_PER_UNIT


def range_m_to_ping_units(range_m: float) -> int:
    """Range in metres → the value FW 1.1 reports: 0 when under 18 or beyond 2900 units."""
    if not math.isfinite(range_m) or range_m <= 0.0:
        return 0
    units = round(range_m / PING_METRES_PER_UNIT)
    if units < PING_MIN_UNITS or units > PING_MAX_UNITS:
        return 0
    return int(units)


# Sharp GP2Y0A21YK0F typical output (datasheet figure "Analog output voltage vs. distance",
# white reflector, Vcc 5 V), tabulated over its rated 10-80 cm range.  Voltage falls
# monotonically with distance there; below 10 cm the curve folds back, so readings above the
# 10 cm voltage are ambiguous and reported as "too close".
_SHARP_DISTANCE_M = (0.10, 0.15, 0.20, 0.25, 0.30, 0.35, 0.40, 0.50, 0.60, 0.70, 0.80)
_SHARP_VOLTS = (2.30, 1.65, 1.30, 1.08, 0.92, 0.81, 0.74, 0.60, 0.50, 0.45, 0.40)
SHARP_MIN_RANGE_M = _SHARP_DISTANCE_M[0]
"""Lower end of the GP2Y0A21's rated range (m)."""
SHARP_MAX_RANGE_M = _SHARP_DISTANCE_M[-1]
"""Upper end of the GP2Y0A21's rated range (m)."""


def sharp_distance_to_voltage(distance_m: float) -> float:
    """GP2Y0A21 output voltage (V) for a target at ``distance_m`` metres.

    Piecewise-linear in 1/distance between the tabulated points (the sensor's output is
    close to linear in inverse distance).  Targets nearer than 10 cm read as the 10 cm
    voltage; beyond 80 cm (or no target, ``inf``) the output keeps falling as 0.32 V·m/d,
    the asymptote of the curve, so "nothing there" reads ≈ 0.3 V or less.
    """
    if not distance_m > 0.0:
        return _SHARP_VOLTS[0]
    if distance_m <= _SHARP_DISTANCE_M[0]:
        return _SHARP_VOLTS[0]
    if distance_m >= _SHARP_DISTANCE_M[-1]:
        if math.isinf(distance_m):
            return 0.0
        return _SHARP_VOLTS[-1] * _SHARP_DISTANCE_M[-1] / distance_m
    i = bisect_left(_SHARP_DISTANCE_M, distance_m)
    d0, d1 = _SHARP_DISTANCE_M[i - 1], _SHARP_DISTANCE_M[i]
    v0, v1 = _SHARP_VOLTS[i - 1], _SHARP_VOLTS[i]
    t = (1.0 / distance_m - 1.0 / d0) / (1.0 / d1 - 1.0 / d0)
    return v0 + t * (v1 - v0)


def sharp_voltage_to_distance(volts: float) -> float:
    """GP2Y0A21 voltage (V) → distance in metres, the inverse of
    :func:`sharp_distance_to_voltage` within 10-80 cm.

    Out of the rated range it follows REP-117: below the 80 cm voltage → ``+inf`` (nothing
    within range); above the 10 cm voltage → ``-inf`` (too close to measure).
    """
    if math.isnan(volts):
        return math.nan
    if volts < _SHARP_VOLTS[-1]:
        return math.inf
    if volts > _SHARP_VOLTS[0]:
        return -math.inf
    # _SHARP_VOLTS is decreasing; search on the negated sequence.
    neg = [-v for v in _SHARP_VOLTS]
    i = bisect_left(neg, -volts)
    if i == 0:
        return _SHARP_DISTANCE_M[0]
    v0, v1 = _SHARP_VOLTS[i - 1], _SHARP_VOLTS[i]
    d0, d1 = _SHARP_DISTANCE_M[i - 1], _SHARP_DISTANCE_M[i]
    t = (volts - v0) / (v1 - v0)
    inv = 1.0 / d0 + t * (1.0 / d1 - 1.0 / d0)
    return 1.0 / inv


# --- sensor table ----------------------------------------------------------------------------


class SensorKind(enum.Enum):
    """Kind of range sensor on Eddie."""

    IR = "ir"
    PING = "ping"


@dataclass(frozen=True)
class RangeSensorMount:
    """One range sensor: where it is wired and where it sits on the robot.

    ``index`` is the ADC index (IR) or the Propeller I/O pin (PING))) ).  The pose is the
    original URDF joint ``urdf_joint`` relative to ``base_link`` (m, rad, REP-103).
    """

    name: str
    kind: SensorKind
    index: int
    urdf_joint: str
    x_m: float
    y_m: float
    z_m: float
    yaw_rad: float
    min_range_m: float
    max_range_m: float
    field_of_view_rad: float


IR_SENSORS: tuple[RangeSensorMount, ...] = (
    RangeSensorMount("ir_left", SensorKind.IR, 0, "ij3", 0.135, 0.155, 0.025, math.pi / 4,
                     SHARP_MIN_RANGE_M, SHARP_MAX_RANGE_M, 0.1),
    RangeSensorMount("ir_center", SensorKind.IR, 1, "ij2", 0.210, 0.0, 0.025, 0.0,
                     SHARP_MIN_RANGE_M, SHARP_MAX_RANGE_M, 0.1),
    RangeSensorMount("ir_right", SensorKind.IR, 2, "ij1", 0.135, -0.155, 0.025, -math.pi / 4,
                     SHARP_MIN_RANGE_M, SHARP_MAX_RANGE_M, 0.1),
)
"""Sharp IR sensors left/center/right on ADC index 0/1/2 (PLAT AD1/AD2/AD3)."""

PING_SENSORS: tuple[RangeSensorMount, ...] = (
    RangeSensorMount("ping_left", SensorKind.PING, 1, "uj1", 0.195, 0.09, 0.015, math.pi / 8,
                     PING_MIN_UNITS * PING_METRES_PER_UNIT, PING_MAX_UNITS * PING_METRES_PER_UNIT,
                     0.5),
    RangeSensorMount("ping_right", SensorKind.PING, 2, "uj2", 0.195, -0.09, 0.015, -math.pi / 8,
                     PING_MIN_UNITS * PING_METRES_PER_UNIT, PING_MAX_UNITS * PING_METRES_PER_UNIT,
                     0.5),
)
"""PING))) sensors left/right on I/O pins 1/2 (PLAT); enable them with ``SPNG 6``."""


# --- firmware profiles ------------------------------------------------------------------------


@dataclass(frozen=True)
class FirmwareProfile:
    """Parameter ranges and behaviour of one control-board firmware (CS11, CS12, FW source).

    Speeds are positions per second; accelerations positions per second squared.
    """

    name: str
    version_word: int
    """What ``VER`` answers (4 hex digits)."""
    move_speed_min: int
    """Smallest ``TRVL``/``TURN`` speed."""
    move_speed_max: int
    """Largest ``TRVL``/``TURN`` speed."""
    acc_min: int
    acc_max: int
    has_watch: bool
    """Whether the ``WATCH`` command exists."""
    watch_default_on: bool
    """Whether the 1 s serial watchdog is armed at power-on."""
    blink_names: tuple[str, ...]
    """Spellings of the blink command the firmware accepts; the first is what the codec sends."""
    power_on_ping_mask: int
    no_load_rev_per_s: float
    """No-load wheel speed at 12 V in revolutions per second (WK36: 150 RPM, WKQ: 100 RPM)."""
    default_acceleration: int = 200
    """``MaxPosAccel`` at power-on (FW ``MaxPosAccel long 200``)."""
    watchdog_timeout_s: float = 1.0
    ignores_control_bytes: bool = True
    """Whether control characters (0x01-0x07, 0x0A-0x0C, 0x0E-0x1F) and bytes ≥ 0x7F are
    dropped, as the command-set documents say.  The FW 1.1 source's ``case`` for them is
    empty *after* the byte was stored, so there they stay in the line: a stray LF makes the
    command (or its last parameter) invalid."""
    acc_zero_freezes: bool = False
    """Whether ``ACC 0`` is accepted but freezes the speed ramp: with ``MaxPosAccel`` 0 the
    FW 1.1 loop clamps every step of ``MidVelocity`` to 0, so after it ``GOSPD`` never
    changes the wheels' speed and ``TRVL``/``TURN`` do not move, until another ``ACC``."""


FIRMWARE_1_1 = FirmwareProfile(
    name="1.1",
    version_word=0x0070,  # the Tang build (VERSION = 112) that the original stack ran
    move_speed_min=1,
    move_speed_max=0x7F,
    acc_min=0,
    acc_max=0x1FF,
    has_watch=False,
    watch_default_on=False,
    blink_names=("BLNK",),
    power_on_ping_mask=0xF,
    no_load_rev_per_s=2.5,
    ignores_control_bytes=False,
    acc_zero_freezes=True,
)
"""Firmware 1.1 for Position Controllers (the FW source; ranges as the source enforces them)."""

FIRMWARE_1_3 = FirmwareProfile(
    name="1.3",
    version_word=0x000D,
    move_speed_min=1,
    move_speed_max=0xFF,
    acc_min=1,
    acc_max=0x7FF,
    has_watch=True,
    watch_default_on=True,
    blink_names=("BLINK",),
    power_on_ping_mask=0x3,
    no_load_rev_per_s=100.0 / 60.0,
)
"""Firmware 1.3 for the quadrature encoder kit (CS12).  Its ``VER`` word is not documented;
``0x000D`` (13) is this project's choice."""

FIRMWARE_PROFILES: dict[str, FirmwareProfile] = {"1.1": FIRMWARE_1_1, "1.3": FIRMWARE_1_3}


def profile_for_name(name: str) -> FirmwareProfile:
    """``"1.1"`` or ``"1.3"`` → its profile (``KeyError`` for others)."""
    return FIRMWARE_PROFILES[name]


def profile_for_version(version_word: int) -> FirmwareProfile:
    """The profile to adopt for a board answering ``VER`` with ``version_word``.

    Builds that add 100 to the version (the Tang build, 112) are reduced first; versions up
    to 12 are the Position Controller firmware 1.1 (and older), 13 and later the quadrature
    firmware 1.3.  Unknown boards get the more restrictive 1.1 ranges.
    """
    base = version_word - 100 if version_word >= 100 else version_word
    if base >= 13:
        return FIRMWARE_1_3
    return FIRMWARE_1_1
