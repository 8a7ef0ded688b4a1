"""The board's health as ROS messages: ``sensor_msgs/BatteryState`` and one
``diagnostic_msgs/DiagnosticStatus`` (pure builders; the board node publishes them)."""

from __future__ import annotations

import math
from typing import Any

from eddiebot.core.time import ns_to_stamp
from eddiebot.msgs.diagnostic_msgs import DiagnosticArray, DiagnosticStatus, KeyValue
from eddiebot.msgs.sensor_msgs import BatteryState

__all__ = ["battery_state_msg", "diagnostic_array"]


def battery_state_msg(volts: float, stamp_ns: int, cutoff_v: float) -> Any:
    """Eddie's 12 V lead-acid pair as BatteryState: only the voltage is measured (ADC 7
    through the 3.21 divider); unmeasured fields are NaN as REP/sensor_msgs asks."""
    msg = BatteryState()
    msg.header.stamp = ns_to_stamp(stamp_ns)
    msg.voltage = float(volts)
    msg.current = math.nan
    msg.charge = math.nan
    msg.capacity = math.nan
    msg.design_capacity = math.nan
    msg.percentage = math.nan
    msg.temperature = math.nan
    msg.power_supply_status = BatteryState.POWER_SUPPLY_STATUS_DISCHARGING
    msg.power_supply_health = (BatteryState.POWER_SUPPLY_HEALTH_DEAD if volts < cutoff_v
                               else BatteryState.POWER_SUPPLY_HEALTH_GOOD)
    # sensor_msgs has no lead-acid constant
    msg.power_supply_technology = BatteryState.POWER_SUPPLY_TECHNOLOGY_UNKNOWN
    msg.present = volts > 1.0
    msg.location = "base"
    msg.serial_number = ""
    return msg


def diagnostic_array(name: str, hardware_id: str, level: bytes | int, message: str,
                     values: dict[str, str], stamp_ns: int) -> Any:
    """A DiagnosticArray holding one status."""
    status = DiagnosticStatus()
    status.name = name
    status.hardware_id = hardware_id
    status.level = level
    status.message = message
    status.values = [KeyValue(key=k, value=v) for k, v in values.items()]
    msg = DiagnosticArray()
    msg.header.stamp = ns_to_stamp(stamp_ns)
    msg.status = [status]
    return msg
