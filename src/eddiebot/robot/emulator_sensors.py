"""Where the emulated control board's range sensors and ADC read from: the simulator plugs in
its world; the standalone emulator reads constant, plausible values."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

from eddiebot.robot.constants import BATTERY_ADC_INDEX, BATTERY_DIVIDER

__all__ = ["FixedSensors", "SensorSource"]


class SensorSource(Protocol):
    """Where the emulated board's range sensors and ADC read from.

    Times are the emulator's, in seconds.  The simulator plugs in its world here.
    """

    def ping_range_m(self, pin: int, time_s: float) -> float:
        """Range in metres seen by the PING))) sensor on I/O ``pin`` (``inf``: no echo)."""
        ...

    def adc_volts(self, channel: int, time_s: float) -> float:
        """Voltage at ADC index ``channel`` (0..7) in volts."""
        ...


@dataclass
class FixedSensors:
    """Constant, plausible readings for the standalone emulator.

    PING))) pins 1 and 2 see walls at ``ping_left_m``/``ping_right_m``; other pins see no
    echo.  IR channels 0..2 read ``ir_volts`` (≈ 0.3 V: nothing within 80 cm); the battery
    (index 7) reads ``battery_v`` through the 3.21 divider; other channels read 0 V.
    """

    ping_left_m: float = 1.5
    ping_right_m: float = 2.0
    ir_volts: tuple[float, float, float] = (0.3, 0.3, 0.3)
    battery_v: float = 12.6

    def ping_range_m(self, pin: int, time_s: float) -> float:
        """Range on ``pin`` in metres."""
        if pin == 1:
            return self.ping_left_m
        if pin == 2:
            return self.ping_right_m
        return math.inf

    def adc_volts(self, channel: int, time_s: float) -> float:
        """Volts on ADC ``channel``."""
        if 0 <= channel < 3:
            return self.ir_volts[channel]
        if channel == BATTERY_ADC_INDEX:
            return self.battery_v / BATTERY_DIVIDER
        return 0.0
