"""Nav2's decorator nodes (nav2_behavior_tree): ``RateController``,
``DistanceController``, ``SpeedController``, ``GoalUpdatedController``, ``GoalUpdater``,
``PathLongerOnApproach``, ``SingleTrigger``, each following its upstream
``tick()``/``halt()`` on the navigator's clock and TF.
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

from eddiebot.nav.bt.core import DecoratorNode, Port, Status, input_port, output_port

__all__ = [
    "DistanceController", "GoalUpdatedController", "GoalUpdater", "PathLongerOnApproach",
    "RateController", "SingleTrigger", "SpeedController",
]

S, F, R, K = Status.SUCCESS, Status.FAILURE, Status.RUNNING, Status.SKIPPED


class RateController(DecoratorNode):
    """nav2 RateController: ticks the child at most ``hz`` times a second (and on every tick
    while it runs), on the navigator's clock."""

    PORTS: ClassVar[dict[str, Port]] = {"hz": input_port(float, 10.0, "Rate")}

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.period_ns = round(1e9 / float(self.get_input("hz")))
        self.start = 0
        self.first = True

    def tick(self) -> Status:
        now = self.context.now_ns()
        if self.status in (Status.IDLE, K):
            self.start = now
            self.first = True
        self.status = R
        if self.first or self.child.status == R or now - self.start >= self.period_ns:
            self.first = False
            s = self.child.execute_tick()
            if s == R:
                return R
            if s == S:
                self.start = self.context.now_ns()
                return S
            return F
        return self.status


class DistanceController(DecoratorNode):
    """nav2 DistanceController: ticks the child each time the robot travelled ``distance``
    metres since the child last succeeded."""

    PORTS: ClassVar[dict[str, Port]] = {
        "distance": input_port(float, 1.0, "Distance"),
        "global_frame": input_port(str, description="Global frame"),
        "robot_base_frame": input_port(str, description="Robot base frame"),
    }

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.start_pose: Any = None
        self.first = False

    def _pose(self) -> Any:
        return self.context.robot_pose(self.get_input("global_frame"),
                                       self.get_input("robot_base_frame"))

    def tick(self) -> Status:
        if self.status in (Status.IDLE, K):
            self.start_pose = self._pose()
            if self.start_pose is None:
                return F
            self.first = True
        self.status = R
        pose = self._pose()
        if pose is None:
            return F
        travelled = math.hypot(pose[0] - self.start_pose[0], pose[1] - self.start_pose[1])
        if self.first or self.child.status == R or travelled >= float(self.get_input("distance")):
            self.first = False
            s = self.child.execute_tick()
            if s in (R, K):
                return s
            if s == S:
                self.start_pose = self._pose()
                return S if self.start_pose is not None else F
            return F
        return self.status


class SpeedController(DecoratorNode):
    """nav2 SpeedController: ticks the child at a rate between ``min_rate`` and
    ``max_rate`` scaled with the robot's speed; a new goal restarts it at ``max_rate``."""

    PORTS: ClassVar[dict[str, Port]] = {
        "min_rate": input_port(float, 0.1, "Minimum rate"),
        "max_rate": input_port(float, 1.0, "Maximum rate"),
        "min_speed": input_port(float, 0.0, "Minimum speed"),
        "max_speed": input_port(float, 0.5, "Maximum speed"),
        "goals": input_port(object, description="Vector of navigation goals"),
        "goal": input_port(object, description="Navigation goal"),
    }

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.min_rate = float(self.get_input("min_rate"))
        self.max_rate = float(self.get_input("max_rate"))
        self.min_speed = float(self.get_input("min_speed"))
        self.max_speed = float(self.get_input("max_speed"))
        if self.min_rate <= 0.0 or self.max_rate <= 0.0:
            raise ValueError("SpeedController node cannot have rate <= 0.0")
        self.period = 1.0 / self.max_rate
        self.start = 0
        self.first = False
        self.goal: Any = None
        self.goals: Any = None

    def scaled_rate(self, speed: float) -> float:
        if speed >= self.max_speed:
            return self.max_rate
        if speed <= self.min_speed:
            return self.min_rate
        d_speed = self.max_speed - self.min_speed
        return (self.max_rate - self.min_rate) / d_speed * (speed - self.min_speed) + self.min_rate

    def tick(self) -> Status:
        now = self.context.now_ns()
        goal, goals = self.get_input_or_blackboard("goal"), self.get_input_or_blackboard("goals")
        if self.status in (Status.IDLE, K) or goal != self.goal or goals != self.goals:
            self.goal, self.goals = goal, goals
            self.period = 1.0 / self.max_rate
            self.start = now
            self.first = True
        self.status = R
        elapsed = (now - self.start) * 1e-9
        if self.first or self.child.status == R or elapsed >= self.period:
            self.first = False
            if elapsed >= self.period:
                self.period = 1.0 / self.scaled_rate(float(self.context.speed()))
                self.start = now
            return self.child.execute_tick()
        return self.status


class GoalUpdatedController(DecoratorNode):
    """nav2 GoalUpdatedController: ticks the child when the goal changed (and while the
    child runs)."""

    PORTS: ClassVar[dict[str, Port]] = {
        "goals": input_port(object, description="Vector of navigation goals"),
        "goal": input_port(object, description="Navigation goal"),
    }

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.goal: Any = None
        self.goals: Any = None
        self.updated = False

    def tick(self) -> Status:
        goal, goals = self.get_input_or_blackboard("goal"), self.get_input_or_blackboard("goals")
        if self.status in (Status.IDLE, K):
            self.goal, self.goals = goal, goals
            self.updated = True
        self.status = R
        if goal != self.goal or goals != self.goals:
            self.goal, self.goals = goal, goals
            self.updated = True
        if self.child.status == R or self.updated:
            self.updated = False
            return self.child.execute_tick()
        return self.status


class GoalUpdater(DecoratorNode):
    """nav2 GoalUpdater: ``output_goal`` is ``input_goal``, or the last pose received on
    the ``goal_updater_topic`` (``goal_update``) when it is newer; then ticks the child."""

    PORTS: ClassVar[dict[str, Port]] = {
        "input_goal": input_port(object, description="Original Goal"),
        "output_goal": output_port(object, "Received Goal by subscription"),
    }

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        if getattr(self.context, "node", None) is not None:
            self.context.latest(self.context.goal_updater_topic)

    def tick(self) -> Status:
        goal = self.get_input("input_goal")
        last = self.context.latest(self.context.goal_updater_topic)
        if last is not None and goal is not None:
            if _stamp_ns(last) > _stamp_ns(goal):
                goal = last
            else:
                self.context.warn(f"{self.name}: the received goal is older than the current "
                                  f"goal; ignored")
        self.set_output("output_goal", goal)
        return self.child.execute_tick()


def _stamp_ns(ps: Any) -> int:
    st = ps.header.stamp
    return int(st.sec) * 1_000_000_000 + int(st.nanosec)


def path_length(path: Any) -> float:
    poses = getattr(path, "poses", None) or []
    total = 0.0
    for a, b in zip(poses, poses[1:]):
        total += math.hypot(b.pose.position.x - a.pose.position.x,
                            b.pose.position.y - a.pose.position.y)
    return total


class PathLongerOnApproach(DecoratorNode):
    """nav2 PathLongerOnApproach: ticks the child when, within ``prox_len`` of the goal, a
    new path is ``length_factor`` times longer than the last one."""

    PORTS: ClassVar[dict[str, Port]] = {
        "path": input_port(object, description="Planned Path"),
        "prox_len": input_port(float, 3.0, "Proximity length (m)"),
        "length_factor": input_port(float, 2.0, "Length multiplication factor"),
    }

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.old_path: Any = None
        self.first = True

    @staticmethod
    def _end(path: Any) -> Any:
        p = path.poses[-1].pose
        return (p.position.x, p.position.y, p.position.z, p.orientation.z, p.orientation.w)

    def tick(self) -> Status:
        new = self.get_input("path")
        prox, factor = float(self.get_input("prox_len")), float(self.get_input("length_factor"))
        old = self.old_path
        new_poses = getattr(new, "poses", None) or []
        old_poses = getattr(old, "poses", None) or []
        if not self.first and (not old_poses or not new_poses or self._end(old) != self._end(new)):
            self.first = True
        self.status = R
        updated = (bool(old_poses) and bool(new_poses) and len(new_poses) != len(old_poses)
                   and self._end(old)[:3] == self._end(new)[:3])
        if updated and path_length(old) < prox and path_length(new) > factor * path_length(old) \
                and not self.first:
            s = self.child.execute_tick()
            if s in (R, K):
                return s
            self.old_path = new
            self.reset_child()
            return s
        self.old_path = new
        self.first = False
        return S


class SingleTrigger(DecoratorNode):
    """nav2 SingleTrigger: ticks the child to completion once, then FAILURE until reset."""

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.first = True

    def tick(self) -> Status:
        if self.status in (Status.IDLE, K):
            self.first = True
        self.status = R
        if self.first:
            s = self.child.execute_tick()
            if s == R:
                return R
            self.first = False
            return S if s == S else F
        return F
