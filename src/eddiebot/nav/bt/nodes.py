"""Nav2's behaviour-tree nodes on py_trees.

Control nodes with BehaviorTree.CPP / Nav2 semantics (``PipelineSequence``,
``RecoveryNode``, ``ReactiveFallback``, ``RoundRobin``, ``RateController``), conditions
(``GoalUpdated``, ``WouldARecoveryHelp``) and action nodes that talk to the servers. No
``update()`` ever blocks: an action node sends its goal through an ``ActionClient`` in
``initialise()`` and polls the futures on every tick; halting it (``stop(INVALID)``) cancels
the goal. The blackboard is a :class:`NavBlackboard` instance handed to every node.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

from py_trees.behaviour import Behaviour
from py_trees.common import Status
from py_trees.composites import Composite
from py_trees.decorators import Decorator

__all__ = [
    "ActionNode",
    "BackUp",
    "ClearEntireCostmap",
    "ComputePathThroughPoses",
    "ComputePathToPose",
    "FollowPath",
    "GoalUpdated",
    "NavBlackboard",
    "PipelineSequence",
    "RateController",
    "ReactiveFallback",
    "RecoveryNode",
    "RemovePassedGoals",
    "RoundRobin",
    "Spin",
    "Wait",
    "WouldARecoveryHelp",
    "tick_child",
]

#: planner/controller codes no recovery can fix (Nav2's WouldA*RecoveryHelp lists the others)
_HOPELESS = {201, 203, 204, 205, 206, 301, 303, 304, 305, 306, 101, 103}


@dataclass
class NavBlackboard:
    """What the tree's nodes share for one navigation (Nav2's blackboard keys)."""

    goal: Any = None
    goals: list[Any] = field(default_factory=list)
    goal_version: int = 0
    path: Any = None
    path_version: int = 0
    planner_id: str = ""
    controller_id: str = ""
    goal_checker_id: str = ""
    progress_checker_id: str = ""
    number_of_recoveries: int = 0
    error_code: int = 0
    error_msg: str = ""
    #: the robot's (x, y, yaw) in the goals' frame, or None (set by the navigator)
    robot_pose: Callable[[], Any] | None = None

    def set_goal(self, goal: Any) -> None:
        self.goal = goal
        self.goal_version += 1

    def set_goals(self, goals: list[Any]) -> None:
        self.goals = list(goals)
        self.goal_version += 1

    def fail(self, code: int, msg: str) -> None:
        self.error_code = int(code)
        self.error_msg = msg


def tick_child(child: Behaviour) -> Status:
    """Tick ``child`` once (run its generator through) and return its new status."""
    for _ in child.tick():
        pass
    return child.status


def _halt(child: Behaviour) -> None:
    if child.status != Status.INVALID:
        child.stop(Status.INVALID)


class _Control(Composite):
    """A control node whose ``decide()`` ticks children with :func:`tick_child`."""

    def decide(self) -> Status:  # pragma: no cover - interface
        raise NotImplementedError

    def tick(self) -> Iterator[Behaviour]:
        if self.status != Status.RUNNING:
            self.initialise()
        status = self.decide()
        if status == Status.RUNNING:
            self.status = status
        else:
            self.stop(status)
        yield self

    def halt_children(self, start: int = 0) -> None:
        for child in self.children[start:]:
            _halt(child)


class PipelineSequence(_Control):
    """nav2 PipelineSequence: re-tick every child up to the furthest one running."""

    def __init__(self, name: str, children: Sequence[Behaviour]) -> None:
        super().__init__(name, list(children))
        self.last_child_ticked = 0

    def decide(self) -> Status:
        for i, child in enumerate(self.children):
            status = tick_child(child)
            if status == Status.FAILURE:
                self.halt_children()
                self.last_child_ticked = 0
                return Status.FAILURE
            if status == Status.RUNNING and i >= self.last_child_ticked:
                self.last_child_ticked = i
                return Status.RUNNING
        self.halt_children()
        self.last_child_ticked = 0
        return Status.SUCCESS

    def terminate(self, new_status: Status) -> None:
        if new_status == Status.INVALID:
            self.last_child_ticked = 0


class RecoveryNode(_Control):
    """nav2 RecoveryNode: tick the first child; on failure tick the second (the recovery)
    and, if it succeeds, retry the first — at most ``number_of_retries`` times."""

    def __init__(self, name: str, main: Behaviour, recovery: Behaviour, number_of_retries: int = 1) -> None:
        super().__init__(name, [main, recovery])
        self.number_of_retries = number_of_retries
        self.retry_count = 0
        self.current = 0

    def decide(self) -> Status:
        while self.current < 2 and self.retry_count <= self.number_of_retries:
            child = self.children[self.current]
            status = tick_child(child)
            if self.current == 0:
                if status == Status.SUCCESS:
                    self._reset()
                    return Status.SUCCESS
                if status == Status.RUNNING:
                    return Status.RUNNING
                if self.retry_count < self.number_of_retries:
                    _halt(self.children[0])
                    self.current = 1
                    continue
                self._reset()
                return Status.FAILURE
            if status == Status.SUCCESS:
                _halt(self.children[1])
                self.retry_count += 1
                self.current = 0
                continue
            if status == Status.RUNNING:
                return Status.RUNNING
            self._reset()
            return Status.FAILURE
        self._reset()
        return Status.FAILURE

    def _reset(self) -> None:
        self.halt_children()
        self.retry_count = 0
        self.current = 0

    def terminate(self, new_status: Status) -> None:
        if new_status == Status.INVALID:
            self.retry_count = 0
            self.current = 0


class ReactiveFallback(_Control):
    """BT.CPP ReactiveFallback: every tick from the first child; the first non-failure wins."""

    def decide(self) -> Status:
        for i, child in enumerate(self.children):
            status = tick_child(child)
            if status == Status.RUNNING:
                self.halt_children(i + 1)
                return Status.RUNNING
            if status == Status.SUCCESS:
                self.halt_children()
                return Status.SUCCESS
        self.halt_children()
        return Status.FAILURE


class RoundRobin(_Control):
    """nav2 RoundRobin: tick the current child; on its end move to the next one, so each
    recovery in turn gets a chance; fail only when every child failed in a row."""

    def __init__(self, name: str, children: Sequence[Behaviour]) -> None:
        super().__init__(name, list(children))
        self.index = 0

    def decide(self) -> Status:
        failed = 0
        n = len(self.children)
        while failed < n:
            status = tick_child(self.children[self.index])
            if status == Status.RUNNING:
                return Status.RUNNING
            self.index = (self.index + 1) % n
            if status == Status.SUCCESS:
                self.halt_children()
                return Status.SUCCESS
            failed += 1
        self.halt_children()
        return Status.FAILURE


class SequenceWithMemory(_Control):
    """BT.CPP Sequence: resume at the running child; any failure restarts from the first."""

    def __init__(self, name: str, children: Sequence[Behaviour]) -> None:
        super().__init__(name, list(children))
        self.index = 0

    def decide(self) -> Status:
        while self.index < len(self.children):
            status = tick_child(self.children[self.index])
            if status == Status.RUNNING:
                return Status.RUNNING
            if status == Status.FAILURE:
                self.halt_children()
                self.index = 0
                return Status.FAILURE
            self.index += 1
        self.halt_children()
        self.index = 0
        return Status.SUCCESS

    def terminate(self, new_status: Status) -> None:
        if new_status == Status.INVALID:
            self.index = 0


class RateController(Decorator):
    """nav2 RateController: tick the child at most ``hz`` times a second (always while it
    runs); between ticks report RUNNING, as Nav2 does."""

    def __init__(self, name: str, child: Behaviour, hz: float, clock: Callable[[], int]) -> None:
        super().__init__(name, child)
        self.period_ns = round(1e9 / hz)
        self.clock = clock
        self._start = 0
        self._first = True

    def tick(self) -> Iterator[Behaviour]:
        now = self.clock()
        if self.status == Status.INVALID:  # BT.CPP's IDLE: fresh or halted
            self._start = now
            self._first = True
        self.status = Status.RUNNING
        if self._first or self.decorated.status == Status.RUNNING or now - self._start >= self.period_ns:
            self._first = False
            status = tick_child(self.decorated)
            if status == Status.SUCCESS:
                self._start = now
            if status != Status.RUNNING:
                self.stop(status)
        yield self

    def update(self) -> Status:
        return self.status

    def terminate(self, new_status: Status) -> None:
        if new_status == Status.INVALID:
            _halt(self.decorated)


class GoalUpdated(Behaviour):
    """SUCCESS when the blackboard goal changed since this node last looked."""

    def __init__(self, bb: NavBlackboard, name: str = "GoalUpdated") -> None:
        super().__init__(name)
        self.bb = bb
        self._seen: int | None = None

    def update(self) -> Status:
        if self._seen is None:
            self._seen = self.bb.goal_version
            return Status.FAILURE
        if self.bb.goal_version != self._seen:
            self._seen = self.bb.goal_version
            return Status.SUCCESS
        return Status.FAILURE


class WouldARecoveryHelp(Behaviour):
    """FAILURE when the last error is one no recovery can fix (goal outside the map or
    occupied, unknown planner/controller, invalid path) — so such goals abort at once."""

    def __init__(self, bb: NavBlackboard, name: str = "WouldARecoveryHelp") -> None:
        super().__init__(name)
        self.bb = bb

    def update(self) -> Status:
        return Status.FAILURE if self.bb.error_code in _HOPELESS else Status.SUCCESS


def _cancel_when_accepted(future: Any) -> None:
    if future.exception() is None and future.result().accepted:
        future.result().cancel_goal_async()


class RemovePassedGoals(Behaviour):
    """nav2 RemovePassedGoals: drop leading goals within ``radius`` (m) of the robot, keeping
    the last one, so replanning through poses never sends the robot back."""

    def __init__(self, bb: NavBlackboard, radius: float = 0.7, name: str = "RemovePassedGoals") -> None:
        super().__init__(name)
        self.bb = bb
        self.radius = radius

    def update(self) -> Status:
        pose = self.bb.robot_pose() if self.bb.robot_pose is not None else None
        if pose is None:
            return Status.SUCCESS
        while len(self.bb.goals) > 1:
            g = self.bb.goals[0].pose.position
            if math.hypot(g.x - pose[0], g.y - pose[1]) > self.radius:
                break
            self.bb.goals.pop(0)
        return Status.SUCCESS


class ActionNode(Behaviour):
    """Sends a goal on ``initialise()``, polls its futures on ``update()``, cancels on halt."""

    #: recoveries count towards the navigation's ``number_of_recoveries``
    is_recovery = False

    def __init__(self, name: str, client: Any, bb: NavBlackboard, clock: Callable[[], int],
                 server_timeout_s: float = 1.0) -> None:
        super().__init__(name)
        self.client = client
        self.bb = bb
        self.clock = clock
        self.server_timeout_ns = round(server_timeout_s * 1e9)
        self._goal_future: Any = None
        self._handle: Any = None
        self._result_future: Any = None
        self._since = 0

    def make_goal(self) -> Any:  # pragma: no cover - interface
        raise NotImplementedError

    def on_success(self, result: Any) -> None:
        """Copy outputs to the blackboard."""

    def initialise(self) -> None:
        if self.is_recovery:
            self.bb.number_of_recoveries += 1
        self._since = self.clock()
        self._send()

    def _send(self) -> None:
        self._handle = self._result_future = None
        self._goal_future = None
        if self.client.server_is_ready():
            self._goal_future = self.client.send_goal_async(self.make_goal())

    def update(self) -> Status:
        if self._goal_future is None:
            if self.client.server_is_ready():
                self._goal_future = self.client.send_goal_async(self.make_goal())
            elif self.clock() - self._since > self.server_timeout_ns:
                self.bb.fail(0, f"{self.name}: action server {self.client.action_name} not available")
                return Status.FAILURE
            return Status.RUNNING
        if not self._goal_future.done():
            return Status.RUNNING
        if self._handle is None:
            if self._goal_future.exception() is not None:
                self.bb.fail(0, f"{self.name}: {self._goal_future.exception()}")
                return Status.FAILURE
            self._handle = self._goal_future.result()
            if not self._handle.accepted:
                self.bb.fail(0, f"{self.name}: goal rejected")
                return Status.FAILURE
            self._result_future = self._handle.get_result_async()
        if not self._result_future.done():
            return self.while_running()
        response = self._result_future.result()
        self._handle = None
        if int(response.status) == 4:  # STATUS_SUCCEEDED
            self.on_success(response.result)
            return Status.SUCCESS
        code = int(getattr(response.result, "error_code", 0))
        msg = str(getattr(response.result, "error_msg", ""))
        self.bb.fail(code, f"{self.name}: {msg or 'failed'} (status {int(response.status)})")
        return Status.FAILURE

    def while_running(self) -> Status:
        return Status.RUNNING

    def terminate(self, new_status: Status) -> None:
        if new_status != Status.INVALID:
            return
        handle = self._handle
        if handle is None and self._goal_future is not None and self._goal_future.done() \
                and self._goal_future.exception() is None:
            handle = self._goal_future.result()
        running = self._result_future is None or not self._result_future.done()
        if handle is not None and handle.accepted and running:
            handle.cancel_goal_async()
        elif handle is None and self._goal_future is not None and not self._goal_future.done():
            self._goal_future.add_done_callback(_cancel_when_accepted)
        self._handle = self._result_future = self._goal_future = None


class ComputePathToPose(ActionNode):
    def make_goal(self) -> Any:
        from eddiebot.msgs.nav2_msgs import ComputePathToPose as Action

        return Action.Goal(goal=self.bb.goal, planner_id=self.bb.planner_id, use_start=False)

    def on_success(self, result: Any) -> None:
        self.bb.path = result.path
        self.bb.path_version += 1


class ComputePathThroughPoses(ActionNode):
    def make_goal(self) -> Any:
        from eddiebot.msgs.nav2_msgs import ComputePathThroughPoses as Action

        return Action.Goal(goals=list(self.bb.goals), planner_id=self.bb.planner_id, use_start=False)

    def on_success(self, result: Any) -> None:
        self.bb.path = result.path
        self.bb.path_version += 1


class FollowPath(ActionNode):
    """Follows the blackboard path; a new path is sent to the running controller (Nav2's
    preemption), so replanning never stops the robot."""

    def make_goal(self) -> Any:
        from eddiebot.msgs.nav2_msgs import FollowPath as Action

        self._sent_version = self.bb.path_version
        return Action.Goal(path=self.bb.path, controller_id=self.bb.controller_id,
                           goal_checker_id=self.bb.goal_checker_id,
                           progress_checker_id=self.bb.progress_checker_id)

    def while_running(self) -> Status:
        if self.bb.path_version != getattr(self, "_sent_version", self.bb.path_version):
            self._goal_future = self.client.send_goal_async(self.make_goal())
            self._handle = self._result_future = None
        return Status.RUNNING


class Spin(ActionNode):
    is_recovery = True

    def __init__(self, *args: Any, spin_dist: float = 1.57, time_allowance: float = 10.0, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.spin_dist = spin_dist
        self.time_allowance = time_allowance

    def make_goal(self) -> Any:
        from eddiebot.core.time import Duration
        from eddiebot.msgs.nav2_msgs import Spin as Action

        return Action.Goal(target_yaw=self.spin_dist,
                           time_allowance=Duration.from_seconds(self.time_allowance).to_msg())


class BackUp(ActionNode):
    is_recovery = True

    def __init__(self, *args: Any, backup_dist: float = 0.30, backup_speed: float = 0.05,
                 time_allowance: float = 10.0, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.backup_dist = backup_dist
        self.backup_speed = backup_speed
        self.time_allowance = time_allowance

    def make_goal(self) -> Any:
        from eddiebot.core.time import Duration
        from eddiebot.msgs.geometry_msgs import Point
        from eddiebot.msgs.nav2_msgs import BackUp as Action

        return Action.Goal(target=Point(x=-abs(self.backup_dist), y=0.0, z=0.0),
                           speed=abs(self.backup_speed),
                           time_allowance=Duration.from_seconds(self.time_allowance).to_msg())


class Wait(ActionNode):
    is_recovery = True

    def __init__(self, *args: Any, wait_duration: float = 5.0, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.wait_duration = wait_duration

    def make_goal(self) -> Any:
        from eddiebot.core.time import Duration
        from eddiebot.msgs.nav2_msgs import Wait as Action

        return Action.Goal(time=Duration.from_seconds(self.wait_duration).to_msg())


class ClearEntireCostmap(Behaviour):
    """Calls a ``clear_entirely_*`` service without blocking."""

    def __init__(self, name: str, client: Any, bb: NavBlackboard) -> None:
        super().__init__(name)
        self.client = client
        self.bb = bb
        self._future: Any = None

    def initialise(self) -> None:
        from eddiebot.msgs.nav2_msgs import ClearEntireCostmap as Srv

        self._future = self.client.call_async(Srv.Request()) if self.client.service_is_ready() else None

    def update(self) -> Status:
        if self._future is None:
            return Status.FAILURE
        if not self._future.done():
            return Status.RUNNING
        return Status.FAILURE if self._future.exception() is not None else Status.SUCCESS


def path_length_from(path_xy: Any, x: float, y: float) -> float:
    """Length of ``path_xy`` ((N, 2), m) from its pose closest to (x, y) to its end."""
    import numpy as np

    p = np.asarray(path_xy, dtype=np.float64).reshape(-1, 2)
    if p.shape[0] == 0:
        return 0.0
    i = int(np.argmin(np.hypot(p[:, 0] - x, p[:, 1] - y)))
    seg = np.hypot(np.diff(p[i:, 0]), np.diff(p[i:, 1]))
    return float(math.hypot(p[i, 0] - x, p[i, 1] - y) + seg.sum())
