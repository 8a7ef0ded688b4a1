"""Nav2's action and condition nodes (nav2_behavior_tree plugins), with their ports.

Action nodes follow ``BtActionNode``: the first tick builds the goal from the ports
(``on_tick``) and sends it; later ticks poll the goal's futures and never block; the
server's result maps to ``on_success`` / ``on_aborted`` / ``on_cancelled``, which write
the output ports (``path``, ``error_code_id``, …); halting cancels the goal. Service nodes
(``ClearEntireCostmap``, ``IsPathValid``) work the same way on a service call. Each node
talks to the server named by its ``server_name`` / ``service_name`` port, or Nav2's default.

Timeouts: a server that is not up fails the node after ``wait_for_service_timeout`` (ms);
an accepted goal's acknowledgement is awaited ``max(server_timeout,
wait_for_service_timeout)`` ms (the servers share the navigator's executor, so an
acknowledgement takes a few callbacks rather than Nav2's ``server_timeout`` of 20 ms).
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

from eddiebot.nav.bt.core import (
    LeafNode,
    Port,
    Status,
    input_port,
    output_port,
)

__all__ = ["NAV2_NODES", "RECOVERIES_KEY", "path_length_from"]

S, F, R = Status.SUCCESS, Status.FAILURE, Status.RUNNING
#: the blackboard entry Nav2's recovery nodes count in (the navigator's feedback reads it)
RECOVERIES_KEY = "number_recoveries"

_STATUS_SUCCEEDED, _STATUS_CANCELED, _STATUS_ABORTED = 4, 5, 6


def _nav2(name: str) -> Any:
    from eddiebot.msgs import nav2_msgs

    return getattr(nav2_msgs, name)


def _duration(seconds: float) -> Any:
    from eddiebot.core.time import Duration

    return Duration.from_seconds(float(seconds)).to_msg()


def _basic(server: bool = True) -> dict[str, Port]:
    name = "server_name" if server else "service_name"
    return {name: input_port(str, description="Action server name" if server else "Service name"),
            "server_timeout": input_port(int, description="Server timeout (ms)")}


class _Remote(LeafNode):
    """What action and service nodes share: server name, timeouts, failure messages."""

    DEFAULT_SERVER: ClassVar[str] = ""
    NAME_PORT: ClassVar[str] = "server_name"

    def server_name(self) -> str:
        return str(self.get_input(self.NAME_PORT) or self.DEFAULT_SERVER)

    def _timeouts_ns(self) -> tuple[int, int]:
        ctx = self.context
        wait = int(getattr(ctx, "wait_for_service_timeout_ms", 1000))
        server = self.get_input("server_timeout")
        server = int(server) if server is not None else int(getattr(ctx, "server_timeout_ms", 20))
        return wait * 1_000_000, max(server, wait) * 1_000_000

    def note_failure(self, msg: str) -> None:
        self.context.last_error_msg = f"{self.name}: {msg}"
        self.context.warn(self.context.last_error_msg)


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
        self.goal.goal = self.get_input("goal")
        self.goal.planner_id = str(self.get_input("planner_id") or "")
        start = self.get_input("start")
        if start is not None:
            use = self.get_input("use_start")
            self.goal.start = start
            self.goal.use_start = True if use is None else bool(use)

    def on_success(self, result: Any) -> Status:
        self.set_output("path", result.path)
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
        path = self.get_input("path")
        if path is not None and path is not self.goal.path and path != self.goal.path:
            self.goal.path = path
            self.goal_updated = True
        for port in ("controller_id", "goal_checker_id", "progress_checker_id"):
            value = str(self.get_input(port) or "")
            if value != getattr(self.goal, port):
                setattr(self.goal, port, value)
                self.goal_updated = True


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


# -- services --------------------------------------------------------------------------------
class BtServiceNode(_Remote):
    """Nav2's ``BtServiceNode``: one request per run, polled until its response."""

    SERVICE: ClassVar[str] = ""
    NAME_PORT = "service_name"

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self._future: Any = None
        self._client: Any = None
        self._since = 0
        if getattr(self.context, "node", None) is not None:
            self._client = self.context.service_client(self.srv_type(), self.server_name())

    def srv_type(self) -> Any:
        return _nav2(self.SERVICE)

    def make_request(self) -> Any:
        return self.srv_type().Request()

    def on_completion(self, response: Any) -> Status:
        return S

    def tick(self) -> Status:
        ctx = self.context
        now = ctx.now_ns()
        if self.status != R:
            self._client = ctx.service_client(self.srv_type(), self.server_name())
            if self._client is None:
                self.note_failure("no node to reach the service")
                return F
            self._future = None
            self._since = now
        wait_ns, ack_ns = self._timeouts_ns()
        if self._future is None:
            if not self._client.service_is_ready():
                if now - self._since > wait_ns:
                    self.note_failure(f"service {self.server_name()} not available")
                    return F
                return R
            self._future = self._client.call_async(self.make_request())
            self._since = now
        if not self._future.done():
            if now - self._since > ack_ns:
                self.note_failure(f"service {self.server_name()} timed out")
                self._future = None
                return F
            return R
        future, self._future = self._future, None
        if future.exception() is not None:
            self.note_failure(str(future.exception()))
            return F
        return self.on_completion(future.result())

    def halt(self) -> None:
        self._future = None


class ReinitializeGlobalLocalization(BtServiceNode):
    """Calls AMCL's ``reinitialize_global_localization`` (std_srvs/Empty)."""

    DEFAULT_SERVER = "reinitialize_global_localization"
    PORTS: ClassVar[dict[str, Port]] = _basic(server=False)

    def srv_type(self) -> Any:
        from eddiebot.msgs.std_srvs import Empty

        return Empty


class ClearEntireCostmap(BtServiceNode):
    SERVICE = "ClearEntireCostmap"
    PORTS: ClassVar[dict[str, Port]] = _basic(server=False)


class ClearCostmapAroundRobot(BtServiceNode):
    SERVICE = "ClearCostmapAroundRobot"
    PORTS: ClassVar[dict[str, Port]] = {
        **_basic(server=False),
        "reset_distance": input_port(float, 1.0, "Distance from the robot under which "
                                     "obstacles are cleared")}

    def make_request(self) -> Any:
        req = super().make_request()
        req.reset_distance = float(self.get_input("reset_distance"))
        return req


class ClearCostmapExceptRegion(ClearCostmapAroundRobot):
    SERVICE = "ClearCostmapExceptRegion"


class IsPathValid(BtServiceNode):
    """SUCCESS when the planner server's ``is_path_valid`` finds ``path`` collision-free;
    FAILURE when it does not, or when the service does not answer."""

    SERVICE = "IsPathValid"
    DEFAULT_SERVER = "is_path_valid"
    PORTS: ClassVar[dict[str, Port]] = {
        "path": input_port(object, description="Path to Check"),
        "server_timeout": input_port(int, description="Server timeout (ms)"),
    }

    def server_name(self) -> str:
        return self.DEFAULT_SERVER

    def note_failure(self, msg: str) -> None:
        self.context.warn(f"{self.name}: {msg}")

    def make_request(self) -> Any:
        req = super().make_request()
        path = self.get_input("path")
        if path is not None:
            req.path = path
        return req

    def on_completion(self, response: Any) -> Status:
        return S if bool(response.is_valid) else F


# -- selectors -------------------------------------------------------------------------------
class _Selector(LeafNode):
    """Nav2's selector nodes: the last ``std_msgs/String`` on ``topic_name``, else the
    default, written to the output port."""

    KIND: ClassVar[str] = ""

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        if getattr(self.context, "node", None) is not None:
            from eddiebot.msgs.std_msgs import String

            self.context.latest(str(self.get_input("topic_name")), String)

    def tick(self) -> Status:
        from eddiebot.msgs.std_msgs import String

        topic = str(self.get_input("topic_name"))
        last = self.context.latest(topic, String)
        value = last.data if last is not None else self.get_input(f"default_{self.KIND}")
        if value is not None:
            self.set_output(f"selected_{self.KIND}", str(value))
        return S


def _selector(kind: str, topic: str) -> type:
    ports = {
        f"default_{kind}": input_port(str, description=f"the default {kind} to use"),
        "topic_name": input_port(str, topic, f"the input topic name to select the {kind}"),
        f"selected_{kind}": output_port(str, f"Selected {kind} by subscription"),
    }
    cls_name = "".join(p.capitalize() for p in kind.split("_")) + "Selector"
    return type(cls_name, (_Selector,), {"KIND": kind, "PORTS": ports})


# -- path and goal tools ---------------------------------------------------------------------
class RemovePassedGoals(LeafNode):
    """Drops leading goals within ``radius`` of the robot, keeping the last one."""

    PORTS: ClassVar[dict[str, Port]] = {
        "input_goals": input_port(object, description="Original goals to remove viapoints from"),
        "output_goals": output_port(object, "Goals with passed viapoints removed"),
        "radius": input_port(float, 0.5, "radius to goal for it to be considered for removal"),
        "global_frame": input_port(str, description="Global frame"),
        "robot_base_frame": input_port(str, description="Robot base frame"),
    }

    def tick(self) -> Status:
        goals = list(self.get_input("input_goals") or [])
        if not goals:
            self.set_output("output_goals", goals)
            return S
        frame = goals[0].header.frame_id or self.get_input("global_frame")
        pose = self.context.robot_pose(frame, self.get_input("robot_base_frame"))
        if pose is None:
            return F
        radius = float(self.get_input("radius"))
        while len(goals) > 1:
            g = goals[0].pose.position
            if math.hypot(g.x - pose[0], g.y - pose[1]) > radius:
                break
            goals.pop(0)
        self.set_output("output_goals", goals)
        return S


class TruncatePath(LeafNode):
    """Cuts ``distance`` metres (straight-line, from the end) off the path and turns its
    new last pose towards the old end."""

    PORTS: ClassVar[dict[str, Port]] = {
        "input_path": input_port(object, description="Original Path"),
        "output_path": output_port(object, "Path truncated to a certain distance"),
        "distance": input_port(float, 1.0, "distance"),
    }

    def tick(self) -> Status:
        import copy

        path = self.get_input("input_path")
        if path is None or not path.poses:
            self.set_output("output_path", path)
            return S
        out = copy.deepcopy(path)
        final = out.poses[-1].pose.position
        distance = float(self.get_input("distance"))

        def dist() -> float:
            p = out.poses[-1].pose.position
            return math.hypot(p.x - final.x, p.y - final.y)

        while dist() < distance and len(out.poses) > 2:
            out.poses.pop()
        last = out.poses[-1].pose
        angle = math.atan2(final.y - last.position.y, final.x - last.position.x)
        if not math.isfinite(angle):
            angle = 0.0
        last.orientation.x = last.orientation.y = 0.0
        last.orientation.z, last.orientation.w = math.sin(angle / 2), math.cos(angle / 2)
        self.set_output("output_path", out)
        return S


class GetPoseFromPath(LeafNode):
    PORTS: ClassVar[dict[str, Port]] = {
        "path": input_port(object, description="Path to extract pose from"),
        "pose": output_port(object, "Stamped Extracted Pose"),
        "index": input_port(int, 0, "Index of pose to extract from. -1 is the end"),
    }

    def tick(self) -> Status:
        import copy

        path = self.get_input("path")
        if path is None or not path.poses:
            return F
        i = int(self.get_input("index"))
        if not -len(path.poses) <= i < len(path.poses):
            return F
        pose = copy.deepcopy(path.poses[i])
        if not pose.header.frame_id:
            pose.header = copy.deepcopy(path.header)
        self.set_output("pose", pose)
        return S


# -- conditions --------------------------------------------------------------------------------
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


def path_length_from(path_xy: Any, x: float, y: float) -> float:
    """Length of ``path_xy`` ((N, 2), m) from its pose closest to (x, y) to its end."""
    import numpy as np

    p = np.asarray(path_xy, dtype=np.float64).reshape(-1, 2)
    if p.shape[0] == 0:
        return 0.0
    i = int(np.argmin(np.hypot(p[:, 0] - x, p[:, 1] - y)))
    seg = np.hypot(np.diff(p[i:, 0]), np.diff(p[i:, 1]))
    return float(math.hypot(p[i, 0] - x, p[i, 1] - y) + seg.sum())


_SELECTORS = [_selector("controller", "controller_selector"),
              _selector("planner", "planner_selector"),
              _selector("goal_checker", "goal_checker_selector"),
              _selector("progress_checker", "progress_checker_selector"),
              _selector("smoother", "smoother_selector")]

NAV2_NODES: dict[str, type] = {
    cls.__name__: cls
    for cls in (
        ComputePathToPose, ComputePathThroughPoses, FollowPath, SmoothPath, Spin, BackUp,
        DriveOnHeading, Wait, AssistedTeleop, CancelControl, CancelSpin, CancelBackUp,
        CancelWait, CancelDriveOnHeading, CancelAssistedTeleop, ClearEntireCostmap,
        ClearCostmapAroundRobot, ClearCostmapExceptRegion, ReinitializeGlobalLocalization,
        IsPathValid, *_SELECTORS, RemovePassedGoals, TruncatePath, GetPoseFromPath,
        GoalUpdated, GlobalUpdatedGoal, AreErrorCodesPresent, WouldAControllerRecoveryHelp,
        WouldAPlannerRecoveryHelp, WouldASmootherRecoveryHelp, PathExpiringTimer, TimeExpired,
        DistanceTraveled, GoalReached, InitialPoseReceived, IsBatteryLow, IsBatteryCharging,
        TransformAvailable)
}
