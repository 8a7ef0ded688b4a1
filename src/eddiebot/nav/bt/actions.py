"""Nav2's action nodes (``BtActionNode`` and its plugins) and ``BtCancelActionNode``.

The first tick builds the goal from the ports (``on_tick``) and sends it; later ticks poll
the goal's futures and never block; the server's result maps to ``on_success`` /
``on_aborted`` / ``on_cancelled``, which write the output ports (``path``,
``error_code_id``, …); halting cancels the goal. Each node talks to the action server named
by its ``server_name`` port, or Nav2's default.
"""

from __future__ import annotations

from typing import Any, ClassVar

from eddiebot.nav.bt.core import Port, Status, input_port, output_port
from eddiebot.nav.bt.remote import (
    _STATUS_CANCELED,
    _STATUS_SUCCEEDED,
    _basic,
    _duration,
    _nav2,
    _Remote,
)

__all__ = [
    "RECOVERIES_KEY",
    "AssistedTeleop",
    "BackUp",
    "BtActionNode",
    "CancelAssistedTeleop",
    "CancelBackUp",
    "CancelControl",
    "CancelDriveOnHeading",
    "CancelSpin",
    "CancelWait",
    "ComputePathThroughPoses",
    "ComputePathToPose",
    "DriveOnHeading",
    "FollowPath",
    "SmoothPath",
    "Spin",
    "Wait",
]

S, F, R = Status.SUCCESS, Status.FAILURE, Status.RUNNING
#: the blackboard entry Nav2's recovery nodes count in (the navigator's feedback reads it)
RECOVERIES_KEY = "number_recoveries"


class BtActionNode(_Remote):
    """Nav2's ``BtActionNode`` for the action ``ACTION`` of nav2_msgs."""

    ACTION: ClassVar[str] = ""
    #: Nav2's recovery nodes add one to ``number_recoveries`` each time they start
    COUNTS_RECOVERY: ClassVar[bool] = False

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.goal: Any = None
        self.should_send_goal = True
        self.goal_updated = False
        self._client: Any = None
        self._goal_future: Any = None
        self._handle: Any = None
        self._result_future: Any = None
        self._since = 0
        self._sent = 0
        self._request = 0
        if getattr(self.context, "node", None) is not None:  # made with the tree, as Nav2 does
            self._client = self.context.action_client(_nav2(self.ACTION), self.server_name())

    # -- what each node fills in --------------------------------------------------------------
    def on_tick(self) -> None:
        """Fill ``self.goal`` from the ports (may clear ``should_send_goal``)."""

    def on_wait_for_result(self) -> None:
        """Called each tick while the goal runs; may update ``self.goal`` and set
        ``goal_updated`` to send it again (preempting the running one)."""

    def on_success(self, result: Any) -> Status:
        self.set_output("error_code_id", 0)
        return S

    def on_aborted(self, result: Any) -> Status:
        self.set_output("error_code_id", int(getattr(result, "error_code", 0)))
        msg = str(getattr(result, "error_msg", "") or "")
        self.note_failure(msg or f"{self.server_name()} aborted")
        return F

    def on_cancelled(self, result: Any) -> Status:
        self.set_output("error_code_id", 0)
        return S

    # -- the protocol ----------------------------------------------------------------------------
    def tick(self) -> Status:
        ctx = self.context
        now = ctx.now_ns()
        if self.status != R:
            self.should_send_goal = True
            self.goal = _nav2(self.ACTION).Goal()
            self.on_tick()
            if self.COUNTS_RECOVERY:
                bb = self.config.blackboard
                bb.set(RECOVERIES_KEY, int(bb.get(RECOVERIES_KEY, 0) or 0) + 1)
            self.status = R
            if not self.should_send_goal:
                return F
            self._client = ctx.action_client(_nav2(self.ACTION), self.server_name())
            if self._client is None:
                self.note_failure("no node to reach the action server")
                return F
            self._goal_future = self._handle = self._result_future = None
            self._since = now
        wait_ns, ack_ns = self._timeouts_ns()
        if self._goal_future is None:
            if not self._client.server_is_ready():
                if now - self._since > wait_ns:
                    self.note_failure(f"action server {self.server_name()} not available")
                    return F
                return R
            self._send(now)
        if self._handle is None:
            if not self._goal_future.done():
                if now - self._sent > ack_ns:
                    self._goal_future.add_done_callback(_cancel_when_accepted)
                    self._goal_future = None
                    self.note_failure("timed out waiting for the server to acknowledge the goal")
                    return F
                return R
            if self._goal_future.exception() is not None:
                self.note_failure(str(self._goal_future.exception()))
                self._goal_future = None
                return F
            self._handle = self._goal_future.result()
            if not self._handle.accepted:
                self.note_failure("goal rejected")
                self._handle = self._goal_future = None
                return F
            self._result_future = self._handle.get_result_async()
            ctx.active_goals.setdefault(self.server_name(), set()).add(self._handle)
        if not self._result_future.done():
            self.on_wait_for_result()
            if self.goal_updated:
                self.goal_updated = False
                self._forget()
                self._send(now)
            return R
        response = self._result_future.result()
        self._forget()
        self._goal_future = None
        code = int(response.status)
        if code == _STATUS_SUCCEEDED:
            return self.on_success(response.result)
        if code == _STATUS_CANCELED:
            return self.on_cancelled(response.result)
        return self.on_aborted(response.result)

    def _send(self, now: int) -> None:
        self._goal_future = self._client.send_goal_async(self.goal)
        self._sent = now

    def _forget(self) -> None:
        if self._handle is not None:
            self.context.active_goals.get(self.server_name(), set()).discard(self._handle)
        self._handle = self._result_future = None

    def halt(self) -> None:
        handle = self._handle
        running = self._result_future is not None and not self._result_future.done()
        if handle is not None and running:
            handle.cancel_goal_async()
        elif handle is None and self._goal_future is not None and not self._goal_future.done():
            self._goal_future.add_done_callback(_cancel_when_accepted)
        self._forget()
        self._goal_future = None


def _cancel_when_accepted(future: Any) -> None:
    if future.exception() is None and future.result().accepted:
        future.result().cancel_goal_async()


# -- planner, controller, smoother ------------------------------------------------------------
class ComputePathToPose(BtActionNode):
    ACTION = "ComputePathToPose"
    DEFAULT_SERVER = "compute_path_to_pose"
    PORTS: ClassVar[dict[str, Port]] = {
        **_basic(),
        "goal": input_port(object, description="Destination to plan to"),
        "start": input_port(object, description="Start pose instead of the robot's"),
        "use_start": input_port(bool, description="Use the start pose"),
        "planner_id": input_port(str, "", "Mapped name to the planner plugin type to use"),
        "path": output_port(object, "Path created by ComputePathToPose node"),
        "error_code_id": output_port(int, "The compute path to pose error code"),
    }

    def on_tick(self) -> None:
        self.context.plan_requests += 1
        self._request = self.context.plan_requests
        self.goal.goal = self.get_input("goal")
        self.goal.planner_id = str(self.get_input("planner_id") or "")
        start = self.get_input("start")
        if start is not None:
            use = self.get_input("use_start")
            self.goal.start = start
            self.goal.use_start = True if use is None else bool(use)

    def on_success(self, result: Any) -> Status:
        self.set_output("path", result.path)
        self.context.planned_request = self._request
        return super().on_success(result)

    def on_aborted(self, result: Any) -> Status:
        from eddiebot.msgs.nav_msgs import Path

        self.set_output("path", Path())
        return super().on_aborted(result)

    def on_cancelled(self, result: Any) -> Status:
        from eddiebot.msgs.nav_msgs import Path

        self.set_output("path", Path())
        return super().on_cancelled(result)


class ComputePathThroughPoses(ComputePathToPose):
    ACTION = "ComputePathThroughPoses"
    DEFAULT_SERVER = "compute_path_through_poses"
    PORTS: ClassVar[dict[str, Port]] = {
        **{k: v for k, v in ComputePathToPose.PORTS.items() if k != "goal"},
        "goals": input_port(object, description="Destinations to plan through"),
    }

    def on_tick(self) -> None:
        self.context.plan_requests += 1
        self._request = self.context.plan_requests
        self.goal.goals = list(self.get_input("goals") or [])
        self.goal.planner_id = str(self.get_input("planner_id") or "")
        start = self.get_input("start")
        if start is not None:
            use = self.get_input("use_start")
            self.goal.start = start
            self.goal.use_start = True if use is None else bool(use)


class FollowPath(BtActionNode):
    """A new ``path`` (or controller/goal checker) while the goal runs is sent to the
    running controller, which takes it over (Nav2's preemption), so replanning never stops
    the robot."""

    ACTION = "FollowPath"
    DEFAULT_SERVER = "follow_path"
    PORTS: ClassVar[dict[str, Port]] = {
        **_basic(),
        "path": input_port(object, description="Path to follow"),
        "controller_id": input_port(str, "", ""),
        "goal_checker_id": input_port(str, "", ""),
        "progress_checker_id": input_port(str, "", ""),
        "error_code_id": output_port(int, "The follow path error code"),
    }

    def on_tick(self) -> None:
        self.goal.path = self.get_input("path")
        self.goal.controller_id = str(self.get_input("controller_id") or "")
        self.goal.goal_checker_id = str(self.get_input("goal_checker_id") or "")
        self.goal.progress_checker_id = str(self.get_input("progress_checker_id") or "")

    def on_wait_for_result(self) -> None:
        # as upstream, a default (empty) path — what a failed ComputePathToPose writes — is
        # not sent: the controller keeps following the last good one while the planner retries
        path = self.get_input("path")
        if (path is not None and path is not self.goal.path and path != self.goal.path
                and not _is_default_path(path)):
            self.goal.path = path
            self.goal_updated = True
        for port in ("controller_id", "goal_checker_id", "progress_checker_id"):
            value = str(self.get_input(port) or "")
            if value != getattr(self.goal, port):
                setattr(self.goal, port, value)
                self.goal_updated = True


def _is_default_path(path: Any) -> bool:
    """``path == nav_msgs::msg::Path()``: no poses, no frame, stamp 0."""
    header = getattr(path, "header", None)
    poses = getattr(path, "poses", None)
    if header is None or poses is None:
        return False
    return (len(poses) == 0 and not header.frame_id
            and header.stamp.sec == 0 and header.stamp.nanosec == 0)


class SmoothPath(BtActionNode):
    ACTION = "SmoothPath"
    DEFAULT_SERVER = "smooth_path"
    PORTS: ClassVar[dict[str, Port]] = {
        **_basic(),
        "unsmoothed_path": input_port(object, description="Path to be smoothed"),
        "max_smoothing_duration": input_port(float, 3.0, "Maximum smoothing duration"),
        "check_for_collisions": input_port(bool, False, "Check for collisions"),
        "smoother_id": input_port(str, "", ""),
        "smoothed_path": output_port(object, "Path smoothed by SmootherServer node"),
        "smoothing_duration": output_port(float, "Time taken to smooth path"),
        "was_completed": output_port(bool, "True if smoothing was not interrupted"),
        "error_code_id": output_port(int, "The smooth path error code"),
    }

    def on_tick(self) -> None:
        self.goal.path = self.get_input("unsmoothed_path")
        self.goal.smoother_id = str(self.get_input("smoother_id") or "")
        self.goal.max_smoothing_duration = _duration(self.get_input("max_smoothing_duration"))
        self.goal.check_for_collisions = bool(self.get_input("check_for_collisions"))

    def on_success(self, result: Any) -> Status:
        self.set_output("smoothed_path", result.path)
        d = result.smoothing_duration
        self.set_output("smoothing_duration", d.sec + d.nanosec * 1e-9)
        self.set_output("was_completed", bool(result.was_completed))
        return super().on_success(result)


# -- behaviours ------------------------------------------------------------------------------
class Spin(BtActionNode):
    ACTION = "Spin"
    DEFAULT_SERVER = "spin"
    PORTS: ClassVar[dict[str, Port]] = {
        **_basic(),
        "spin_dist": input_port(float, 1.57, "Spin distance"),
        "time_allowance": input_port(float, 10.0, "Allowed time for spinning"),
        "is_recovery": input_port(bool, True, "True if recovery"),
        "error_code_id": output_port(int, "The spin behavior error code"),
    }

    def on_tick(self) -> None:
        self.goal.target_yaw = float(self.get_input("spin_dist"))
        self.goal.time_allowance = _duration(self.get_input("time_allowance"))
        if bool(self.get_input("is_recovery")):
            bb = self.config.blackboard
            bb.set(RECOVERIES_KEY, int(bb.get(RECOVERIES_KEY, 0) or 0) + 1)


class BackUp(BtActionNode):
    ACTION = "BackUp"
    DEFAULT_SERVER = "backup"
    COUNTS_RECOVERY = True
    PORTS: ClassVar[dict[str, Port]] = {
        **_basic(),
        "backup_dist": input_port(float, 0.15, "Distance to backup"),
        "backup_speed": input_port(float, 0.025, "Speed at which to backup"),
        "time_allowance": input_port(float, 10.0, "Allowed time for reversing"),
        "error_code_id": output_port(int, "The back up behavior server error code"),
    }

    def on_tick(self) -> None:
        from eddiebot.msgs.geometry_msgs import Point

        self.goal.target = Point(x=-abs(float(self.get_input("backup_dist"))), y=0.0, z=0.0)
        self.goal.speed = abs(float(self.get_input("backup_speed")))
        self.goal.time_allowance = _duration(self.get_input("time_allowance"))


class DriveOnHeading(BtActionNode):
    ACTION = "DriveOnHeading"
    DEFAULT_SERVER = "drive_on_heading"
    PORTS: ClassVar[dict[str, Port]] = {
        **_basic(),
        "dist_to_travel": input_port(float, 0.15, "Distance to travel"),
        "speed": input_port(float, 0.025, "Speed at which to travel"),
        "time_allowance": input_port(float, 10.0, "Allowed time for driving on heading"),
        "error_code_id": output_port(int, "The drive on heading behavior server error code"),
    }

    def on_tick(self) -> None:
        from eddiebot.msgs.geometry_msgs import Point

        self.goal.target = Point(x=float(self.get_input("dist_to_travel")), y=0.0, z=0.0)
        self.goal.speed = float(self.get_input("speed"))
        self.goal.time_allowance = _duration(self.get_input("time_allowance"))


class Wait(BtActionNode):
    ACTION = "Wait"
    DEFAULT_SERVER = "wait"
    COUNTS_RECOVERY = True
    PORTS: ClassVar[dict[str, Port]] = {
        **_basic(), "wait_duration": input_port(float, 1.0, "Wait time")}

    def on_tick(self) -> None:
        self.goal.time = _duration(self.get_input("wait_duration"))


class AssistedTeleop(BtActionNode):
    ACTION = "AssistedTeleop"
    DEFAULT_SERVER = "assisted_teleop"
    PORTS: ClassVar[dict[str, Port]] = {
        **_basic(),
        "time_allowance": input_port(float, 10.0, "Allowed time for running assisted teleop"),
        "is_recovery": input_port(bool, False, "If true the recovery count will be incremented"),
        "error_code_id": output_port(int, "The assisted teleop behavior server error code"),
    }

    def on_tick(self) -> None:
        self.goal.time_allowance = _duration(self.get_input("time_allowance"))
        if bool(self.get_input("is_recovery")):
            bb = self.config.blackboard
            bb.set(RECOVERIES_KEY, int(bb.get(RECOVERIES_KEY, 0) or 0) + 1)

    def on_cancelled(self, result: Any) -> Status:
        # Nav2: an assisted teleop stopped by the operator counts as done
        self.set_output("error_code_id", 0)
        return S


class _CancelNode(_Remote):
    """Nav2's ``BtCancelActionNode``: cancels every goal this tree has on the server."""

    PORTS: ClassVar[dict[str, Port]] = _basic()

    def tick(self) -> Status:
        for handle in list(self.context.active_goals.get(self.server_name(), ())):
            handle.cancel_goal_async()
        return S


class CancelControl(_CancelNode):
    DEFAULT_SERVER = "follow_path"


class CancelSpin(_CancelNode):
    DEFAULT_SERVER = "spin"


class CancelBackUp(_CancelNode):
    DEFAULT_SERVER = "backup"


class CancelWait(_CancelNode):
    DEFAULT_SERVER = "wait"


class CancelDriveOnHeading(_CancelNode):
    DEFAULT_SERVER = "drive_on_heading"


class CancelAssistedTeleop(_CancelNode):
    DEFAULT_SERVER = "assisted_teleop"
