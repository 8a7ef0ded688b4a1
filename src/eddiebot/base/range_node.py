"""Range node: raw PING and ADC → ``sensor_msgs/Range`` in metres, battery level, and the
original stack's ``Distances``/``Voltages`` topics.

One table (``eddiebot.robot.constants``) says which sensor is which: IR left/center/right
are ADC indices 0/1/2 (frames ``ir_*_link``), PING left/right are pins 1/2 reported lowest
pin first (frames ``ping_*_link``), the battery is ADC index 7 through the 3.21 divider.
Out-of-range readings follow REP-117: PING 0 (no echo) and an IR voltage below the curve's
far end (nothing within 80 cm) are ``+inf``; an IR voltage above its 10 cm end (closer than
the sensor can measure) is ``-inf``, which the safety veto treats as the most urgent reading.
A malformed or empty message is skipped with one warning (the original read out of bounds
here).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from eddiebot.core.node import Node
from eddiebot.core.parameters import ParameterDescriptor
from eddiebot.msgs.eddiebot_msgs import ADC, BatteryLevel, Distances, Ping, Voltages
from eddiebot.msgs.sensor_msgs import Range
from eddiebot.robot.constants import (
    BATTERY_ADC_INDEX,
    IR_SENSORS,
    PING_MASK,
    PING_SENSORS,
    RangeSensorMount,
    adc_counts_to_volts,
    battery_volts_from_counts,
    ping_units_to_range_m,
    sharp_voltage_to_distance,
)

__all__ = ["RangeNode"]


class RangeNode(Node):
    default_node_name = "eddie_range"

    def __init__(self, node_name: str = default_node_name, **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        self.ping_mask = int(self.declare_parameter(
            "ping_mask", PING_MASK, ParameterDescriptor(read_only=True)).value)
        self.ir_pubs = {s.name: self.create_publisher(Range, f"/eddie/ir/{s.name.split('_')[1]}", 10)
                        for s in IR_SENSORS}
        self.ping_pubs = {s.name: self.create_publisher(Range, f"/eddie/ping/{s.name.split('_')[1]}", 10)
                          for s in PING_SENSORS}
        self.battery_pub = self.create_publisher(BatteryLevel, "/eddie/battery_level", 10)
        self.distances_pub = self.create_publisher(Distances, "/eddie/ping_distances", 10)
        self.voltages_pub = self.create_publisher(Voltages, "/eddie/ir_voltages", 10)
        self.create_subscription(Ping, "/eddie/ping_data", self._on_ping, 10)
        self.create_subscription(ADC, "/eddie/adc_data", self._on_adc, 10)

    def _range(self, s: RangeSensorMount, value: float, radiation: int) -> Any:
        msg = Range()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.header.frame_id = f"{s.name}_link"
        msg.radiation_type = radiation
        msg.field_of_view = s.field_of_view_rad
        msg.min_range = s.min_range_m
        msg.max_range = s.max_range_m
        msg.range = value
        return msg

    def _on_ping(self, msg: Any) -> None:
        values = list(msg.value)
        pins = [p for p in range(16) if self.ping_mask & (1 << p)]
        if msg.status != "SUCCESS" or len(values) != len(pins):
            self.get_logger().warning(
                f"/eddie/ping_data: status {msg.status!r} with {len(values)} values for pins {pins}; skipped",
                once=True,
            )
            return
        self.distances_pub.publish(Distances(value=np.asarray(values, dtype=np.uint16)))
        by_pin = dict(zip(pins, values))
        for s in PING_SENSORS:
            if s.index in by_pin:
                self.ping_pubs[s.name].publish(
                    self._range(s, ping_units_to_range_m(int(by_pin[s.index])), Range.ULTRASOUND)
                )

    def _on_adc(self, msg: Any) -> None:
        values = list(msg.value)
        if msg.status != "SUCCESS" or len(values) < 8:
            self.get_logger().warning(
                f"/eddie/adc_data: status {msg.status!r} with {len(values)} values (need 8); skipped",
                once=True,
            )
            return
        volts = [adc_counts_to_volts(int(v)) for v in values]
        self.voltages_pub.publish(Voltages(value=np.asarray(volts[:3], dtype=np.float64)))
        for s in IR_SENSORS:
            d = sharp_voltage_to_distance(volts[s.index])  # ±inf as REP-117, never NaN here
            self.ir_pubs[s.name].publish(self._range(s, d, Range.INFRARED))
        self.battery_pub.publish(BatteryLevel(value=battery_volts_from_counts(int(values[BATTERY_ADC_INDEX]))))
