"""Control and decorator nodes: BehaviorTree.CPP v4's built-ins and Nav2's own.

BT.CPP: ``Sequence``, ``SequenceWithMemory`` (v3 ``SequenceStar``), ``ReactiveSequence``,
``Fallback``, ``ReactiveFallback``, ``Parallel``, ``IfThenElse``, ``WhileDoElse``;
decorators ``Inverter``, ``ForceSuccess``, ``ForceFailure``, ``KeepRunningUntilFailure``,
``Repeat``, ``RetryUntilSuccessful``, ``Timeout``, ``Delay``; leaves ``AlwaysSuccess``, ``AlwaysFailure``,
``SetBlackboard``. Nav2 (nav2_behavior_tree): ``PipelineSequence``, ``RecoveryNode``,
``RoundRobin``, ``RateController``, ``DistanceController``, ``SpeedController``,
``GoalUpdatedController``, ``GoalUpdater``, ``PathLongerOnApproach``, ``SingleTrigger``.
Each follows its upstream ``tick()``/``halt()`` line by line; the reactive nodes halt every
other child when one is running, as BT.CPP v4 does.
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

from eddiebot.nav.bt.core import (
    ControlNode,
    DecoratorNode,
    LeafNode,
    Port,
    PortDirection,
    Status,
    input_port,
    output_port,
)

__all__ = ["CONTROL_NODES"]

S, F, R, K = Status.SUCCESS, Status.FAILURE, Status.RUNNING, Status.SKIPPED


# -- BT.CPP controls ------------------------------------------------------------------------
class Sequence(ControlNode):
    """Ticks children in order; resumes at the running child; a failure restarts it."""

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.current = 0
        self.all_skipped = True

    def tick(self) -> Status:
        if self.status == Status.IDLE:
            self.all_skipped = True
        self.status = R
        while self.current < len(self.children):
            s = self.children[self.current].execute_tick()
            self.all_skipped = self.all_skipped and s == K
            if s == R:
                return R
            if s == F:
                self.reset_children()
                self.current = 0
                return F
            self.current += 1
        self.reset_children()
        self.current = 0
        return K if self.all_skipped else S

    def halt(self) -> None:
        self.current = 0
        super().halt()


class SequenceWithMemory(Sequence):
    """A failure does not restart the sequence: the next tick retries the failed child."""

    def tick(self) -> Status:
        if self.status == Status.IDLE:
            self.all_skipped = True
        self.status = R
        while self.current < len(self.children):
            s = self.children[self.current].execute_tick()
            self.all_skipped = self.all_skipped and s == K
            if s == R:
                return R
            if s == F:
                self.reset_children(self.current)
                return F
            self.current += 1
        self.reset_children()
        self.current = 0
        return K if self.all_skipped else S


class ReactiveSequence(ControlNode):
    """Every tick from the first child; the running child halts every other one."""

    def tick(self) -> Status:
        all_skipped = True
        self.status = R
        for i, child in enumerate(self.children):
            s = child.execute_tick()
            all_skipped = all_skipped and s == K
            if s == R:
                for j in range(len(self.children)):
                    if j != i:
                        self.halt_child(j)
                return R
            if s == F:
                self.reset_children()
                return F
            if s == K:
                self.halt_child(i)
        self.reset_children()
        return K if all_skipped else S


class Fallback(ControlNode):
    """Ticks children in order until one does not fail."""

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.current = 0
        self.all_skipped = True

    def tick(self) -> Status:
        if self.status == Status.IDLE:
            self.all_skipped = True
        self.status = R
        while self.current < len(self.children):
            s = self.children[self.current].execute_tick()
            self.all_skipped = self.all_skipped and s == K
            if s == R:
                return R
            if s == S:
                self.reset_children()
                self.current = 0
                return S
            self.current += 1
        self.reset_children()
        self.current = 0
        return K if self.all_skipped else F

    def halt(self) -> None:
        self.current = 0
        super().halt()


class ReactiveFallback(ControlNode):
    """Every tick from the first child; the first one not failing decides."""

    def tick(self) -> Status:
        all_skipped = True
        self.status = R
        for i, child in enumerate(self.children):
            s = child.execute_tick()
            all_skipped = all_skipped and s == K
            if s == R:
                for j in range(len(self.children)):
                    if j != i:
                        self.halt_child(j)
                return R
            if s == S:
                self.reset_children()
                return S
            if s == K:
                self.halt_child(i)
        self.reset_children()
        return K if all_skipped else F


class Parallel(ControlNode):
    """Ticks every unfinished child each tick; SUCCESS once ``success_count`` children
    succeeded, FAILURE once ``failure_count`` failed (-1: all of them)."""

    PORTS: ClassVar[dict[str, Port]] = {
        "success_count": input_port(int, -1, "children that must succeed (-1: all)"),
        "failure_count": input_port(int, 1, "children that fail the node (-1: all)"),
    }

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.done: set[int] = set()
        self.successes = 0
        self.failures = 0

    def _threshold(self, name: str) -> int:
        n = int(self.get_input(name))
        return len(self.children) + n + 1 if n < 0 else n

    def tick(self) -> Status:
        need_s, need_f = self._threshold("success_count"), self._threshold("failure_count")
        self.status = R
        for i, child in enumerate(self.children):
            if i in self.done:
                continue
            s = child.execute_tick()
            if s == S:
                self.done.add(i)
                self.successes += 1
            elif s == F:
                self.done.add(i)
                self.failures += 1
            if self.successes >= need_s:
                self._clear()
                return S
            if self.failures >= need_f or len(self.children) - self.failures < need_s:
                self._clear()
                return F
        return R

    def _clear(self) -> None:
        self.reset_children()
        self.done.clear()
        self.successes = self.failures = 0

    def halt(self) -> None:
        self._clear()


class IfThenElse(ControlNode):
    """Child 1 is the condition; child 2 runs on its SUCCESS, child 3 (or FAILURE) else."""

    MIN_CHILDREN = 2
    MAX_CHILDREN = 3

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.current = 0

    def tick(self) -> Status:
        self.status = R
        if self.current == 0:
            c = self.children[0].execute_tick()
            if c == R:
                return R
            if c == S:
                self.current = 1
            elif len(self.children) == 3:
                self.current = 2
            else:
                self.reset_children()
                return F
        s = self.children[self.current].execute_tick()
        if s == R:
            return R
        self.reset_children()
        self.current = 0
        return s

    def halt(self) -> None:
        self.current = 0
        super().halt()


class WhileDoElse(ControlNode):
    """Reactive IfThenElse: the condition is ticked every time; a change halts the branch
    that was running."""

    MIN_CHILDREN = 2
    MAX_CHILDREN = 3

    def tick(self) -> Status:
        self.status = R
        c = self.children[0].execute_tick()
        if c == R:
            return R
        if c == S:
            if len(self.children) == 3:
                self.halt_child(2)
            s = self.children[1].execute_tick()
        elif len(self.children) == 3:
            self.halt_child(1)
            s = self.children[2].execute_tick()
        else:
            s = F
        if s != R:
            self.reset_children()
        return s


# -- BT.CPP decorators ----------------------------------------------------------------------
class Inverter(DecoratorNode):
    def tick(self) -> Status:
        self.status = R
        s = self.child.execute_tick()
        return {S: F, F: S}.get(s, s)


class ForceSuccess(DecoratorNode):
    def tick(self) -> Status:
        self.status = R
        s = self.child.execute_tick()
        return S if s in (S, F) else s


class ForceFailure(DecoratorNode):
    def tick(self) -> Status:
        self.status = R
        s = self.child.execute_tick()
        return F if s in (S, F) else s


class KeepRunningUntilFailure(DecoratorNode):
    def tick(self) -> Status:
        self.status = R
        s = self.child.execute_tick()
        if s == S:
            self.reset_child()
            return R
        if s == F:
            self.reset_child()
        return s


class Repeat(DecoratorNode):
    """Ticks the child until it succeeded ``num_cycles`` times (-1: forever)."""

    PORTS: ClassVar[dict[str, Port]] = {
        "num_cycles": input_port(int, description="repetitions (-1: infinite)")}

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.count = 0

    def tick(self) -> Status:
        n = int(self.get_input("num_cycles", 1))
        self.status = R
        while self.count < n or n == -1:
            s = self.child.execute_tick()
            if s == S:
                self.count += 1
                self.reset_child()
            elif s == F:
                self.count = 0
                self.reset_child()
                return F
            elif s == K:
                self.reset_child()
                return K
            else:
                return R
        self.count = 0
        return S

    def halt(self) -> None:
        self.count = 0
        super().halt()


class RetryUntilSuccessful(DecoratorNode):
    """Ticks the child again after a failure, ``num_attempts`` times in all (-1: forever)."""

    PORTS: ClassVar[dict[str, Port]] = {
        "num_attempts": input_port(int, description="attempts (-1: infinite)")}

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.tries = 0

    def tick(self) -> Status:
        n = int(self.get_input("num_attempts", 1))
        self.status = R
        while self.tries < n or n == -1:
            s = self.child.execute_tick()
            if s == S:
                self.tries = 0
                self.reset_child()
                return S
            if s == F:
                self.tries += 1
                self.reset_child()
                continue
            if s == K:
                self.reset_child()
            return s
        self.tries = 0
        return F

    def halt(self) -> None:
        self.tries = 0
        super().halt()


class Timeout(DecoratorNode):
    """BT.CPP Timeout: halts the child and fails once it ran ``msec`` ms."""

    PORTS: ClassVar[dict[str, Port]] = {
        "msec": input_port(int, description="After a certain amount of time, halt() the child "
                           "if it is still running.")}

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.start = 0

    def tick(self) -> Status:
        now = self.context.now_ns()
        if self.status in (Status.IDLE, K):
            self.start = now
        self.status = R
        if now - self.start >= int(self.get_input("msec", 0)) * 1_000_000:
            self.reset_child()
            return F
        s = self.child.execute_tick()
        if s != R:
            self.reset_child()
        return s


class Delay(DecoratorNode):
    """BT.CPP Delay: RUNNING for ``delay_msec`` ms, then ticks the child."""

    PORTS: ClassVar[dict[str, Port]] = {
        "delay_msec": input_port(int, description="Tick the child after a few milliseconds")}

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.start = 0

    def tick(self) -> Status:
        now = self.context.now_ns()
        if self.status in (Status.IDLE, K):
            self.start = now
        self.status = R
        if now - self.start < int(self.get_input("delay_msec", 0)) * 1_000_000:
            return R
        s = self.child.execute_tick()
        if s != R:
            self.reset_child()
        return s


# -- BT.CPP leaves -------------------------------------------------------------------------
class AlwaysSuccess(LeafNode):
    def tick(self) -> Status:
        return S


class AlwaysFailure(LeafNode):
    def tick(self) -> Status:
        return F


class SetBlackboard(LeafNode):
    PORTS: ClassVar[dict[str, Port]] = {
        "value": input_port(str, description="value to write"),
        "output_key": Port(PortDirection.INOUT, object, description="entry to write"),
    }

    def tick(self) -> Status:
        raw = self.config.ports.get("value", "")
        from eddiebot.nav.bt.core import blackboard_key

        key = blackboard_key(raw)
        value = self.config.blackboard.get(key) if key else raw
        self.set_output("output_key", value)
        return S


# -- Nav2 controls --------------------------------------------------------------------------
class PipelineSequence(ControlNode):
    """nav2 PipelineSequence: re-ticks every child up to the furthest one running."""

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.last_child_ticked = 0

    def tick(self) -> Status:
        skipped = 0
        for i, child in enumerate(self.children):
            s = child.execute_tick()
            if s == F:
                self.reset_children()
                self.last_child_ticked = 0
                return F
            if s == K:
                skipped += 1
            elif s == R and i >= self.last_child_ticked:
                self.last_child_ticked = i
                return R
        self.reset_children()
        self.last_child_ticked = 0
        return K if skipped == len(self.children) else S

    def halt(self) -> None:
        super().halt()
        self.last_child_ticked = 0


class RecoveryNode(ControlNode):
    """nav2 RecoveryNode: on the first child's failure tick the second (the recovery); if
    it succeeds, retry the first — at most ``number_of_retries`` times."""

    MIN_CHILDREN = 2
    MAX_CHILDREN = 2
    PORTS: ClassVar[dict[str, Port]] = {
        "number_of_retries": input_port(int, 1, "Number of retries")}

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.current = 0
        self.retry_count = 0

    def tick(self) -> Status:
        retries = int(self.get_input("number_of_retries"))
        self.status = R
        while self.current < 2 and self.retry_count <= retries:
            s = self.children[self.current].execute_tick()
            if self.current == 0:
                if s == K:
                    self.halt()
                    return K
                if s == S:
                    self.halt()
                    return S
                if s == R:
                    return R
                if self.retry_count < retries:
                    self.halt_child(0)
                    self.current = 1
                    continue
                self.halt()
                return F
            if s == K:
                self.current = 0
                self.halt_child(1)
                return F
            if s == R:
                return R
            if s == S:
                self.halt_child(1)
                self.retry_count += 1
                self.current = 0
                continue
            self.halt()
            return F
        self.halt()
        return F

    def halt(self) -> None:
        super().halt()
        self.retry_count = 0
        self.current = 0


class RoundRobin(ControlNode):
    """nav2 RoundRobin: ticks the current child; when it ends, the next one is current, so
    each recovery in turn gets its chance; FAILURE only when every child failed in a row."""

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.current = 0
        self.failed = 0

    def tick(self) -> Status:
        n = len(self.children)
        self.status = R
        skipped = 0
        while self.failed + skipped < n:
            s = self.children[self.current].execute_tick()
            if s != R:
                self.current = (self.current + 1) % n
            if s == S:
                self.failed = 0
                self.reset_children()
                return S
            if s == F:
                self.failed += 1
            elif s == K:
                skipped += 1
            else:
                return R
        self.halt()
        return K if skipped == n else F

    def halt(self) -> None:
        super().halt()
        self.current = 0
        self.failed = 0


# -- Nav2 decorators ------------------------------------------------------------------------
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


CONTROL_NODES: dict[str, type] = {
    cls.__name__: cls
    for cls in (Sequence, SequenceWithMemory, ReactiveSequence, Fallback, ReactiveFallback,
                Parallel, IfThenElse, WhileDoElse, Inverter, ForceSuccess, ForceFailure,
                KeepRunningUntilFailure, Repeat, RetryUntilSuccessful, Timeout, Delay,
                AlwaysSuccess,
                AlwaysFailure, SetBlackboard, PipelineSequence, RecoveryNode, RoundRobin,
                RateController, DistanceController, SpeedController, GoalUpdatedController,
                GoalUpdater, PathLongerOnApproach, SingleTrigger)
}
