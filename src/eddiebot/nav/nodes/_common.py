"""Shared pieces of the navigation servers: parameter trees, message conversions, TF poses.

A server declares its top-level Nav2 parameters with their defaults and then every other
override it was given (plugin sections such as ``FollowPath.desired_linear_vel`` or the
nested costmap ``global_costmap.plugins``), so a parameter file written for Nav2 loads as is.
At configure the dotted names are folded back into the nested dict the pure cores' builders
take, and a :class:`~eddiebot.nav.errors.ParameterError` (server, key, value) fails the
transition with that message in :attr:`NavServer.last_error`.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Mapping
from typing import Any

import numpy as np
import numpy.typing as npt

from eddiebot.core.lifecycle import LifecycleNode, TransitionCallbackReturn
from eddiebot.core.tf import TransformException
from eddiebot.nav.errors import NavError
from eddiebot.nav.types import Twist2D

__all__ = [
    "NavServer",
    "flatten_params",
    "nest_nav2_params",
    "path_from_msg",
    "path_to_msg",
    "pose_from_msg",
    "pose_is_finite",
    "pose_stamped",
    "robot_pose",
    "twist_from_msg",
    "twist_to_msg",
    "unflatten",
]

_RUNTIME_KEYS = {"use_sim_time", "bond_heartbeat_period"}


def unflatten(flat: Mapping[str, Any]) -> dict[str, Any]:
    """``{"a.b": 1}`` → ``{"a": {"b": 1}}`` (the nesting a ROS parameter file had)."""
    out: dict[str, Any] = {}
    for key in sorted(flat):
        parts = key.split(".")
        node = out
        for p in parts[:-1]:
            child = node.get(p)
            if not isinstance(child, dict):
                child = {}
                node[p] = child
            node = child
        if not isinstance(node.get(parts[-1]), dict):
            node[parts[-1]] = flat[key]
    return out


def flatten_params(tree: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """``{"a": {"b": 1}}`` → ``{"a.b": 1}`` (parameter names as a parameter file gives them)."""
    out: dict[str, Any] = {}
    for key, value in tree.items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping):
            out.update(flatten_params(value, f"{name}."))
        else:
            out[name] = value
    return out


def nest_nav2_params(doc: Mapping[str, Any]) -> dict[str, Any]:
    """A Nav2 parameters document with the costmap nodes folded into their servers.

    Nav2 runs each costmap as its own node (``global_costmap: global_costmap:
    ros__parameters``); here the planner server owns the global costmap and the controller
    server the local one, under the parameter prefixes ``global_costmap.`` and
    ``local_costmap.``.
    """
    out = copy.deepcopy(dict(doc))
    for owner, cm in (("planner_server", "global_costmap"), ("controller_server", "local_costmap")):
        outer = out.get(cm)
        if not isinstance(outer, dict) or not isinstance(outer.get(cm), dict):
            continue
        params = (outer[cm] or {}).get("ros__parameters") or {}
        server = out.setdefault(owner, {}).setdefault("ros__parameters", {})
        if server is None:
            server = out[owner]["ros__parameters"] = {}
        server[cm] = params
        del outer[cm]
        if not outer:
            del out[cm]
    return out


class NavServer(LifecycleNode):
    """A Nav2 lifecycle server: declared defaults, plugin overrides, named configure errors."""

    default_node_name = "nav_server"
    #: top-level parameters and their Nav2 (Jazzy) defaults
    PARAMETERS: dict[str, Any] = {}

    def __init__(self, node_name: str | None = None, **kwargs: Any) -> None:
        super().__init__(node_name or self.default_node_name, **kwargs)
        for key, value in self.PARAMETERS.items():
            if not self.has_parameter(key):
                self.declare_parameter(key, value)
        for o in self.undeclared_overrides():
            self.declare_parameter(o.name, o.value)
        self.last_error = ""

    # -- parameters ------------------------------------------------------------------------
    def params_tree(self) -> dict[str, Any]:
        """Every parameter of this node as the nested dict of its YAML section."""
        flat = {k: p.value for k, p in self.parameters.items() if k not in _RUNTIME_KEYS}
        return unflatten(flat)

    def param(self, name: str) -> Any:
        return self.get_parameter(name).value

    def fail(self, exc: Exception) -> TransitionCallbackReturn:
        """Log a configure error (it names server, key and value) and fail the transition."""
        self.last_error = str(exc)
        self.get_logger().error(f"{self.get_name()}: configure failed: {exc}")
        return TransitionCallbackReturn.FAILURE

    def configure_with(self, build: Any) -> TransitionCallbackReturn:
        try:
            build()
        except (NavError, ValueError, TypeError, KeyError, OSError) as exc:
            return self.fail(exc)
        return TransitionCallbackReturn.SUCCESS


# -- conversions ---------------------------------------------------------------------------
def _yaw_of(q: Any) -> float:
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def pose_is_finite(pose: Any) -> bool:
    """Whether a geometry_msgs/Pose has a finite position and orientation (a NaN or inf goal
    is refused at once: the planner would report it outside the map only after the robot's
    pose, and a NaN yaw makes a goal checker spin forever)."""
    p, q = pose.position, pose.orientation
    return all(math.isfinite(float(v)) for v in (p.x, p.y, p.z, q.x, q.y, q.z, q.w))


def pose_from_msg(pose: Any) -> npt.NDArray[np.float64]:
    """geometry_msgs/Pose → (x, y, yaw)."""
    return np.array([pose.position.x, pose.position.y, _yaw_of(pose.orientation)])


def pose_stamped(x: float, y: float, yaw: float, frame_id: str, stamp_ns: int = 0) -> Any:
    from eddiebot.msgs.builtin_interfaces import Time
    from eddiebot.msgs.geometry_msgs import Point, Pose, PoseStamped, Quaternion
    from eddiebot.msgs.std_msgs import Header

    return PoseStamped(
        header=Header(stamp=Time(sec=int(stamp_ns // 1_000_000_000), nanosec=int(stamp_ns % 1_000_000_000)),
                      frame_id=frame_id),
        pose=Pose(position=Point(x=float(x), y=float(y), z=0.0),
                  orientation=Quaternion(x=0.0, y=0.0, z=math.sin(yaw / 2.0), w=math.cos(yaw / 2.0))),
    )


def path_to_msg(path: npt.ArrayLike, frame_id: str, stamp_ns: int = 0) -> Any:
    from eddiebot.msgs.builtin_interfaces import Time
    from eddiebot.msgs.geometry_msgs import Point, Pose, PoseStamped, Quaternion
    from eddiebot.msgs.nav_msgs import Path
    from eddiebot.msgs.std_msgs import Header

    p = np.asarray(path, dtype=np.float64).reshape(-1, 3)
    sec, nanosec = int(stamp_ns // 1_000_000_000), int(stamp_ns % 1_000_000_000)
    qz, qw = np.sin(p[:, 2] / 2.0).tolist(), np.cos(p[:, 2] / 2.0).tolist()
    # the message classes resolved once per path, not once per pose (paths run to 1000s)
    poses = [PoseStamped(header=Header(stamp=Time(sec=sec, nanosec=nanosec), frame_id=frame_id),
                         pose=Pose(position=Point(x=x, y=y, z=0.0),
                                   orientation=Quaternion(x=0.0, y=0.0, z=z, w=w)))
             for x, y, z, w in zip(p[:, 0].tolist(), p[:, 1].tolist(), qz, qw)]
    return Path(header=Header(stamp=Time(sec=sec, nanosec=nanosec), frame_id=frame_id), poses=poses)


def path_from_msg(msg: Any) -> npt.NDArray[np.float64]:
    if not msg.poses:
        return np.zeros((0, 3))
    rows = [(ps.pose.position.x, ps.pose.position.y, ps.pose.orientation.x, ps.pose.orientation.y,
             ps.pose.orientation.z, ps.pose.orientation.w) for ps in msg.poses]
    a = np.array(rows, dtype=np.float64)
    qx, qy, qz, qw = a[:, 2], a[:, 3], a[:, 4], a[:, 5]
    yaw = np.arctan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))
    return np.column_stack([a[:, 0], a[:, 1], yaw])


def twist_from_msg(msg: Any) -> Twist2D:
    return Twist2D(float(msg.linear.x), float(msg.linear.y), float(msg.angular.z))


def twist_to_msg(t: Twist2D) -> Any:
    from eddiebot.msgs.geometry_msgs import Twist, Vector3

    return Twist(linear=Vector3(x=float(t.vx), y=float(t.vy), z=0.0),
                 angular=Vector3(x=0.0, y=0.0, z=float(t.wz)))


def robot_pose(buffer: Any, global_frame: str, base_frame: str, now_ns: int,
               tolerance_s: float) -> npt.NDArray[np.float64] | None:
    """Robot (x, y, yaw) in ``global_frame`` from the latest TF, or None if unavailable or
    older than ``tolerance_s`` (a stopped odometry publisher means a lost robot)."""
    try:
        x, y, yaw = buffer.lookup_pose2d(global_frame, base_frame, 0)
        stamp = buffer.get_latest_common_time(global_frame, base_frame).nanoseconds
    except TransformException:
        return None
    if stamp != 0 and (now_ns - stamp) * 1e-9 > tolerance_s:
        return None
    return np.array([x, y, yaw])
