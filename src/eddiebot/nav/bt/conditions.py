"""Nav2's condition nodes: goal updates, error codes, timers, distance, goal reached,
initial pose, battery and TF checks; each returns SUCCESS or FAILURE in one tick.
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

from eddiebot.nav.bt.core import LeafNode, Port, Status, input_port

__all__ = [
    "AreErrorCodesPresent", "DistanceTraveled", "GlobalUpdatedGoal", "GoalReached",
    "GoalUpdated", "InitialPoseReceived", "IsBatteryCharging", "IsBatteryLow",
    "PathExpiringTimer", "TimeExpired", "TransformAvailable", "WouldAControllerRecoveryHelp",
    "WouldAPlannerRecoveryHelp", "WouldASmootherRecoveryHelp",
]

S, F, R = Status.SUCCESS, Status.FAILURE, Status.RUNNING


class GoalUpdated(LeafNode):
    """SUCCESS when ``goal``/``goals`` changed since this node's first tick (after a reset)."""

    PORTS: ClassVar[dict[str, Port]] = {
        "goals": input_port(object, description="Vector of navigation goals"),
        "goal": input_port(object, description="Navigation goal"),
    }

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.goal: Any = None
        self.goals: Any = None

    def _read(self) -> tuple[Any, Any]:
        return self.get_input_or_blackboard("goal"), self.get_input_or_blackboard("goals")

    def tick(self) -> Status:
        if self.status in (Status.IDLE, Status.SKIPPED):
            self.goal, self.goals = self._read()
            return F
        goal, goals = self._read()
        if goal != self.goal or goals != self.goals:
            self.goal, self.goals = goal, goals
            return S
        return F


class GlobalUpdatedGoal(GoalUpdated):
    """Like GoalUpdated, but SUCCESS on its very first tick and never reset by a halt."""

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.first_time = True

    def tick(self) -> Status:
        if self.first_time:
            self.first_time = False
            self.goal, self.goals = self._read()
            return S
        goal, goals = self._read()
        if goal != self.goal or goals != self.goals:
            self.goal, self.goals = goal, goals
            return S
        return F


class AreErrorCodesPresent(LeafNode):
    PORTS: ClassVar[dict[str, Port]] = {
        "error_code": input_port(int, description="The active error codes"),
        "error_codes_to_check": input_port(str, description="Error codes to check, ';'-separated"),
    }
    CODES: ClassVar[frozenset[int]] = frozenset()

    def codes(self) -> frozenset[int]:
        if "error_codes_to_check" not in self.PORTS:
            return self.CODES
        value = self.get_input("error_codes_to_check")
        if value is None:
            return self.CODES
        if isinstance(value, str):  # a literal: "100;104" (or comma-separated)
            return frozenset(int(c) for c in value.replace(",", ";").split(";") if c.strip())
        return frozenset(int(c) for c in value)  # a set of codes from the blackboard

    def tick(self) -> Status:
        code = self.get_input("error_code")
        return S if code is not None and int(code) in self.codes() else F


class WouldAControllerRecoveryHelp(AreErrorCodesPresent):
    # FollowPath UNKNOWN, PATIENCE_EXCEEDED, FAILED_TO_MAKE_PROGRESS, NO_VALID_CONTROL
    CODES = frozenset({100, 104, 105, 106})
    PORTS: ClassVar[dict[str, Port]] = {"error_code": input_port(int, description="The active error codes")}


class WouldAPlannerRecoveryHelp(AreErrorCodesPresent):
    # ComputePathToPose UNKNOWN, NO_VALID_PATH, TIMEOUT; through poses the same
    CODES = frozenset({200, 208, 207, 300, 307, 308})
    PORTS: ClassVar[dict[str, Port]] = {"error_code": input_port(int, description="The active error codes")}


class WouldASmootherRecoveryHelp(AreErrorCodesPresent):
    # SmoothPath UNKNOWN, TIMEOUT, FAILED_TO_SMOOTH_PATH, SMOOTHED_PATH_IN_COLLISION
    CODES = frozenset({500, 502, 504, 503})
    PORTS: ClassVar[dict[str, Port]] = {"error_code": input_port(int, description="The active error codes")}


class PathExpiringTimer(LeafNode):
    """SUCCESS once ``seconds`` passed since the path last changed (then restarts)."""

    PORTS: ClassVar[dict[str, Port]] = {
        "seconds": input_port(float, 1.0, "Seconds"),
        "path": input_port(object, description="Check if path has been updated to enable timer reset"),
    }

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.first_time = True
        self.prev_path: Any = None
        self.start = 0

    def tick(self) -> Status:
        now = self.context.now_ns()
        path = self.get_input("path")
        if self.first_time:
            self.first_time = False
            self.prev_path = path
            self.start = now
            return F
        if path is not self.prev_path and path != self.prev_path:
            self.prev_path = path
            self.start = now
        if (now - self.start) * 1e-9 < float(self.get_input("seconds")):
            return F
        self.start = now
        return S


class TimeExpired(LeafNode):
    PORTS: ClassVar[dict[str, Port]] = {"seconds": input_port(float, 1.0, "Seconds")}

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.start: int | None = None

    def tick(self) -> Status:
        now = self.context.now_ns()
        if self.status in (Status.IDLE, Status.SKIPPED) or self.start is None:
            self.start = now
            return F
        if (now - self.start) * 1e-9 < float(self.get_input("seconds")):
            return F
        self.start = now
        return S


class DistanceTraveled(LeafNode):
    PORTS: ClassVar[dict[str, Port]] = {
        "distance": input_port(float, 1.0, "Distance"),
        "global_frame": input_port(str, description="Global frame"),
        "robot_base_frame": input_port(str, description="Robot base frame"),
    }

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.start: Any = None

    def tick(self) -> Status:
        pose = self.context.robot_pose(self.get_input("global_frame"),
                                       self.get_input("robot_base_frame"))
        if self.status in (Status.IDLE, Status.SKIPPED) or self.start is None:
            self.start = pose
            return F
        if pose is None:
            return F
        if math.hypot(pose[0] - self.start[0], pose[1] - self.start[1]) < float(
                self.get_input("distance")):
            return F
        self.start = pose
        return S


class GoalReached(LeafNode):
    """SUCCESS when the robot is within ``goal_reached_tol`` (0.25 m) of ``goal``."""

    PORTS: ClassVar[dict[str, Port]] = {
        "goal": input_port(object, description="Destination"),
        "global_frame": input_port(str, description="Global frame"),
        "robot_base_frame": input_port(str, description="Robot base frame"),
    }
    TOLERANCE = 0.25

    def tick(self) -> Status:
        goal = self.get_input("goal")
        pose = self.context.robot_pose(self.get_input("global_frame"),
                                       self.get_input("robot_base_frame"))
        if goal is None or pose is None:
            return F
        g = goal.pose.position
        return S if math.hypot(g.x - pose[0], g.y - pose[1]) <= self.TOLERANCE else F


class InitialPoseReceived(LeafNode):
    PORTS: ClassVar[dict[str, Port]] = {
        "initial_pose_received": input_port(bool, description="Initial pose received")}

    def tick(self) -> Status:
        return S if bool(self.get_input_or_blackboard("initial_pose_received", False)) else F


class IsBatteryLow(LeafNode):
    """SUCCESS while the last ``sensor_msgs/BatteryState`` on ``battery_topic`` is at or
    below ``min_battery`` (percentage, or volts with ``is_voltage``)."""

    PORTS: ClassVar[dict[str, Port]] = {
        "min_battery": input_port(float, description="Minimum battery percentage/voltage"),
        "battery_topic": input_port(str, "/battery_status", "Battery topic"),
        "is_voltage": input_port(bool, False, "If true voltage will be used to check for low "
                                 "battery"),
    }

    def _last(self) -> Any:
        from eddiebot.msgs.sensor_msgs import BatteryState

        return self.context.latest(str(self.get_input("battery_topic")), BatteryState)

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        if getattr(self.context, "node", None) is not None:
            self._last()

    def tick(self) -> Status:
        msg = self._last()
        if msg is None:
            return F
        level = msg.voltage if bool(self.get_input("is_voltage")) else msg.percentage
        return S if float(level) <= float(self.get_input("min_battery", 0.0)) else F


class IsBatteryCharging(IsBatteryLow):
    PORTS: ClassVar[dict[str, Port]] = {
        "battery_topic": input_port(str, "/battery_status", "Battery topic")}

    def tick(self) -> Status:
        from eddiebot.msgs.sensor_msgs import BatteryState

        msg = self._last()
        charging = BatteryState.POWER_SUPPLY_STATUS_CHARGING
        return S if msg is not None and int(msg.power_supply_status) == charging else F


class TransformAvailable(LeafNode):
    """SUCCESS once TF gives ``parent`` → ``child`` (then always, as Nav2's node)."""

    PORTS: ClassVar[dict[str, Port]] = {
        "child": input_port(str, "", "Child frame for transform"),
        "parent": input_port(str, "", "parent frame for transform"),
    }

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.was_found = False
        if not self.get_input("child") or not self.get_input("parent"):
            raise ValueError("child and parent frames must both be set")

    def tick(self) -> Status:
        if self.was_found:
            return S
        found = self.context.robot_pose(str(self.get_input("parent")),
                                        str(self.get_input("child"))) is not None
        self.was_found = found
        return S if found else F
