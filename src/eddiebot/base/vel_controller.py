"""Velocity controller node: ``/cmd_vel`` (Twist) → ``/eddie/simple_velocity`` (Velocity).

Clamps to ``max_linear_velocity`` / ``max_angular_velocity`` (REP-103 units and signs) and
forwards each command once; it never repeats a command, so when ``/cmd_vel`` goes silent
the board node's stale-command timeout stops the motors. Non-finite commands become zero.
"""

from __future__ import annotations

import math
from typing import Any

from eddiebot.core.node import Node
from eddiebot.core.parameters import Parameter, SetParametersResult
from eddiebot.msgs.eddiebot_msgs import Velocity
from eddiebot.msgs.geometry_msgs import Twist

__all__ = ["VelocityControllerNode", "clamp_twist"]


def clamp_twist(linear: float, angular: float, max_linear: float, max_angular: float) -> tuple[float, float]:
    """Clamp each axis to its limit; NaN/Inf → 0 (never drive on garbage)."""
    if not (math.isfinite(linear) and math.isfinite(angular)):
        return 0.0, 0.0
    return (
        max(-max_linear, min(max_linear, linear)),
        max(-max_angular, min(max_angular, angular)),
    )


class VelocityControllerNode(Node):
    default_node_name = "eddie_vel_controller"

    def __init__(self, node_name: str = default_node_name, **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        self.max_linear = float(self.declare_parameter("max_linear_velocity", 0.5).value)
        self.max_angular = float(self.declare_parameter("max_angular_velocity", 2.0).value)
        self.pub = self.create_publisher(Velocity, "/eddie/simple_velocity", 5)
        self.create_subscription(Twist, "cmd_vel", self._on_twist, 5)
        self.add_on_set_parameters_callback(self._on_set_limits)

    def _on_set_limits(self, params: list[Parameter]) -> SetParametersResult:
        for prm in params:
            if prm.name == "max_linear_velocity":
                self.max_linear = float(prm.value)
            elif prm.name == "max_angular_velocity":
                self.max_angular = float(prm.value)
        return SetParametersResult(True)

    def _on_twist(self, msg: Any) -> None:
        v, w = clamp_twist(msg.linear.x, msg.angular.z, self.max_linear, self.max_angular)
        self.pub.publish(Velocity(linear=v, angular=w))
