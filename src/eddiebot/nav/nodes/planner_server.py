"""nav2_planner: the planner server with its global costmap.

Parameters as Nav2's ``planner_server`` (``planner_plugins`` list, each with ``plugin:``,
``expected_planner_frequency``) plus the global costmap under the prefix
``global_costmap.`` (Nav2's separate ``global_costmap/global_costmap`` node, folded in:
see :func:`eddiebot.nav.nodes._common.nest_nav2_params`). Serves ``compute_path_to_pose``
and ``compute_path_through_poses`` (nav2_msgs, Jazzy error codes from the typed planner
failures) and the ``is_path_valid`` service, publishes ``/plan``,
``/global_costmap/costmap`` and ``costmap_raw``.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from eddiebot.core.action import ActionServer, CancelResponse, ServerGoalHandle
from eddiebot.core.lifecycle import State, TransitionCallbackReturn
from eddiebot.core.tf import Buffer, TransformException, TransformListener
from eddiebot.core.time import Duration
from eddiebot.msgs.nav_msgs import Path
from eddiebot.nav.costmap import LayeredCostmap, build_costmap
from eddiebot.nav.errors import (
    GoalOutsideMapBounds,
    NavError,
    PlannerError,
    PlannerTFError,
    StartOutsideMapBounds,
)
from eddiebot.nav.nodes._common import NavServer, path_to_msg, pose_from_msg, pose_is_finite
from eddiebot.nav.nodes._costmap import CostmapHost
from eddiebot.nav.planners import GlobalPlanner, build_planners, get_planner

__all__ = ["PlannerServer"]


class PlannerServer(NavServer):
    default_node_name = "planner_server"
    #: parameter-file node entries this server takes in, under a parameter prefix (Nav2 runs
    #: the costmap as its own node ``/global_costmap/global_costmap`` in this process)
    nested_parameter_nodes = {"global_costmap/global_costmap": "global_costmap"}
    PARAMETERS = {"expected_planner_frequency": 1.0, "planner_plugins": ["GridBased"],
                  "costmap_update_timeout": 1.0}

    def __init__(self, node_name: str = "planner_server", **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        self.planners: dict[str, GlobalPlanner] = {}
        self.costmap: LayeredCostmap | None = None
        self.host: CostmapHost | None = None
        self.tf_buffer = Buffer(node=self)
        self._listener: TransformListener | None = None
        self._actions: list[ActionServer] = []
        self._plan_pub: Any = None
        self._is_path_valid: Any = None

    def on_configure(self, state: State) -> TransitionCallbackReturn:
        def build() -> None:
            tree = self.params_tree()
            cm_params = tree.pop("global_costmap", {}) or {}
            self.planners = build_planners(tree, server=self.get_name())
            self.costmap = build_costmap(cm_params, "global_costmap")
            self.host = CostmapHost(self, self.costmap, "global_costmap", self.tf_buffer)
            self._plan_pub = self.create_lifecycle_publisher(Path, "/plan", 1)
        return self.configure_with(build)

    def on_activate(self, state: State) -> TransitionCallbackReturn:
        from eddiebot.msgs.nav2_msgs import ComputePathThroughPoses, ComputePathToPose, IsPathValid

        assert self.host is not None
        self._listener = TransformListener(self.tf_buffer, self)
        self.host.activate()
        accept = self._cancel_ok
        self._actions = [
            ActionServer(self, ComputePathToPose, "compute_path_to_pose", self._to_pose,
                         cancel_callback=accept),
            ActionServer(self, ComputePathThroughPoses, "compute_path_through_poses",
                         self._through_poses, cancel_callback=accept),
        ]
        self._is_path_valid = self.create_service(IsPathValid, "is_path_valid",
                                                  self._on_is_path_valid)
        return TransitionCallbackReturn.SUCCESS

    def on_deactivate(self, state: State) -> TransitionCallbackReturn:
        for a in self._actions:
            a.destroy()
        self._actions = []
        if self._is_path_valid is not None:
            self.destroy_service(self._is_path_valid)
            self._is_path_valid = None
        if self.host is not None:
            self.host.deactivate()
        if self._listener is not None:
            self._listener.unregister()
            self._listener = None
        return TransitionCallbackReturn.SUCCESS

    def on_cleanup(self, state: State) -> TransitionCallbackReturn:
        if self.host is not None:
            self.host.destroy()
        if self._plan_pub is not None:
            self.destroy_lifecycle_publisher(self._plan_pub)
        self.host = self.costmap = self._plan_pub = None
        self.planners = {}
        return TransitionCallbackReturn.SUCCESS

    @staticmethod
    def _cancel_ok(_handle: ServerGoalHandle) -> CancelResponse:
        return CancelResponse.ACCEPT

    # -- is_path_valid ------------------------------------------------------------------------
    def _on_is_path_valid(self, request: Any, response: Any) -> Any:
        """Nav2's ``PlannerServer::isPathValid``: from the pose closest to the robot on, the
        path is invalid at the first pose whose cell is lethal or inscribed (a circular robot)
        or whose footprint touches a lethal cell (a footprint), or that lies off the map."""
        assert self.host is not None and self.costmap is not None
        response.is_valid = True
        poses = request.path.poses
        if not poses:
            return response
        xy = np.array([(p.pose.position.x, p.pose.position.y) for p in poses], dtype=np.float64)
        robot = self.host.latest_robot_pose()
        first = 0 if robot is None else int(np.argmin(np.sum((xy - robot[:2]) ** 2, axis=1)))
        self.host.update()
        invalid = is_path_invalid_from(self.costmap, poses, first)
        if invalid is not None:
            response.is_valid = False
            response.invalid_pose_indices = np.array([invalid], dtype=np.int32)
        return response

    # -- planning -----------------------------------------------------------------------------
    def _in_global(self, pose_stamped: Any, what: str = "goal") -> npt.NDArray[np.float64]:
        assert self.host is not None
        if not pose_is_finite(pose_stamped.pose):
            # no map holds a NaN/inf position; a NaN orientation is as unusable
            error = StartOutsideMapBounds if what == "start" else GoalOutsideMapBounds
            raise error(f"{what} pose is not finite: {_pose_text(pose_stamped.pose)}")
        p = pose_from_msg(pose_stamped.pose)
        frame = pose_stamped.header.frame_id or self.host.global_frame
        if frame == self.host.global_frame:
            return p
        try:
            x, y, yaw = self.tf_buffer.lookup_pose2d(self.host.global_frame, frame, 0)
        except TransformException as exc:
            raise PlannerTFError(f"cannot transform {frame} to {self.host.global_frame}: {exc}") from exc
        c, s = np.cos(yaw), np.sin(yaw)
        return np.array([x + c * p[0] - s * p[1], y + s * p[0] + c * p[1], p[2] + yaw])

    def _start(self, goal: Any) -> npt.NDArray[np.float64]:
        assert self.host is not None
        if goal.use_start:
            return self._in_global(goal.start, "start")
        pose = self.host.latest_robot_pose()
        if pose is None:
            raise PlannerTFError(f"no robot pose ({self.host.global_frame} -> {self.host.base_frame})")
        return pose

    def plan(self, start: npt.ArrayLike, goal: npt.ArrayLike, planner_id: str) -> npt.NDArray[np.float64]:
        """One plan on the current global costmap (raises the typed planner failures)."""
        assert self.host is not None and self.costmap is not None
        planner = get_planner(self.planners, planner_id or next(iter(self.planners)))
        self.host.update()
        if hasattr(planner, "configure_from_costmap"):  # footprint-aware (SmacPlannerHybrid)
            planner.configure_from_costmap(self.costmap)
        path = planner.create_plan(np.asarray(start), np.asarray(goal), self.costmap.master)
        return np.asarray(path, dtype=np.float64).reshape(-1, 3)

    def _finish(self, handle: ServerGoalHandle, result: Any, path: npt.NDArray[np.float64] | None,
                err: NavError | None, t0: int, code_offset: int = 0) -> Any:
        """``code_offset`` 100 gives ComputePathThroughPoses' codes (300..309)."""
        assert self.host is not None
        result.planning_time = Duration(nanoseconds=self.now().nanoseconds - t0).to_msg()
        if err is not None:
            result.error_code = int(err.result_code or PlannerError.result_code) + code_offset
            result.error_msg = str(err)
            self.get_logger().warning(f"planning failed: {err}")
            handle.abort()
            return result
        assert path is not None
        msg = path_to_msg(path, self.host.global_frame, self.now().nanoseconds)
        result.path = msg
        self._plan_pub.publish(msg)
        handle.succeed()
        return result

    def _to_pose(self, handle: ServerGoalHandle) -> Any:
        from eddiebot.msgs.nav2_msgs import ComputePathToPose

        t0 = self.now().nanoseconds
        goal = handle.request
        result = ComputePathToPose.Result()
        try:
            target = self._in_global(goal.goal)
            path = self.plan(self._start(goal), target, goal.planner_id)
        except NavError as err:
            return self._finish(handle, result, None, err, t0)
        return self._finish(handle, result, path, None, t0)

    def _through_poses(self, handle: ServerGoalHandle) -> Any:
        from eddiebot.msgs.nav2_msgs import ComputePathThroughPoses

        t0 = self.now().nanoseconds
        goal = handle.request
        result = ComputePathThroughPoses.Result()
        try:
            if not goal.goals:
                raise PlannerError("no goals given")
            targets = [self._in_global(g, f"goal {i}") for i, g in enumerate(goal.goals)]
            start = self._start(goal)
            parts: list[npt.NDArray[np.float64]] = []
            for target in targets:
                seg = self.plan(start, target, goal.planner_id)
                parts.append(seg if not parts else seg[1:])
                start = target
            path = np.concatenate(parts, axis=0)
        except NavError as err:
            return self._finish(handle, result, None, err, t0, 100)
        return self._finish(handle, result, path, None, t0)


def is_path_invalid_from(costmap: LayeredCostmap, poses: Any, first: int) -> int | None:
    """Index of the first pose from ``first`` on that makes a path invalid on ``costmap``
    (Nav2's rule, see `PlannerServer._on_is_path_valid`), or None."""
    from eddiebot.nav.cost_values import INSCRIBED_INFLATED_OBSTACLE, LETHAL_OBSTACLE

    grid = costmap.master
    for i in range(first, len(poses)):
        pose = poses[i].pose
        x, y = pose.position.x, pose.position.y
        if costmap.use_radius:
            cell = grid.world_to_map(x, y)
            cost = LETHAL_OBSTACLE if cell is None else grid.get_cost(*cell)
            if cost in (LETHAL_OBSTACLE, INSCRIBED_INFLATED_OBSTACLE):
                return i
        else:
            yaw = pose_from_msg(pose)[2]
            cost = grid.footprint_cost(costmap.footprint_at((x, y, yaw)))
            if cost < 0 or cost >= LETHAL_OBSTACLE:  # off the map counts as lethal
                return i
    return None


def _pose_text(pose: Any) -> str:
    p, q = pose.position, pose.orientation
    return f"position ({p.x}, {p.y}, {p.z}), orientation ({q.x}, {q.y}, {q.z}, {q.w})"
