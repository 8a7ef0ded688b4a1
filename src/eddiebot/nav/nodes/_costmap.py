"""A layered costmap inside a server node (what ``nav2_costmap_2d::Costmap2DROS`` does).

The planner server owns the global costmap and the controller server the local one; this
helper wires a :class:`~eddiebot.nav.costmap.LayeredCostmap` to the bus: ``/map`` for static
layers, LaserScan and PointCloud2 observation sources for obstacle layers, ``sensor_msgs/Range`` topics for
range layers, an update timer at ``update_frequency`` (robot pose from TF), the
``/<name>/costmap`` (OccupancyGrid) and ``/<name>/costmap_raw`` (nav2_msgs/Costmap)
publishers at ``publish_frequency``, ``/<name>/clear_entirely_<name>``, and the costmap
filters' topics (:class:`~eddiebot.nav.nodes.costmap_filters.FilterHost`).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import numpy.typing as npt

from eddiebot.core.lifecycle import LifecycleNode
from eddiebot.core.qos import DurabilityPolicy, QoSProfile, qos_profile_sensor_data
from eddiebot.core.tf import Buffer, TransformException
from eddiebot.core.time import stamp_to_ns
from eddiebot.maps import map_from_msg
from eddiebot.nav.costmap import (
    LayeredCostmap,
    ObstacleLayer,
    RangeLayer,
    RangeReading,
    StaticLayer,
    cloud_observation,
    scan_observation,
    to_occupancy_grid,
)
from eddiebot.nav.nodes._common import robot_pose
from eddiebot.nav.nodes.costmap_filters import FilterHost

__all__ = ["CostmapHost", "cloud_xyz"]


def cloud_xyz(msg: Any, max_points: int = 20000) -> npt.NDArray[np.float64]:
    """Finite (x, y, z) of a PointCloud2 with float32 x/y/z fields (N x 3, sensor frame),
    evenly subsampled to at most ``max_points``."""
    offsets = {f.name: int(f.offset) for f in msg.fields if int(f.datatype) == 7}
    if not {"x", "y", "z"} <= offsets.keys() or int(msg.point_step) == 0:
        return np.zeros((0, 3))
    n = int(msg.width) * int(msg.height)
    step = int(msg.point_step)
    raw = np.ascontiguousarray(np.asarray(msg.data, dtype=np.uint8)[: n * step])
    fmt = ">f4" if msg.is_bigendian else "<f4"
    dtype = np.dtype({"names": ["x", "y", "z"], "formats": [fmt] * 3,
                      "offsets": [offsets["x"], offsets["y"], offsets["z"]], "itemsize": step})
    rec = np.frombuffer(raw, dtype=dtype, count=raw.size // step)
    out = np.empty((rec.shape[0], 3))
    out[:, 0], out[:, 1], out[:, 2] = rec["x"], rec["y"], rec["z"]
    out = out[np.isfinite(out).all(axis=1)]
    if out.shape[0] > max_points:
        out = out[:: int(np.ceil(out.shape[0] / max_points))]
    return out


def _rotation(x: float, y: float, z: float, w: float) -> npt.NDArray[np.float64]:
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


class CostmapHost:
    """Runs ``costmap`` named ``name`` (``global_costmap`` / ``local_costmap``) for ``node``."""

    def __init__(self, node: LifecycleNode, costmap: LayeredCostmap, name: str, buffer: Buffer) -> None:
        self.node = node
        self.costmap = costmap
        self.name = name
        self.buffer = buffer
        self.pose: npt.NDArray[np.float64] | None = None
        self.updated = False
        self._map_frame = ""
        self._subs: list[Any] = []
        self._timers: list[Any] = []
        self._pubs: list[Any] = []
        self._srv: Any = None
        from eddiebot.msgs.nav2_msgs import Costmap
        from eddiebot.msgs.nav_msgs import OccupancyGrid

        self._grid_pub = node.create_lifecycle_publisher(OccupancyGrid, f"/{name}/costmap", 1)
        from eddiebot.msgs.geometry_msgs import PolygonStamped

        self._raw_pub = node.create_lifecycle_publisher(Costmap, f"/{name}/costmap_raw", 1)
        self._footprint_pub = node.create_lifecycle_publisher(
            PolygonStamped, f"/{name}/published_footprint", 1)
        self._pubs = [self._grid_pub, self._raw_pub, self._footprint_pub]
        self.filters = FilterHost(node, costmap, buffer, on_mask=self.update)

    @property
    def global_frame(self) -> str:
        return self.costmap.config.global_frame

    @property
    def base_frame(self) -> str:
        return self.costmap.config.robot_base_frame

    def activate(self) -> None:
        from eddiebot.msgs.nav2_msgs import ClearEntireCostmap
        from eddiebot.msgs.nav_msgs import OccupancyGrid
        from eddiebot.msgs.sensor_msgs import LaserScan, PointCloud2, Range

        node = self.node
        for layer in self.costmap.layers:
            if isinstance(layer, StaticLayer):
                topic = layer.config.map_topic or self.costmap.config.map_topic or "map"
                qos = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL
                                 if layer.config.map_subscribe_transient_local
                                 else DurabilityPolicy.VOLATILE)
                self._subs.append(node.create_subscription(
                    OccupancyGrid, "/" + topic.lstrip("/"), self._on_map, qos))
            elif isinstance(layer, ObstacleLayer):
                for src_name, src in layer.config.sources.items():
                    if src.data_type == "PointCloud2":
                        self._subs.append(node.create_subscription(
                            PointCloud2, src.topic or "points", self._cloud_cb(layer, src_name),
                            qos_profile_sensor_data))
                        continue
                    self._subs.append(node.create_subscription(
                        LaserScan, src.topic or "scan", self._scan_cb(layer, src_name),
                        qos_profile_sensor_data))
            elif isinstance(layer, RangeLayer):
                for topic in layer.config.topics:
                    if topic:
                        self._subs.append(node.create_subscription(
                            Range, topic, self._range_cb(layer), qos_profile_sensor_data))
        cfg = self.costmap.config
        self._timers.append(node.create_timer(1.0 / cfg.update_frequency, self.update))
        if cfg.publish_frequency > 0.0:
            self._timers.append(node.create_timer(1.0 / cfg.publish_frequency, self.publish))
        self._srv = node.create_service(ClearEntireCostmap,
                                        f"/{self.name}/clear_entirely_{self.name}", self._on_clear)
        self.filters.activate()

    def deactivate(self) -> None:
        for s in self._subs:
            self.node.destroy_subscription(s)
        for t in self._timers:
            self.node.destroy_timer(t)
        if self._srv is not None:
            self.node.destroy_service(self._srv)
        self._subs, self._timers, self._srv = [], [], None
        self.filters.deactivate()

    def destroy(self) -> None:
        self.deactivate()
        for p in self._pubs:
            self.node.destroy_lifecycle_publisher(p)
        self._pubs = []

    # -- inputs -------------------------------------------------------------------------------
    def _on_map(self, msg: Any) -> None:
        self._map_frame = msg.header.frame_id or "map"
        self.costmap.set_static_map(map_from_msg(msg))
        self.update()

    def _transform_at(self, frame: str, stamp_ns: int) -> Any:
        """``global_frame`` <- ``frame`` at the data's stamp (Nav2's observation buffer
        transforms a cloud at its own stamp: a moving robot's scan lands where it was taken).
        The latest transform stands in when ``stamp_ns`` is 0 or within the costmap's
        ``transform_tolerance`` of it; None when neither is known."""
        if stamp_ns:
            try:
                return self.buffer.lookup_transform(self.global_frame, frame, stamp_ns).transform
            except TransformException:
                try:
                    latest = self.buffer.get_latest_common_time(self.global_frame, frame).nanoseconds
                except TransformException:
                    return None
                if abs(stamp_ns - latest) * 1e-9 > self.costmap.config.transform_tolerance:
                    return None
        try:
            return self.buffer.lookup_transform(self.global_frame, frame, 0).transform
        except TransformException:
            return None

    def _sensor_pose(self, frame: str, stamp_ns: int = 0) -> tuple[float, float, float, float] | None:
        t = self._transform_at(frame, stamp_ns)
        if t is None:
            return None
        q = t.rotation
        yaw = math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))
        return (t.translation.x, t.translation.y, t.translation.z, yaw)

    def _scan_cb(self, layer: ObstacleLayer, source: str) -> Any:
        cfg = layer.config.sources[source]

        def callback(msg: Any) -> None:
            stamp = stamp_to_ns(msg.header.stamp)
            pose = self._sensor_pose(cfg.sensor_frame or msg.header.frame_id, stamp)
            if pose is None:
                return
            obs = scan_observation(msg.ranges, msg.angle_min, msg.angle_increment, msg.range_min,
                                   msg.range_max, pose, inf_is_valid=cfg.inf_is_valid,
                                   stamp_ns=stamp)
            layer.add_observation(source, obs)
        return callback

    def _cloud_cb(self, layer: ObstacleLayer, source: str) -> Any:
        cfg = layer.config.sources[source]

        def callback(msg: Any) -> None:
            frame = cfg.sensor_frame or msg.header.frame_id
            t = self._transform_at(frame, stamp_to_ns(msg.header.stamp))
            if t is None:
                return
            pts = cloud_xyz(msg)
            if pts.shape[0] == 0:
                return
            q = t.rotation
            rot = _rotation(q.x, q.y, q.z, q.w)
            origin = np.array([t.translation.x, t.translation.y, t.translation.z])
            glob = pts @ rot.T + origin
            layer.add_observation(source, cloud_observation(glob, origin,
                                                            stamp_to_ns(msg.header.stamp)))
        return callback

    def _range_cb(self, layer: RangeLayer) -> Any:
        def callback(msg: Any) -> None:
            pose = self._sensor_pose(msg.header.frame_id, stamp_to_ns(msg.header.stamp))
            if pose is None:
                return
            layer.add_reading(RangeReading((pose[0], pose[1], pose[3]), float(msg.field_of_view),
                                           float(msg.min_range), float(msg.max_range),
                                           float(msg.range)))
        return callback

    # -- cycle --------------------------------------------------------------------------------
    def robot_pose(self) -> npt.NDArray[np.float64] | None:
        return robot_pose(self.buffer, self.global_frame, self.base_frame,
                          self.node.now().nanoseconds, self.costmap.config.transform_tolerance)

    def latest_robot_pose(self) -> npt.NDArray[np.float64] | None:
        """The robot's pose from the latest transform however old, as Nav2's
        ``Costmap2DROS::getRobotPose`` gives it to the planner (``transform_tolerance`` is a
        wait there, not an age limit); the controller keeps the age check of `robot_pose`."""
        return robot_pose(self.buffer, self.global_frame, self.base_frame,
                          self.node.now().nanoseconds, math.inf)

    def update(self) -> None:
        pose = self.robot_pose()
        if pose is None:
            if self.costmap.rolling_window or self.pose is None:
                return
            pose = self.pose
        self.pose = pose
        now_ns = self.node.now().nanoseconds
        for layer in self.costmap.layers:
            if isinstance(layer, RangeLayer):
                layer.set_time(now_ns)  # no_readings_timeout
            elif isinstance(layer, StaticLayer) and self.costmap.rolling_window:
                layer.map_to_global = self._map_pose()
        self.filters.before_update()
        self.costmap.update_map(pose)
        self.filters.publish_changes()
        self.updated = True

    def _map_pose(self) -> npt.NDArray[np.float64] | None:
        """The map frame's pose in the rolling costmap's frame, looked up at each update as
        Nav2's StaticLayer does (map -> odom moves as localization corrects); None (the
        layer sits this update out) while it is unknown."""
        if self._map_frame in ("", self.global_frame):
            return np.zeros(3)
        try:
            return np.array(self.buffer.lookup_pose2d(self.global_frame, self._map_frame, 0))
        except TransformException:
            return None

    def publish(self) -> None:
        from eddiebot.msgs.geometry_msgs import (
            Point,
            Point32,
            Polygon,
            PolygonStamped,
            Pose,
            Quaternion,
        )
        from eddiebot.msgs.nav2_msgs import Costmap, CostmapMetaData
        from eddiebot.msgs.std_msgs import Header

        if not self.updated:
            return
        now = self.node.now()
        m = self.costmap.master
        grid = to_occupancy_grid(m, self.global_frame, now.nanoseconds)
        self._grid_pub.publish(grid)
        self._raw_pub.publish(Costmap(
            header=Header(stamp=now.to_msg(), frame_id=self.global_frame),
            metadata=CostmapMetaData(
                map_load_time=now.to_msg(), update_time=now.to_msg(), layer="master",
                resolution=float(m.resolution), size_x=m.size_x, size_y=m.size_y,
                origin=Pose(position=Point(x=m.origin_x, y=m.origin_y, z=0.0),
                            orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0))),
            data=np.ascontiguousarray(m.data, dtype=np.uint8).reshape(-1).copy(),
        ))
        # The footprint in the robot frame, as the behaviours and the collision monitor read it.
        self._footprint_pub.publish(PolygonStamped(
            header=Header(stamp=now.to_msg(), frame_id=self.base_frame),
            polygon=Polygon(points=[Point32(x=float(x), y=float(y), z=0.0)
                                    for x, y in self.costmap.footprint])))

    def _on_clear(self, request: Any, response: Any) -> Any:
        self.costmap.clear_entirely()
        self.update()
        return response
