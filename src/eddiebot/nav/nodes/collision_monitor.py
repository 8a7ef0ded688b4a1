"""nav2_collision_monitor as a lifecycle node: ``/cmd_vel_smoothed`` → ``/cmd_vel_safe``.

Sources (``observation_sources``; each ``type: scan | range``, ``topic``,
``enabled``, ``source_timeout``) are turned into points in ``base_frame_id`` through TF as
they arrive; every incoming command is checked against the polygons and circles by
:class:`eddiebot.nav.collision_monitor.CollisionMonitor` (Nav2's rules: stop, slowdown,
limit, approach; an enabled source with no recent data stops the robot).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from eddiebot.core.lifecycle import State, TransitionCallbackReturn
from eddiebot.core.qos import qos_profile_sensor_data
from eddiebot.core.tf import Buffer, TransformException, TransformListener
from eddiebot.core.time import stamp_to_ns
from eddiebot.msgs.geometry_msgs import Twist
from eddiebot.nav.collision_monitor import (
    CollisionMonitor,
    Points,
    build_collision_monitor,
    range_source_points,
    scan_source_points,
)
from eddiebot.nav.errors import ParameterError
from eddiebot.nav.nodes._common import NavServer, twist_from_msg, twist_to_msg

__all__ = ["CollisionMonitorNode"]


class CollisionMonitorNode(NavServer):
    default_node_name = "collision_monitor"
    PARAMETERS = {
        "cmd_vel_in_topic": "cmd_vel_smoothed", "cmd_vel_out_topic": "cmd_vel",
        "state_topic": "", "base_frame_id": "base_footprint", "odom_frame_id": "odom",
        "transform_tolerance": 0.1, "source_timeout": 2.0, "base_shift_correction": True,
        "stop_pub_timeout": 1.0, "polygons": [""], "observation_sources": [""],
    }

    def __init__(self, node_name: str = "collision_monitor", **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        self.monitor: CollisionMonitor | None = None
        self._sources: dict[str, dict[str, Any]] = {}
        self._latest: dict[str, tuple[Points, int]] = {}
        self._pub: Any = None
        self._state_pub: Any = None
        self._subs: list[Any] = []
        self.tf_buffer = Buffer(node=self)
        self._listener: TransformListener | None = None
        self.last_action = ""

    def on_configure(self, state: State) -> TransitionCallbackReturn:
        def build() -> None:
            from eddiebot.msgs.nav2_msgs import CollisionMonitorState

            tree = self.params_tree()
            for key in ("polygons", "observation_sources"):
                tree[key] = [n for n in tree.get(key, []) if n]
            self.monitor = build_collision_monitor(tree, None, server=self.get_name())
            self._sources = {}
            for name in self.monitor.config.observation_sources:
                sub = dict(tree.get(name) or {})
                kind = str(sub.get("type", "scan"))
                if kind not in ("scan", "range"):
                    raise ParameterError(self.get_name(), f"{name}.type", kind,
                                         "expected scan or range (pointcloud sources are not "
                                         "supported yet)")
                if "topic" not in sub:
                    raise ParameterError(self.get_name(), f"{name}.topic", None, "missing topic")
                self._sources[name] = sub
            cfg = self.monitor.config
            self._pub = self.create_lifecycle_publisher(Twist, cfg.cmd_vel_out_topic, 1)
            if cfg.state_topic:
                self._state_pub = self.create_lifecycle_publisher(CollisionMonitorState,
                                                                  cfg.state_topic, 1)
        return self.configure_with(build)

    def on_activate(self, state: State) -> TransitionCallbackReturn:
        from eddiebot.msgs.sensor_msgs import LaserScan, Range

        assert self.monitor is not None
        self._listener = TransformListener(self.tf_buffer, self)
        self._latest = {}
        types = {"scan": LaserScan, "range": Range}
        for name, sub in self._sources.items():
            if not sub.get("enabled", True):
                continue
            self._subs.append(self.create_subscription(
                types[str(sub.get("type", "scan"))], str(sub["topic"]),
                self._source_callback(name), qos_profile_sensor_data))
        self._subs.append(self.create_subscription(
            Twist, self.monitor.config.cmd_vel_in_topic, self._on_cmd, 1))
        return TransitionCallbackReturn.SUCCESS

    def on_deactivate(self, state: State) -> TransitionCallbackReturn:
        for s in self._subs:
            self.destroy_subscription(s)
        self._subs = []
        if self._listener is not None:
            self._listener.unregister()
            self._listener = None
        return TransitionCallbackReturn.SUCCESS

    def on_cleanup(self, state: State) -> TransitionCallbackReturn:
        for p in (self._pub, self._state_pub):
            if p is not None:
                self.destroy_lifecycle_publisher(p)
        self._pub = self._state_pub = None
        self.monitor = None
        return TransitionCallbackReturn.SUCCESS

    # -- sources ------------------------------------------------------------------------------
    def _source_callback(self, name: str) -> Any:
        def callback(msg: Any) -> None:
            self._on_source(name, msg)
        return callback

    def _sensor_pose(self, frame: str) -> tuple[float, float, float] | None:
        assert self.monitor is not None
        base = self.monitor.config.base_frame_id
        if not frame or frame == base:
            return (0.0, 0.0, 0.0)
        try:
            return self.tf_buffer.lookup_pose2d(base, frame, 0)
        except TransformException:
            return None

    def _on_source(self, name: str, msg: Any) -> None:
        pose = self._sensor_pose(msg.header.frame_id)
        if pose is None:
            return
        sub = self._sources[name]
        kind = str(sub.get("type", "scan"))
        if kind == "scan":
            pts = scan_source_points(msg.ranges, msg.angle_min, msg.angle_increment,
                                     msg.range_min, msg.range_max, pose)
        elif kind == "range":
            pts = range_source_points(float(msg.range), float(msg.min_range), float(msg.max_range),
                                      float(msg.field_of_view), pose,
                                      float(sub.get("obstacles_angle", math.pi / 180.0)))
        else:  # pragma: no cover - rejected at configure
            return
        stamp = stamp_to_ns(msg.header.stamp) or self.now().nanoseconds
        self._latest[name] = (pts, stamp)

    def _gather(self, now_ns: int) -> dict[str, Points | None]:
        assert self.monitor is not None
        out: dict[str, Points | None] = {}
        default_timeout = self.monitor.config.source_timeout
        for name, sub in self._sources.items():
            if not sub.get("enabled", True):
                continue
            timeout = float(sub.get("source_timeout", default_timeout))
            got = self._latest.get(name)
            if got is None:
                out[name] = None if timeout != 0.0 else np.zeros((0, 2))
            elif timeout != 0.0 and (now_ns - got[1]) * 1e-9 > timeout:
                out[name] = None
            else:
                out[name] = got[0]
        return out

    def _on_cmd(self, msg: Any) -> None:
        from eddiebot.msgs.nav2_msgs import CollisionMonitorState

        assert self.monitor is not None
        now = self.now().nanoseconds
        result = self.monitor.process(twist_from_msg(msg), self._gather(now), now)
        if result.publish is not None:
            self._pub.publish(twist_to_msg(result.publish))
        if result.state_changed:
            self.last_action = result.polygon_name
            if result.polygon_name:
                self.get_logger().info(
                    f"robot to {result.action.name.lower()} due to {result.polygon_name} polygon")
            if self._state_pub is not None:
                self._state_pub.publish(CollisionMonitorState(
                    action_type=int(result.action), polygon_name=result.polygon_name))
