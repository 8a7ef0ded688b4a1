"""Range-sensor safety: the forward-motion veto (pure core) and the ``emergency_status`` node.

The veto forbids forward motion while an IR or PING return lies in the robot's path closer
than ``veto_distance`` (default 0.25 m) to its front; turning and reversing stay allowed so the robot can get
itself out. The board node applies it last before GOSPD, so every command source is covered.
A reading of ``+inf`` (nothing in range, REP-117) or NaN never vetoes, ``-inf`` (closer than
the sensor can measure) always does; a sensor that stops reporting
keeps its last value until ``stale_after`` seconds pass.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from eddiebot.core.node import Node
from eddiebot.msgs.eddiebot_msgs import GetStatus
from eddiebot.msgs.sensor_msgs import Range
from eddiebot.msgs.std_msgs import Bool

__all__ = ["SafetyConfig", "SafetyNode", "VetoState", "forward_veto"]


@dataclass(frozen=True)
class SafetyConfig:
    veto_distance: float = 0.25
    enabled: bool = True


@dataclass
class VetoState:
    """Latest range per sensor (m), and which of them see something in the robot's way.

    A reading becomes a point in the base frame through its sensor's mount (``mounts``:
    name → (x, y, yaw) in base_link, from the sensor table). Forward motion is vetoed when a
    point lies in the corridor the robot would sweep — within ``robot_radius`` + 2 cm of the
    centre line — and closer than ``veto_distance`` to the robot's front. Door jambs beside
    the robot (a 0.9 m door leaves 0.22 m each side) therefore do not stop it, a wall ahead
    does. Sensors without a mount fall back to the plain range test.
    """

    ranges: dict[str, float] = field(default_factory=dict)
    veto_distance: float = 0.25
    mounts: dict[str, tuple[float, float, float]] = field(default_factory=dict)
    robot_radius: float = 0.2245

    def update(self, ranges: dict[str, float]) -> None:
        self.ranges.update(ranges)

    @property
    def vetoed(self) -> bool:
        return bool(self.too_close())

    def too_close(self, distance: float | None = None) -> list[str]:
        d = self.veto_distance if distance is None else distance
        out = []
        for name, r in self.ranges.items():
            if math.isnan(r) or r == math.inf:
                continue
            mount = self.mounts.get(name)
            if mount is None:
                # -inf is REP-117's "too close to measure": the most urgent reading of all
                if r == -math.inf or r < d:
                    out.append(name)
                continue
            mx, my, myaw = mount
            rr = 0.0 if r == -math.inf else r
            px, py = mx + rr * math.cos(myaw), my + rr * math.sin(myaw)
            if abs(py) <= self.robot_radius + 0.02 and 0.0 <= px <= self.robot_radius + d:
                out.append(name)
        return out


def forward_veto(linear: float, state: VetoState, config: SafetyConfig) -> float:
    """``linear`` with forward motion removed while an obstacle is too close."""
    if not config.enabled or linear <= 0.0:
        return linear
    return 0.0 if state.too_close(config.veto_distance) else linear


class SafetyNode(Node):
    """Watches the range topics; serves the original ``emergency_status`` (GetStatus) and
    publishes ``/eddie/safety_veto`` (Bool) whenever the answer changes."""

    default_node_name = "eddie_safety"
    TOPICS = ("/eddie/ir/left", "/eddie/ir/center", "/eddie/ir/right",
              "/eddie/ping/left", "/eddie/ping/right")

    def __init__(self, node_name: str = default_node_name, **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        self.config = SafetyConfig(
            veto_distance=float(self.declare_parameter("veto_distance", 0.25).value),
            enabled=bool(self.declare_parameter("veto_enabled", True).value),
        )
        from eddiebot.robot.constants import IR_SENSORS, PING_SENSORS

        self.state = VetoState(
            veto_distance=self.config.veto_distance,
            mounts={s.name: (s.x_m, s.y_m, s.yaw_rad) for s in (*IR_SENSORS, *PING_SENSORS)},
        )
        self._last: bool | None = None
        self.pub = self.create_publisher(Bool, "/eddie/safety_veto", 10)
        for topic in self.TOPICS:
            self.create_subscription(Range, topic, self._make_cb(topic.rsplit("/", 2)[-2:]), 10)
        self.create_service(GetStatus, "emergency_status", self._status)

    def _make_cb(self, parts: list[str]) -> Any:
        name = "_".join(parts)

        def cb(msg: Any) -> None:
            self.state.update({name: float(msg.range)})
            vetoed = self.config.enabled and self.state.vetoed
            if vetoed != self._last:
                self._last = vetoed
                self.pub.publish(Bool(data=vetoed))

        return cb

    def _status(self, req: Any, res: Any) -> Any:
        res.okay = not (self.config.enabled and self.state.vetoed)
        return res
