"""nav2_behaviors: ``spin``, ``backup``, ``drive_on_heading``, ``wait``, ``assisted_teleop``.

Parameters as Nav2's ``behavior_server`` (``behavior_plugins`` with ``plugin:``,
``cycle_frequency``, ``local_frame``, ``robot_base_frame``, ``transform_tolerance``,
``simulate_ahead_time``, rotational limits). Each behaviour is an action named after its
plugin instance (``spin``, ``backup``, …) that publishes on ``cmd_vel`` — remapped to
``/cmd_vel_nav`` so the velocity smoother and the collision monitor stay in the chain — and
checks collisions on the local costmap (``/local_costmap/costmap_raw`` with
``/local_costmap/published_footprint``: Jazzy's ``local_costmap_topic`` and
``local_footprint_topic``, or Humble's ``costmap_topic`` and ``footprint_topic``; Jazzy's
``global_*_topic`` feed behaviours of the global costmap, which none of these is). Every end
(success, failure, cancel) sends zero.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from eddiebot.core.action import ActionServer, CancelResponse, ServerGoalHandle, sleep
from eddiebot.core.lifecycle import State, TransitionCallbackReturn
from eddiebot.core.tf import Buffer, TransformListener
from eddiebot.core.time import Duration
from eddiebot.msgs.geometry_msgs import Twist
from eddiebot.nav.behaviors import (
    AssistedTeleop,
    BackUp,
    BehaviorServerConfig,
    DriveOnHeading,
    Spin,
    Status,
    Wait,
    build_behaviors,
)
from eddiebot.nav.costmap import CostmapConfig, LayeredCostmap
from eddiebot.nav.errors import (
    BehaviorError,
    BehaviorTimedOut,
    CollisionAhead,
    InvalidBehaviorInput,
    ParameterError,
)
from eddiebot.nav.nodes._common import NavServer, robot_pose, twist_from_msg, twist_to_msg
from eddiebot.nav.nodes.smoother_server import costmap_from_raw
from eddiebot.nav.types import Twist2D

__all__ = ["BehaviorServer"]


def _error_code(result_cls: Any, err: BehaviorError) -> int:
    if isinstance(err, CollisionAhead):
        name = "COLLISION_AHEAD"
    elif isinstance(err, BehaviorTimedOut):
        name = "TIMEOUT"
    elif isinstance(err, InvalidBehaviorInput):
        name = "INVALID_INPUT"
    elif err.result_code == 702:
        name = "TF_ERROR"
    else:
        name = "UNKNOWN"
    return int(getattr(result_cls, name, getattr(result_cls, "UNKNOWN", 0)))


class _TfLost(BehaviorError):
    result_code = 702


class BehaviorServer(NavServer):
    default_node_name = "behavior_server"
    PARAMETERS = {
        "costmap_topic": "local_costmap/costmap_raw",
        "footprint_topic": "local_costmap/published_footprint",
        # Jazzy's names for the same topics (a value set here wins over Humble's)
        "local_costmap_topic": "local_costmap/costmap_raw",
        "local_footprint_topic": "local_costmap/published_footprint",
        "cycle_frequency": 10.0, "local_frame": "odom", "global_frame": "map",
        "robot_base_frame": "base_link", "transform_tolerance": 0.1,
        "simulate_ahead_time": 2.0, "max_rotational_vel": 1.0, "min_rotational_vel": 0.4,
        "rotational_acc_lim": 3.2, "projection_time": 1.0, "simulation_time_step": 0.1,
        "behavior_plugins": ["spin", "backup", "drive_on_heading", "assisted_teleop", "wait"],
        "enable_stamped_cmd_vel": False,
    }

    def __init__(self, node_name: str = "behavior_server", **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        self.config: BehaviorServerConfig | None = None
        self.behaviors: dict[str, Any] = {}
        self.costmap: LayeredCostmap | None = None
        self.tf_buffer = Buffer(node=self)
        self._listener: TransformListener | None = None
        self._actions: list[ActionServer] = []
        self._subs: list[Any] = []
        self._cmd_pub: Any = None
        self._teleop = Twist2D()
        self._busy = False

    def on_configure(self, state: State) -> TransitionCallbackReturn:
        def build() -> None:
            tree = self.params_tree()
            for key in ("costmap_topic", "footprint_topic", "local_costmap_topic",
                        "local_footprint_topic", "enable_stamped_cmd_vel"):
                tree.pop(key, None)
            # Humble spelled the local frame global_frame; Jazzy has both.
            self.config, self.behaviors = build_behaviors(tree, server=self.get_name())
            for name, beh in self.behaviors.items():
                if not isinstance(beh, (Spin, DriveOnHeading, Wait, AssistedTeleop)):
                    raise ParameterError(
                        self.get_name(), f"{name}.plugin", type(beh).__qualname__,
                        "a behaviour serves the action of the nav2_behaviors type it extends "
                        "(Spin, BackUp, DriveOnHeading, Wait or AssistedTeleop)")
            self._cmd_pub = self.create_lifecycle_publisher(Twist, "cmd_vel", 1)
        return self.configure_with(build)

    def _topic(self, kind: str) -> str:
        """The local costmap's ``kind`` ("costmap" / "footprint") topic: Jazzy's
        ``local_<kind>_topic`` when set away from its default, else Humble's ``<kind>_topic``."""
        jazzy = str(self.param(f"local_{kind}_topic"))
        topic = jazzy if jazzy != self.PARAMETERS[f"local_{kind}_topic"] else str(
            self.param(f"{kind}_topic"))
        return "/" + topic.lstrip("/")

    def on_activate(self, state: State) -> TransitionCallbackReturn:
        from eddiebot.msgs.geometry_msgs import PolygonStamped
        from eddiebot.msgs.nav2_msgs import AssistedTeleop as AssistedTeleopAction
        from eddiebot.msgs.nav2_msgs import BackUp as BackUpAction
        from eddiebot.msgs.nav2_msgs import Costmap
        from eddiebot.msgs.nav2_msgs import DriveOnHeading as DriveOnHeadingAction
        from eddiebot.msgs.nav2_msgs import Spin as SpinAction
        from eddiebot.msgs.nav2_msgs import Wait as WaitAction

        self._listener = TransformListener(self.tf_buffer, self)
        self._subs = [
            self.create_subscription(Costmap, self._topic("costmap"), self._on_costmap, 1),
            self.create_subscription(PolygonStamped, self._topic("footprint"),
                                     self._on_footprint, 1),
            self.create_subscription(Twist, "cmd_vel_teleop", self._on_teleop, 1),
        ]
        kinds = {Spin: SpinAction, BackUp: BackUpAction, DriveOnHeading: DriveOnHeadingAction,
                 Wait: WaitAction, AssistedTeleop: AssistedTeleopAction}
        for name, beh in self.behaviors.items():
            # a plugin extending a built-in behaviour serves that behaviour's action
            action = next(kinds[c] for c in type(beh).__mro__ if c in kinds)
            self._actions.append(ActionServer(
                self, action, name, self._executor_for(name, action),
                cancel_callback=lambda _h: CancelResponse.ACCEPT))
        return TransitionCallbackReturn.SUCCESS

    def on_deactivate(self, state: State) -> TransitionCallbackReturn:
        for a in self._actions:
            a.destroy()
        for s in self._subs:
            self.destroy_subscription(s)
        self._actions, self._subs = [], []
        if self._listener is not None:
            self._listener.unregister()
            self._listener = None
        return TransitionCallbackReturn.SUCCESS

    def on_cleanup(self, state: State) -> TransitionCallbackReturn:
        if self._cmd_pub is not None:
            self.destroy_lifecycle_publisher(self._cmd_pub)
        self._cmd_pub = None
        self.behaviors = {}
        return TransitionCallbackReturn.SUCCESS

    # -- inputs -------------------------------------------------------------------------------
    def _on_costmap(self, msg: Any) -> None:
        master = costmap_from_raw(msg)
        if self.costmap is None:
            self.costmap = LayeredCostmap(CostmapConfig(
                global_frame=msg.header.frame_id or "odom", width=1, height=1,
                resolution=master.resolution, robot_radius=0.1, footprint_padding=0.0),
                "local_costmap")
        self.costmap.master = master
        self.costmap.config = CostmapConfig(**{**self.costmap.config.__dict__,
                                               "global_frame": msg.header.frame_id or "odom"})

    def _on_footprint(self, msg: Any) -> None:
        if self.costmap is not None and msg.polygon.points:
            self.costmap.set_footprint(np.array([[p.x, p.y] for p in msg.polygon.points]))

    def _on_teleop(self, msg: Any) -> None:
        self._teleop = twist_from_msg(msg)

    def _pose(self) -> Any:
        assert self.config is not None
        frame = self.costmap.config.global_frame if self.costmap is not None else self.config.local_frame
        return robot_pose(self.tf_buffer, frame, self.config.robot_base_frame,
                          self.now().nanoseconds, max(self.config.transform_tolerance, 0.25))

    # -- execution ----------------------------------------------------------------------------
    def _executor_for(self, name: str, action: Any) -> Any:
        async def execute(handle: ServerGoalHandle) -> Any:
            return await self._run_behavior(name, action, handle)
        return execute

    def _start(self, beh: Any, goal: Any, pose: Any, now: int) -> None:
        allowance = Duration.from_msg(goal.time_allowance).to_seconds() \
            if hasattr(goal, "time_allowance") else 0.0
        if isinstance(beh, Spin):
            beh.start(pose, float(goal.target_yaw), now, allowance)
        elif isinstance(beh, DriveOnHeading):  # BackUp included
            beh.start(pose, float(goal.target.x), float(goal.speed), now, allowance)
        elif isinstance(beh, Wait):
            beh.start(Duration.from_msg(goal.time).to_seconds(), now)
        elif isinstance(beh, AssistedTeleop):
            beh.start(now, allowance)

    def _feedback(self, action: Any, beh: Any, pose: Any, start_pose: Any, now: int) -> Any:
        fb = action.Feedback()
        if isinstance(beh, Spin):
            fb.angular_distance_traveled = float(abs(getattr(beh, "_relative", 0.0)))
        elif isinstance(beh, DriveOnHeading):
            fb.distance_traveled = float(math.hypot(pose[0] - start_pose[0], pose[1] - start_pose[1]))
        elif isinstance(beh, Wait):
            fb.time_left = Duration.from_seconds(beh.time_left(now)).to_msg()
        return fb

    async def _run_behavior(self, name: str, action: Any, handle: ServerGoalHandle) -> Any:
        assert self.config is not None
        beh = self.behaviors[name]
        result = action.Result()
        t0 = self.now().nanoseconds

        def end(err: BehaviorError | None) -> Any:
            self._busy = False
            if not isinstance(beh, Wait):
                self._cmd_pub.publish(twist_to_msg(Twist2D()))
            result.total_elapsed_time = Duration(self.now().nanoseconds - t0).to_msg()
            if err is not None and hasattr(result, "error_code"):
                result.error_code = _error_code(action.Result, err)
                result.error_msg = str(err)
            return result

        if self._busy:
            self.get_logger().warning(f"{name}: another behaviour is running; rejected")
            handle.abort()
            return end(BehaviorError("another behaviour is running"))
        self._busy = True
        needs_costmap = not isinstance(beh, Wait)
        waited = 0.0
        while needs_costmap and (self.costmap is None or self._pose() is None) and waited < 1.0:
            await sleep(self, 0.1)
            waited += 0.1
        pose = self._pose() if needs_costmap else np.zeros(3)
        if needs_costmap and (self.costmap is None or pose is None):
            handle.abort()
            return end(_TfLost(f"{name}: no local costmap or robot pose"))
        start_pose = pose
        try:
            self._start(beh, handle.request, pose, self.now().nanoseconds)
        except BehaviorError as err:
            handle.abort()
            return end(err)
        period = 1.0 / self.config.cycle_frequency
        while True:
            if handle.is_cancel_requested:
                handle.canceled()
                return end(None)
            now = self.now().nanoseconds
            if needs_costmap:
                pose = self._pose()
                if pose is None:
                    handle.abort()
                    return end(_TfLost(f"{name}: lost the robot pose"))
            if isinstance(beh, AssistedTeleop):
                beh.set_teleop(self._teleop)
            step = beh.update(pose, now, self.costmap)
            if step.status == Status.SUCCEEDED:
                handle.succeed()
                return end(None)
            if step.status == Status.FAILED:
                self.get_logger().warning(f"{name} failed: {step.error}")
                handle.abort()
                return end(step.error or BehaviorError(f"{name} failed"))
            if step.cmd is not None:
                self._cmd_pub.publish(twist_to_msg(step.cmd))
            handle.publish_feedback(self._feedback(action, beh, pose, start_pose, now))
            await sleep(self, period)
