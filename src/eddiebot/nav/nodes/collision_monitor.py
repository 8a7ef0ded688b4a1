"""nav2_collision_monitor as a lifecycle node: ``/cmd_vel_smoothed`` → ``/cmd_vel_safe``.

Sources (``observation_sources``; each ``type: scan | pointcloud | range | polygon | costmap``,
``topic``, ``enabled``, ``source_timeout`` (default: the node's)): ``pointcloud`` keeps points
with ``min_height`` ≤ z ≤ ``max_height`` (0.05 / 0.5 m; in the base frame, or in the odom frame
with ``use_global_height``); ``range`` puts points on the arc at the measured distance every
``obstacles_angle`` (π/180); ``polygon`` (geometry_msgs/PolygonInstanceStamped, one shape per
``id``, dropped after ``source_timeout``) samples each outline every ``sampling_distance``
(0.1 m); ``costmap`` (nav2_msgs/Costmap, e.g. ``/local_costmap/costmap_raw``; Nav2 Kilted's
``CostmapSource``) gives the centres of cells with cost in [``cost_threshold`` (253), 255),
and of unknown cells with ``treat_unknown_as_obstacle`` (true): the costmap remembers what
the sensors no longer see, beside or behind a robot whose sensors all look ahead. The newest message of each source is turned into base-frame points when a command
arrives: with ``base_shift_correction`` through ``odom`` from the data's stamp to the latest
odometry (the robot moved since), else with the latest sensor-to-base transform. An enabled
source with no data, stale data or no transform stops the robot ("invalid source") unless
its ``source_timeout`` is 0.

Zones (``polygons``): ``polygon`` (``points``, or ``polygon_sub_topic`` /
``footprint_topic`` for approach, geometry_msgs/PolygonStamped transformed into the base
frame), ``circle`` and ``velocity_polygon``, with Nav2's actions (stop, slowdown, limit,
approach); ``visualize`` publishes each zone's current shape on ``polygon_pub_topic``
(default: its name). ``state_topic`` publishes nav2_msgs/CollisionMonitorState when the active
zone changes. ``use_realtime_priority`` is accepted and ignored.

Beyond Nav2 (never drive blind): with ``localization_check``, a lost localization — no
``map → odom`` or one older than ``localization_tf_timeout`` s, or ``localization_pose_topic``
(``amcl_pose``) reporting a position std above ``localization_max_xy_std`` m or a heading std
above ``localization_max_yaw_std`` rad — stops the autonomous commands too, reported like a
zone named after the reason. Teleop goes to the mux directly and is not affected.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from eddiebot.core.lifecycle import State, TransitionCallbackReturn
from eddiebot.core.qos import qos_profile_sensor_data
from eddiebot.core.tf import Buffer, ExtrapolationException, TransformException, TransformListener
from eddiebot.core.time import stamp_to_ns
from eddiebot.geometry import quaternion_to_matrix
from eddiebot.msgs.geometry_msgs import Twist
from eddiebot.nav.collision_monitor import (
    SOURCE_TYPES,
    CollisionMonitor,
    Points,
    build_collision_monitor,
    cloud_source_points,
    costmap_source_points,
    polygon_source_points,
    range_source_points,
    scan_source_points,
)
from eddiebot.nav.errors import ParameterError
from eddiebot.nav.nodes._common import NavServer, twist_from_msg, twist_to_msg
from eddiebot.nav.nodes.amcl import LocalizationWatch

__all__ = ["SOURCE_KEYS", "CollisionMonitorNode"]

_SOURCE_DEFAULTS: dict[str, dict[str, Any]] = {
    "scan": {},
    "pointcloud": {"min_height": 0.05, "max_height": 0.5, "use_global_height": False},
    "range": {"obstacles_angle": math.pi / 180.0},
    "polygon": {"sampling_distance": 0.1},
    "costmap": {"cost_threshold": 253, "treat_unknown_as_obstacle": True},
}
#: the keys each source type reads
SOURCE_KEYS: dict[str, frozenset[str]] = {
    kind: frozenset({"type", "topic", "enabled", "source_timeout", *defaults})
    for kind, defaults in _SOURCE_DEFAULTS.items()}


def _matrix(t: Any) -> np.ndarray:
    """TransformStamped -> 4 x 4."""
    m = np.eye(4)
    r = t.transform.rotation
    m[:3, :3] = quaternion_to_matrix((r.x, r.y, r.z, r.w))
    tr = t.transform.translation
    m[:3, 3] = (tr.x, tr.y, tr.z)
    return m


def _cost_threshold(server: str, source: str, value: Any) -> int:
    """``<source>.cost_threshold``: an integer, clamped to 0-255 with a warning upstream; here
    a value outside is an error naming it."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or value != int(value):
        raise ParameterError(server, f"{source}.cost_threshold", value, "must be an integer")
    if not 0 <= int(value) <= 255:
        raise ParameterError(server, f"{source}.cost_threshold", value, "must be in 0-255")
    return int(value)


def _pose2d(m: np.ndarray) -> tuple[float, float, float]:
    return float(m[0, 3]), float(m[1, 3]), math.atan2(float(m[1, 0]), float(m[0, 0]))


class CollisionMonitorNode(NavServer):
    default_node_name = "collision_monitor"
    PARAMETERS = {
        "cmd_vel_in_topic": "cmd_vel_smoothed", "cmd_vel_out_topic": "cmd_vel",
        "state_topic": "", "base_frame_id": "base_footprint", "odom_frame_id": "odom",
        "transform_tolerance": 0.1, "source_timeout": 2.0, "base_shift_correction": True,
        "stop_pub_timeout": 1.0, "polygons": [""], "observation_sources": [""],
        "use_realtime_priority": False,
        # eddiebot: stop on lost localization
        "localization_check": False, "global_frame_id": "map",
        "localization_pose_topic": "amcl_pose", "localization_tf_timeout": 1.0,
        "localization_max_xy_std": 0.5, "localization_max_yaw_std": 0.5,
    }

    def __init__(self, node_name: str = "collision_monitor", **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        self.monitor: CollisionMonitor | None = None
        self._sources: dict[str, dict[str, Any]] = {}
        self._latest: dict[str, Any] = {}
        self._polygons: dict[str, dict[int, Any]] = {}
        self._pub: Any = None
        self._state_pub: Any = None
        self._viz_pubs: dict[str, Any] = {}
        self._subs: list[Any] = []
        self.tf_buffer = Buffer(node=self)
        self._listener: TransformListener | None = None
        self._watch: LocalizationWatch | None = None
        self.last_action = ""
        self.last_state: tuple[int, str] | None = None

    def on_configure(self, state: State) -> TransitionCallbackReturn:
        def build() -> None:
            from eddiebot.msgs.geometry_msgs import PolygonStamped
            from eddiebot.msgs.nav2_msgs import CollisionMonitorState

            tree = self.params_tree()
            for key in ("polygons", "observation_sources"):
                tree[key] = [n for n in tree.get(key, []) if n]
            own = [k for k in tree if k.startswith("localization_") or k == "global_frame_id"]
            for k in own:
                tree.pop(k)
            self.monitor = build_collision_monitor(tree, None, server=self.get_name())
            self._sources = {}
            for name in self.monitor.config.observation_sources:
                sub = dict(tree.get(name) or {})
                kind = str(sub.get("type", "scan"))
                if kind not in SOURCE_TYPES:
                    raise ParameterError(self.get_name(), f"{name}.type", kind,
                                         f"must be one of {list(SOURCE_TYPES)}")
                if "topic" not in sub:
                    raise ParameterError(self.get_name(), f"{name}.topic", None, "missing topic")
                merged = {"type": kind, "enabled": True,
                          "source_timeout": self.monitor.config.source_timeout,
                          **_SOURCE_DEFAULTS[kind], **sub}
                for key in ("source_timeout", "min_height", "max_height", "obstacles_angle",
                            "sampling_distance"):
                    if key in merged:
                        try:
                            merged[key] = float(merged[key])
                        except (TypeError, ValueError) as exc:
                            raise ParameterError(self.get_name(), f"{name}.{key}", merged[key],
                                                 "must be a number") from exc
                if kind == "costmap":
                    merged["cost_threshold"] = _cost_threshold(self.get_name(), name,
                                                               merged["cost_threshold"])
                    unknown = merged["treat_unknown_as_obstacle"]
                    if not isinstance(unknown, bool):
                        raise ParameterError(self.get_name(), f"{name}.treat_unknown_as_obstacle",
                                             unknown, "must be true or false")
                if kind == "polygon" and merged["sampling_distance"] <= 0.0:
                    raise ParameterError(self.get_name(), f"{name}.sampling_distance",
                                         merged["sampling_distance"], "must be > 0")
                self._sources[name] = merged
            cfg = self.monitor.config
            self._pub = self.create_lifecycle_publisher(Twist, cfg.cmd_vel_out_topic, 1)
            if cfg.state_topic:
                self._state_pub = self.create_lifecycle_publisher(CollisionMonitorState,
                                                                  cfg.state_topic, 1)
            self._viz_pubs = {
                z.name: self.create_lifecycle_publisher(
                    PolygonStamped, z.config.polygon_pub_topic or z.name, 1)
                for z in self.monitor.zones if z.config.visualize}
        return self.configure_with(build)

    def on_activate(self, state: State) -> TransitionCallbackReturn:
        from eddiebot.msgs.geometry_msgs import PolygonInstanceStamped, PolygonStamped
        from eddiebot.msgs.nav2_msgs import Costmap
        from eddiebot.msgs.sensor_msgs import LaserScan, PointCloud2, Range

        assert self.monitor is not None
        self._listener = TransformListener(self.tf_buffer, self)
        self._latest = {}
        self._polygons = {}
        types = {"scan": LaserScan, "range": Range, "pointcloud": PointCloud2,
                 "polygon": PolygonInstanceStamped, "costmap": Costmap}
        for name, sub in self._sources.items():
            if not sub.get("enabled", True):
                continue
            # upstream subscribes to the costmap with the standard (reliable) QoS
            qos = 1 if sub["type"] == "costmap" else qos_profile_sensor_data
            self._subs.append(self.create_subscription(
                types[sub["type"]], str(sub["topic"]), self._source_callback(name), qos))
        for zone in self.monitor.zones:
            if zone.dynamic_topic:
                self._subs.append(self.create_subscription(
                    PolygonStamped, zone.dynamic_topic, self._shape_callback(zone.name), 1))
        self._subs.append(self.create_subscription(
            Twist, self.monitor.config.cmd_vel_in_topic, self._on_cmd, 1))
        if bool(self.param("localization_check")):
            self._watch = LocalizationWatch.from_parameters(self, self.tf_buffer, self.monitor.config.odom_frame_id)
        return TransitionCallbackReturn.SUCCESS

    def on_deactivate(self, state: State) -> TransitionCallbackReturn:
        for s in self._subs:
            self.destroy_subscription(s)
        self._subs = []
        if self._watch is not None:
            self._watch.destroy()
            self._watch = None
        if self._listener is not None:
            self._listener.unregister()
            self._listener = None
        return TransitionCallbackReturn.SUCCESS

    def on_cleanup(self, state: State) -> TransitionCallbackReturn:
        for p in (self._pub, self._state_pub, *self._viz_pubs.values()):
            if p is not None:
                self.destroy_lifecycle_publisher(p)
        self._pub = self._state_pub = None
        self._viz_pubs = {}
        self.monitor = None
        return TransitionCallbackReturn.SUCCESS

    # -- inputs -------------------------------------------------------------------------------
    def _source_callback(self, name: str) -> Any:
        def callback(msg: Any) -> None:
            if self._sources[name]["type"] == "polygon":
                self._polygons.setdefault(name, {})[int(msg.polygon.id)] = msg
            else:
                self._latest[name] = msg
        return callback

    def _shape_callback(self, zone_name: str) -> Any:
        def callback(msg: Any) -> None:
            assert self.monitor is not None
            pts = np.array([[p.x, p.y] for p in msg.polygon.points], dtype=np.float64).reshape(-1, 2)
            pose = self._sensor_pose(msg.header.frame_id, 0)
            if pose is None:
                self.get_logger().warning(f"{zone_name}: cannot transform the polygon from "
                                          f"{msg.header.frame_id!r}", once=True)
                return
            x, y, yaw = pose
            c, s = math.cos(yaw), math.sin(yaw)
            base = np.stack([x + c * pts[:, 0] - s * pts[:, 1], y + s * pts[:, 0] + c * pts[:, 1]],
                            axis=-1)
            self.monitor.zone(zone_name).set_polygon(base)
        return callback

    # -- transforms ---------------------------------------------------------------------------
    def _sensor_matrix(self, frame: str, stamp_ns: int) -> np.ndarray | None:
        """4 x 4 taking ``frame`` points at ``stamp_ns`` into the base frame now (latest)."""
        assert self.monitor is not None
        cfg = self.monitor.config
        base = cfg.base_frame_id
        if not frame or frame == base:
            if not cfg.base_shift_correction or stamp_ns == 0:
                return np.eye(4)
            frame = base
        try:
            if cfg.base_shift_correction and stamp_ns != 0:
                try:
                    t = self.tf_buffer.lookup_transform_full(base, 0, frame, stamp_ns,
                                                             cfg.odom_frame_id)
                except ExtrapolationException:
                    # Data newer than the odometry (they tick together): upstream waits up to
                    # transform_tolerance for it; the robot moved (almost) nothing since.
                    latest = self.tf_buffer.get_latest_common_time(cfg.odom_frame_id, base)
                    if (stamp_ns - latest.nanoseconds) * 1e-9 > cfg.transform_tolerance:
                        return None
                    t = self.tf_buffer.lookup_transform(base, frame, 0)
            else:
                t = self.tf_buffer.lookup_transform(base, frame, 0)
        except TransformException:
            return None
        return _matrix(t)

    def _sensor_pose(self, frame: str, stamp_ns: int) -> tuple[float, float, float] | None:
        m = self._sensor_matrix(frame, stamp_ns)
        return None if m is None else _pose2d(m)

    def _points(self, name: str, msg: Any) -> Points | None:
        """Base-frame points of a source's message; None when it cannot be transformed."""
        sub = self._sources[name]
        kind = sub["type"]
        stamp = stamp_to_ns(msg.header.stamp)
        m = self._sensor_matrix(msg.header.frame_id, stamp)
        if m is None:
            return None
        pose = _pose2d(m)
        if kind == "scan":
            return scan_source_points(msg.ranges, msg.angle_min, msg.angle_increment,
                                      msg.range_min, msg.range_max, pose)
        if kind == "range":
            return range_source_points(float(msg.range), float(msg.min_range),
                                       float(msg.max_range), float(msg.field_of_view), pose,
                                       float(sub["obstacles_angle"]))
        if kind == "costmap":
            meta = msg.metadata
            return costmap_source_points(
                msg.data, int(meta.size_x), int(meta.size_y), float(meta.resolution),
                (float(meta.origin.position.x), float(meta.origin.position.y)),
                int(sub["cost_threshold"]), bool(sub["treat_unknown_as_obstacle"]), pose)
        if kind == "pointcloud":
            from eddiebot.nav.nodes._costmap import cloud_xyz

            xyz = cloud_xyz(msg)
            base = xyz @ m[:3, :3].T + m[:3, 3]
            if not sub.get("use_global_height", False):
                return cloud_source_points(base, float(sub["min_height"]), float(sub["max_height"]))
            try:
                g = _matrix(self.tf_buffer.lookup_transform(
                    self.monitor.config.odom_frame_id if self.monitor else "odom",
                    self.monitor.config.base_frame_id if self.monitor else "base_footprint", 0))
            except TransformException:
                return None
            z = base @ g[2, :3] + g[2, 3]
            keep = (z >= float(sub["min_height"])) & (z <= float(sub["max_height"]))
            return base[keep, :2].copy()
        raise AssertionError(kind)  # pragma: no cover - rejected at configure

    def _polygon_points(self, name: str, now_ns: int) -> Points | None:
        sub = self._sources[name]
        timeout = float(sub["source_timeout"])
        shapes = self._polygons.get(name, {})
        for pid in [k for k, m in shapes.items()
                    if (now_ns - stamp_to_ns(m.header.stamp)) * 1e-9 > timeout]:
            del shapes[pid]
        if not shapes:
            return None
        outlines = []
        for msg in shapes.values():
            m = self._sensor_matrix(msg.header.frame_id, stamp_to_ns(msg.header.stamp))
            if m is None:
                return None
            pts = np.array([[p.x, p.y, p.z] for p in msg.polygon.polygon.points],
                           dtype=np.float64).reshape(-1, 3)
            outlines.append((pts @ m[:3, :3].T + m[:3, 3])[:, :2])
        return polygon_source_points(outlines, float(sub["sampling_distance"]))

    def _gather(self, now_ns: int) -> dict[str, Points | None]:
        """Points of every enabled source; None for one without valid recent data (which stops
        the robot unless that source's timeout is 0: then it just contributes nothing)."""
        out: dict[str, Points | None] = {}
        for name, sub in self._sources.items():
            if not sub.get("enabled", True):
                continue
            timeout = float(sub["source_timeout"])
            pts: Points | None
            if sub["type"] == "polygon":
                pts = self._polygon_points(name, now_ns)
            else:
                msg = self._latest.get(name)
                if msg is None:
                    pts = None
                else:
                    stamp = stamp_to_ns(msg.header.stamp)
                    fresh = timeout == 0.0 or (now_ns - stamp) * 1e-9 <= timeout
                    pts = self._points(name, msg) if fresh else None
            if pts is None and timeout == 0.0:
                pts = np.zeros((0, 2))
            out[name] = pts
        return out

    def _on_cmd(self, msg: Any) -> None:
        from eddiebot.msgs.nav2_msgs import CollisionMonitorState

        assert self.monitor is not None
        now = self.now().nanoseconds
        reason = self._watch.problem(now) if self._watch is not None else ""
        result = self.monitor.process(twist_from_msg(msg), self._gather(now), now, stop_reason=reason)
        if result.publish is not None:
            self._pub.publish(twist_to_msg(result.publish))
        if result.state_changed:
            self.last_action = result.polygon_name
            self.last_state = (int(result.action), result.polygon_name)
            if result.polygon_name:
                log = self.get_logger().warning if result.action.name == "STOP" else \
                    self.get_logger().info
                log(f"robot to {result.action.name.lower()} due to {result.polygon_name}")
            else:
                self.get_logger().info("robot to continue normal operation")
            if self._state_pub is not None:
                self._state_pub.publish(CollisionMonitorState(
                    action_type=int(result.action), polygon_name=result.polygon_name))
        self._publish_shapes(now)

    def _publish_shapes(self, now_ns: int) -> None:
        from eddiebot.msgs.geometry_msgs import Point32, PolygonStamped

        if not self._viz_pubs or self.monitor is None:
            return
        for zone in self.monitor.zones:
            pub = self._viz_pubs.get(zone.name)
            if pub is None or not zone.config.enabled:
                continue
            msg = PolygonStamped()
            msg.header.frame_id = self.monitor.config.base_frame_id
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(now_ns, 1_000_000_000)
            if zone.config.type == "circle":
                a = np.linspace(0.0, 2.0 * math.pi, 32, endpoint=False)
                pts = np.stack([np.cos(a), np.sin(a)], axis=-1) * zone.config.radius
            else:
                pts = zone.poly if zone.poly is not None else np.zeros((0, 2))
            msg.polygon.points = [Point32(x=float(x), y=float(y), z=0.0) for x, y in pts]
            pub.publish(msg)
