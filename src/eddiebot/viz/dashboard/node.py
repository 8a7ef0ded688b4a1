"""The dashboard's node: subscribes to what the page shows, publishes what the page commands.

Everything the browser draws is expressed in one *display frame*: ``map`` when TF links
``map`` to ``base_footprint``, else ``odom``. Callbacks run on the dashboard's own executor
thread and hand ready-made frames to the :class:`~eddiebot.viz.dashboard.hub.Hub`; commands
arrive from the web server's thread and publish directly.

Heavy layers are throttled and decimated before they travel: AMCL's particle cloud (at most
``MAX_PARTICLES`` at 5 Hz), the vSLAM graph (1 Hz), and the point clouds of the 3D view, which
are converted only while a page has that view open (2 Hz at most; the assembled map up to
``MAX_CLOUD_POINTS``, the live ``/points`` up to ``MAX_LIVE_POINTS``). The
velocity source that holds ``cmd_vel`` is worked out as twist_mux does, from the mux's own
parameters (read from the running ``twist_mux`` node, twist_mux's defaults until it answers)
and the commands and locks seen on its input topics.

Keepout zones painted on the page go into a copy of the current keepout mask (the one on
``/keepout_filter_mask``, else an empty one shaped as ``/map``), which is written to a
map_server file and handed to the keepout filter mask server's ``load_map``: the server
publishes it and the costmaps' keepout filters take it.
"""

from __future__ import annotations

import functools
import math
import tempfile
import threading
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from xml.etree import ElementTree

import numpy as np

from eddiebot.base.twist_mux import DEFAULT_LOCKS, DEFAULT_TOPICS, MuxInput, TwistMux
from eddiebot.core.action import ActionClient
from eddiebot.core.clock_node import ROSOUT_QOS
from eddiebot.core.context import Context
from eddiebot.core.errors import TopicTypeMismatchError
from eddiebot.core.node import Node
from eddiebot.core.param_services import ParameterClient
from eddiebot.core.parameters import value_from_msg
from eddiebot.core.qos import QoSProfile, qos_profile_latched, qos_profile_sensor_data
from eddiebot.core.task import Future
from eddiebot.core.tf import Buffer, TransformException
from eddiebot.maps import OccupancyMap, map_from_msg, map_to_world, save_map
from eddiebot.msgs import get_action, get_message, get_service
from eddiebot.robot.urdf import BASE_RADIUS_M
from eddiebot.viz.dashboard.core import (
    GridMeta,
    TileCache,
    binary_frame,
    colorize_depth,
    depth_to_metres,
    encode_jpeg,
    image_to_bgr,
    text_frame,
)
from eddiebot.viz.dashboard.errors import CommandError
from eddiebot.viz.dashboard.hub import Hub

__all__ = ["FOOTPRINT_RADIUS", "GRID_LAYERS", "MAX_CLOUD_POINTS", "MAX_LIVE_POINTS", "MAX_PARTICLES",
           "RANGE_TOPICS",
           "DashboardNode", "DashboardTopics", "footprint_from_urdf"]

#: Eddie's footprint radius (m): the URDF's base_link cylinder, until /robot_description says.
FOOTPRINT_RADIUS = BASE_RADIUS_M
RANGE_TOPICS = ("/eddie/ir/left", "/eddie/ir/center", "/eddie/ir/right",
                "/eddie/ping/left", "/eddie/ping/right")
#: layer name → topic (vslam_map: rtabmap's grid at its default ``map_topic``)
GRID_LAYERS = {"map": "/map", "global_costmap": "/global_costmap/costmap",
               "local_costmap": "/local_costmap/costmap", "vslam_map": "/rtabmap/map"}
#: particles sent per cloud (more are decimated evenly)
MAX_PARTICLES = 5000
#: points sent per 3D cloud (more are decimated evenly): the assembled map is sent when it
#: changes (rarely), the live sensor cloud twice a second, so it gets fewer
MAX_CLOUD_POINTS = 60000
MAX_LIVE_POINTS = 20000
#: points (or segment ends) sent per graph marker
_MAX_MARKER_POINTS = 20000
_NS = 1_000_000_000
_POINT_MARKERS = {6, 7, 8}  # CUBE_LIST, SPHERE_LIST, POINTS
_LINE_MARKERS = {4, 5}  # LINE_STRIP, LINE_LIST


@dataclass(frozen=True)
class DashboardTopics:
    """Topic names the dashboard uses (ROS 2 defaults of the stack)."""

    scan: str = "/scan"
    odom: str = "/odom"
    plan: str = "/plan"
    local_plan: str = "/local_plan"
    goal_pose: str = "/goal_pose"
    initial_pose: str = "/initialpose"
    image: str = "/image_raw"
    depth: str = "/depth/image_raw"
    battery: str = "/eddie/battery_level"
    collisions: str = "/sim/collisions"
    rosout: str = "/rosout"
    cmd_vel: str = "/cmd_vel_teleop"
    e_stop: str = "/e_stop"
    base_frame: str = "base_footprint"
    navigate_action: str = "navigate_to_pose"
    map_saver: str = "/map_saver/save_map"
    slam_saver: str = "/slam_toolbox/save_map"
    particle_cloud: str = "/particle_cloud"
    lookahead: str = "/lookahead_point"
    footprint: str = "/local_costmap/published_footprint"
    robot_description: str = "/robot_description"
    vslam_graph: str = "/rtabmap/mapGraph"
    cloud_map: str = "/rtabmap/cloud_map"
    points: str = "/points"
    twist_mux: str = "/twist_mux"
    keepout_mask: str = "/keepout_filter_mask"
    keepout_mask_server: str = "/keepout_filter_mask_server/load_map"


def footprint_from_urdf(text: str) -> float | None:
    """Footprint radius (m) of a URDF: base_link's collision (else visual) cylinder; None
    when the description has none. Raises ``ValueError`` on malformed XML."""
    try:
        root = ElementTree.fromstring(text)
    except ElementTree.ParseError as exc:
        raise ValueError(f"robot_description is not valid XML: {exc}") from None
    for link in root.iter("link"):
        if link.get("name") != "base_link":
            continue
        for part in ("collision", "visual"):
            for cyl in link.findall(f"{part}/geometry/cylinder"):
                r = float(cyl.get("radius", "nan"))
                if math.isfinite(r) and r > 0:
                    return r
    return None


def _quat_matrix(x: float, y: float, z: float, w: float) -> np.ndarray:
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def _yaw(q: Any) -> float:
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def _compose(a: tuple[float, float, float], x: float, y: float, yaw: float) -> tuple[float, float, float]:
    c, s = math.cos(a[2]), math.sin(a[2])
    return (a[0] + c * x - s * y, a[1] + s * x + c * y, math.remainder(a[2] + yaw, 2 * math.pi))


def _r(v: float, nd: int = 4) -> float:
    return round(float(v), nd) if math.isfinite(v) else 0.0


class _Rate:
    """Receipt times of one topic (wall ns) for a rate over the last two seconds."""

    __slots__ = ("last_ns", "times")

    def __init__(self) -> None:
        self.times: deque[int] = deque(maxlen=200)
        self.last_ns: int | None = None

    def tick(self, now_ns: int) -> None:
        self.times.append(now_ns)
        self.last_ns = now_ns

    def hz(self, now_ns: int) -> float:
        recent = [t for t in self.times if now_ns - t <= 2 * _NS]
        if len(recent) < 2:
            return 0.0
        return (len(recent) - 1) * _NS / max(1, recent[-1] - recent[0])


class DashboardNode(Node):
    """Turns topics into dashboard frames and browser commands into topics, actions and calls."""

    def __init__(self, hub: Hub, *, context: Context | None = None, name: str = "eddie_dashboard",
                 topics: DashboardTopics | None = None, image_rate_hz: float = 5.0,
                 pose_rate_hz: float = 50.0) -> None:
        super().__init__(name, context=context, start_parameter_services=False)
        self.hub = hub
        self.topics = t = topics or DashboardTopics()
        self._wall = self.context.system_clock
        self._cmd_lock = threading.RLock()
        self.tf = Buffer(cache_time=10.0)
        self.display_frame = "odom"
        self._rates: dict[str, _Rate] = {}
        self._problems: dict[str, str] = {}
        self._tiles = {layer: TileCache() for layer in GRID_LAYERS}
        self._grid_meta: dict[str, GridMeta] = {}
        self._grid_placed: dict[str, tuple[str, tuple[float, float, float]] | None] = {}
        self._image_period_ns = round(_NS / image_rate_hz)
        self._pose_period_ns = round(_NS / pose_rate_hz)
        self._last_image_ns: dict[str, int] = {}
        self._last_pose_ns = 0
        self._last_range_ns: dict[str, int] = {}
        self._status: dict[str, Any] = {"battery": None, "linear": None, "angular": None,
                                        "collisions": None}
        self._logs: deque[dict[str, Any]] = deque(maxlen=200)
        self.footprint_radius = FOOTPRINT_RADIUS
        self.footprint_source = "URDF (built in)"
        self._last_layer_ns: dict[str, int] = {}
        #: latched-style layers (plans, lookahead): the newest message, re-placed when the
        #: display frame changes or when TF for it arrives after the message did
        self._replay: dict[str, tuple[Callable[[Any], None], Any]] = {}
        self._unplaced: set[str] = set()
        #: newest graph and cloud messages with their arrival count; sent counts per name
        self._clouds: dict[str, tuple[int, Any]] = {}
        self._cloud_sent: dict[str, int] = {}
        self._mux = TwistMux(*self._mux_inputs(None))
        self._mux_source = "twist_mux defaults"
        self._mux_subs: dict[str, Any] = {}
        self._mux_params: ParameterClient | None = None
        self._mux_query: Future | None = None
        self._logs_dirty = False
        self._goal: dict[str, Any] | None = None
        self._estop = False
        self._teleop: tuple[float, float] | None = None
        self._teleop_refresh_ns = 0
        #: seconds a held teleop command lives without a refresh from the browser
        self.teleop_timeout_s = 0.5

        msg = get_message
        self._twist_cls = msg("geometry_msgs/msg/Twist")
        self._bool_cls = msg("std_msgs/msg/Bool")
        self._pose_stamped_cls = msg("geometry_msgs/msg/PoseStamped")
        self._pose_cov_cls = msg("geometry_msgs/msg/PoseWithCovarianceStamped")
        self._cmd_pub = self.create_publisher(self._twist_cls, t.cmd_vel, 10)
        self._estop_pub = self.create_publisher(self._bool_cls, t.e_stop, qos_profile_latched)
        self._goal_pub = self.create_publisher(self._pose_stamped_cls, t.goal_pose, 10)
        self._initial_pub = self.create_publisher(self._pose_cov_cls, t.initial_pose, 10)
        self._nav = ActionClient(self, get_action("nav2_msgs/action/NavigateToPose"), t.navigate_action)
        self._nav_handles: list[Any] = []
        self._map_saver = self.create_client(get_service("nav2_msgs/srv/SaveMap"), t.map_saver)
        self._slam_saver = self.create_client(get_service("slam_toolbox/srv/SaveMap"), t.slam_saver)
        self._mask_loader = self.create_client(get_service("nav2_msgs/srv/LoadMap"),
                                               t.keepout_mask_server)
        self._keepout: OccupancyMap | None = None
        self._keepout_dir: Path | None = None
        self._keepout_count = 0

        tf_msg = msg("tf2_msgs/msg/TFMessage")
        grid = msg("nav_msgs/msg/OccupancyGrid")
        self._sub(tf_msg, "/tf", self._on_tf, 100)
        self._sub(tf_msg, "/tf_static", self._on_tf_static,
                  QoSProfile(depth=100, durability=qos_profile_latched.durability))
        for layer, topic in GRID_LAYERS.items():
            self._sub(grid, topic, functools.partial(self._on_grid, layer), qos_profile_latched)
        self._sub(msg("sensor_msgs/msg/LaserScan"), t.scan, self._on_scan, qos_profile_sensor_data)
        for topic in RANGE_TOPICS:
            self._sub(msg("sensor_msgs/msg/Range"), topic,
                      functools.partial(self._on_range, topic), qos_profile_sensor_data)
        path = msg("nav_msgs/msg/Path")
        self._sub(path, t.plan, lambda m: self._on_path("plan", t.plan, m), 5)
        self._sub(path, t.local_plan, lambda m: self._on_path("local_plan", t.local_plan, m), 5)
        self._sub(self._pose_stamped_cls, t.goal_pose, self._on_goal_pose, 5)
        image = msg("sensor_msgs/msg/Image")
        self._sub(image, t.image, lambda m: self._on_image("camera", t.image, m), qos_profile_sensor_data)
        self._sub(image, t.depth, lambda m: self._on_image("depth", t.depth, m), qos_profile_sensor_data)
        self._sub(msg("eddiebot_msgs/msg/BatteryLevel"), t.battery, self._on_battery, 5)
        self._sub(msg("nav_msgs/msg/Odometry"), t.odom, self._on_odom, 10)
        self._sub(msg("std_msgs/msg/UInt32"), t.collisions, self._on_collisions, 5)
        self._sub(msg("rcl_interfaces/msg/Log"), t.rosout, self._on_log, ROSOUT_QOS)
        self._sub(self._bool_cls, t.e_stop, self._on_estop, qos_profile_latched)
        self._sub(msg("nav2_msgs/msg/ParticleCloud"), t.particle_cloud, self._on_particles,
                  qos_profile_sensor_data)
        self._sub(msg("geometry_msgs/msg/PointStamped"), t.lookahead, self._on_lookahead, 5)
        self._sub(msg("geometry_msgs/msg/PolygonStamped"), t.footprint, self._on_footprint, 5)
        self._sub(msg("std_msgs/msg/String"), t.robot_description, self._on_description,
                  qos_profile_latched)
        self._sub(msg("visualization_msgs/msg/MarkerArray"), t.vslam_graph, self._on_graph,
                  qos_profile_latched)
        cloud = msg("sensor_msgs/msg/PointCloud2")
        self._sub(cloud, t.cloud_map, functools.partial(self._on_cloud, "cloud_map"), qos_profile_latched)
        self._sub(cloud, t.points, functools.partial(self._on_cloud, "points"), qos_profile_sensor_data)
        self._sub(grid, t.keepout_mask, self._on_keepout_mask, qos_profile_latched)
        self._subscribe_mux()
        try:
            self._mux_params = ParameterClient(self, t.twist_mux)
        except TopicTypeMismatchError as exc:
            self._problems[t.twist_mux] = str(exc)
        self.create_timer(0.2, self._status_tick, clock=self._wall)
        self.create_timer(0.1, self._teleop_tick, clock=self._wall)
        self.hub.post("estop", text_frame("estop", locked=False))
        self._post_robot()

    # -- plumbing -------------------------------------------------------------------------
    def _sub(self, cls: Any, topic: str, cb: Callable[[Any], None], qos: Any) -> None:
        def counted(m: Any, topic: str = topic) -> None:
            self._rates.setdefault(topic, _Rate()).tick(self._wall.now_ns())
            cb(m)

        try:
            self.create_subscription(cls, topic, counted, qos)
        except TopicTypeMismatchError as exc:
            self._problems[topic] = str(exc)
            self.get_logger().warning(f"dashboard cannot show {topic}: {exc}")

    def _to_display(self, frame: str) -> tuple[float, float, float] | None:
        """Pose of ``frame`` in the display frame at the latest time, or None."""
        frame = frame.lstrip("/") or self.display_frame
        if frame == self.display_frame:
            return (0.0, 0.0, 0.0)
        try:
            return self.tf.lookup_pose2d(self.display_frame, frame)
        except TransformException:
            return None

    def _choose_display_frame(self) -> None:
        base = self.topics.base_frame
        frame = "map" if self.tf.can_transform("map", base) else "odom"
        if frame != self.display_frame:
            self.display_frame = frame
            self._place_grids()
            self.hub.drop_prefix("path:")
            self.hub.drop_prefix("range:")
            self._unplaced.update(self._replay)

    def _replay_unplaced(self) -> None:
        for key in list(self._unplaced):
            handler, msg = self._replay[key]
            self._last_layer_ns.pop(key, None)
            handler(msg)

    # -- TF and pose ----------------------------------------------------------------------
    def _on_tf(self, msg: Any) -> None:
        for tr in msg.transforms:
            self.tf.set_transform(tr, "dashboard")
        now = self._wall.now_ns()
        if now - self._last_pose_ns >= self._pose_period_ns:
            self._last_pose_ns = now
            self._post_pose()

    def _on_tf_static(self, msg: Any) -> None:
        for tr in msg.transforms:
            self.tf.set_transform_static(tr, "dashboard")
        self._post_pose()

    def _post_pose(self) -> None:
        self._choose_display_frame()
        pose = self._to_display(self.topics.base_frame)
        if pose is None:
            return
        self.hub.post("pose", text_frame(
            "pose", frame=self.display_frame, x=_r(pose[0]), y=_r(pose[1]), yaw=_r(pose[2]),
            wall_ns=self._wall.now_ns()))

    # -- grids ----------------------------------------------------------------------------
    def _on_grid(self, layer: str, msg: Any) -> None:
        info = msg.info
        o = info.origin
        meta = GridMeta(int(info.width), int(info.height), float(info.resolution),
                        (float(o.position.x), float(o.position.y), _yaw(o.orientation)),
                        msg.header.frame_id.lstrip("/") or "map")
        cells = np.asarray(msg.data, dtype=np.int8)
        if cells.size != meta.width * meta.height or meta.resolution <= 0:
            self._problems[GRID_LAYERS[layer]] = (
                f"grid of {cells.size} cells does not match {meta.width}x{meta.height}")
            return
        cache = self._tiles[layer]
        new_gen, tiles = cache.update(meta, cells.reshape(meta.height, meta.width))
        if new_gen:
            self._grid_meta[layer] = meta
            self.hub.drop_prefix(f"tile:{layer}:")
            self._post_grid_meta(layer)
        for tx, ty, w, h, data in tiles:
            self.hub.post(f"tile:{layer}:{tx}:{ty}", binary_frame(
                {"t": "tile", "layer": layer, "gen": cache.generation, "tx": tx, "ty": ty,
                 "w": w, "h": h, "tile": cache.tile}, data))

    def _post_grid_meta(self, layer: str) -> None:
        meta = self._grid_meta[layer]
        where = self._to_display(meta.frame_id)
        origin = None if where is None else _compose(where, *meta.origin)
        self._grid_placed[layer] = None if origin is None else (self.display_frame, origin)
        self.hub.post(f"grid:{layer}", text_frame(
            "grid", layer=layer, gen=self._tiles[layer].generation, w=meta.width, h=meta.height,
            res=meta.resolution, tile=self._tiles[layer].tile, frame=meta.frame_id,
            origin=None if origin is None else [_r(v, 5) for v in origin]))

    def _place_grids(self) -> None:
        """Re-send grid placements whose transform into the display frame moved."""
        for layer, meta in self._grid_meta.items():
            where = self._to_display(meta.frame_id)
            origin = None if where is None else _compose(where, *meta.origin)
            placed = self._grid_placed.get(layer)
            if origin is None and placed is None:
                continue
            if (placed is None or origin is None or placed[0] != self.display_frame
                    or max(abs(a - b) for a, b in zip(placed[1], origin, strict=True)) > 1e-3):
                self._post_grid_meta(layer)

    def map_bounds(self) -> tuple[float, float, float, float] | None:
        """Axis-aligned bounds of ``/map`` in the display frame (m), if placed."""
        meta = self._grid_meta.get("map")
        placed = self._grid_placed.get("map")
        if meta is None or placed is None or placed[0] != self.display_frame:
            return None
        w, h = meta.width * meta.resolution, meta.height * meta.resolution
        pts = [_compose(placed[1], x, y, 0.0) for x, y in ((0, 0), (w, 0), (0, h), (w, h))]
        xs, ys = [p[0] for p in pts], [p[1] for p in pts]
        return min(xs), min(ys), max(xs), max(ys)

    # -- sensors --------------------------------------------------------------------------
    def _on_scan(self, msg: Any) -> None:
        where = self._to_display(msg.header.frame_id)
        if where is None:
            self._problems[self.topics.scan] = f"no TF from {msg.header.frame_id!r} to {self.display_frame!r}"
            return
        self._problems.pop(self.topics.scan, None)
        ranges = np.asarray(msg.ranges, dtype=np.float32)
        self.hub.post("scan", binary_frame(
            {"t": "scan", "frame": self.display_frame, "pose": [_r(v) for v in where],
             "amin": float(msg.angle_min), "ainc": float(msg.angle_increment),
             "rmin": float(msg.range_min), "rmax": float(msg.range_max),
             "stamp": [int(msg.header.stamp.sec), int(msg.header.stamp.nanosec)]}, ranges.tobytes()), retain=True)

    def _on_range(self, topic: str, msg: Any) -> None:
        now = self._wall.now_ns()
        if now - self._last_range_ns.get(topic, 0) < _NS // 10:
            return
        self._last_range_ns[topic] = now
        where = self._to_display(msg.header.frame_id)
        if where is None:
            return
        name = topic.removeprefix("/eddie/")
        self.hub.post(f"range:{name}", text_frame(
            "range", name=name, pose=[_r(v) for v in where], fov=_r(msg.field_of_view),
            range=_r(msg.range), min=_r(msg.min_range), max=_r(msg.max_range)))

    def _on_path(self, name: str, topic: str, msg: Any) -> None:
        key = f"path:{name}"
        self._replay[key] = (functools.partial(self._on_path, name, topic), msg)
        frame = msg.header.frame_id or (msg.poses[0].header.frame_id if msg.poses else "")
        where = self._to_display(frame)
        if where is None:
            self._problems[topic] = f"no TF from {frame!r} to {self.display_frame!r}"
            self._unplaced.add(key)
            return
        self._problems.pop(topic, None)
        self._unplaced.discard(key)
        poses = msg.poses
        step = max(1, len(poses) // 400)
        pts = []
        for p in poses[::step]:
            x, y, _ = _compose(where, p.pose.position.x, p.pose.position.y, 0.0)
            pts.append([round(x, 3), round(y, 3)])
        self.hub.post(f"path:{name}", text_frame("path", name=name, pts=pts))

    def _on_goal_pose(self, msg: Any) -> None:
        where = self._to_display(msg.header.frame_id)
        if where is None:
            return
        p = msg.pose
        self._set_goal(_compose(where, p.position.x, p.position.y, _yaw(p.orientation)), "published")

    def _set_goal(self, pose: tuple[float, float, float] | None, status: str) -> None:
        if pose is not None:
            self._goal = {"x": _r(pose[0]), "y": _r(pose[1]), "yaw": _r(pose[2])}
        self.hub.post("goal", text_frame("goal", pose=self._goal, status=status))

    def _on_image(self, name: str, topic: str, msg: Any) -> None:
        now = self._wall.now_ns()
        if now - self._last_image_ns.get(name, 0) < self._image_period_ns:
            return
        self._last_image_ns[name] = now
        w, h, step = int(msg.width), int(msg.height), int(msg.step)
        try:
            if name == "depth":
                depth = depth_to_metres(msg.encoding, w, h, step, msg.data, msg.is_bigendian)
                stride = max(1, w // 320)  # shrink before colouring: a quarter of the work
                img = None if depth is None else colorize_depth(depth[::stride, ::stride])
            else:
                img = image_to_bgr(msg.encoding, w, h, step, msg.data)
            if img is None:
                self._problems[topic] = f"cannot show encoding {msg.encoding!r} ({w}x{h})"
                return
            jpeg = encode_jpeg(img)
        except (ValueError, ImportError) as exc:
            self._problems[topic] = str(exc)
            return
        self._problems.pop(topic, None)
        self.hub.post(f"image:{name}", binary_frame({"t": "image", "name": name, "w": w, "h": h}, jpeg))

    def _on_battery(self, msg: Any) -> None:
        self._status["battery"] = _r(msg.value, 3)

    def _on_odom(self, msg: Any) -> None:
        self._status["linear"] = _r(msg.twist.twist.linear.x, 3)
        self._status["angular"] = _r(msg.twist.twist.angular.z, 3)

    def _on_collisions(self, msg: Any) -> None:
        self._status["collisions"] = int(msg.data)

    def _on_log(self, msg: Any) -> None:
        self._logs.append({"level": int(msg.level), "name": str(msg.name), "msg": str(msg.msg)[:500],
                           "sec": int(msg.stamp.sec)})
        self._logs_dirty = True

    def _on_estop(self, msg: Any) -> None:
        locked = bool(msg.data)
        if locked != self._estop:
            self._estop = locked
            self.hub.post("estop", text_frame("estop", locked=locked))

    # -- navigation and SLAM layers -------------------------------------------------------
    def _throttled(self, key: str, period_ns: int) -> bool:
        """True when ``key`` was sent less than ``period_ns`` ago; else marks it sent now."""
        now = self._wall.now_ns()
        if now - self._last_layer_ns.get(key, -period_ns) < period_ns:
            return True
        self._last_layer_ns[key] = now
        return False

    def _on_particles(self, msg: Any) -> None:
        if self._throttled("particles", _NS // 5):
            return
        where = self._to_display(msg.header.frame_id)
        if where is None:
            self._problems[self.topics.particle_cloud] = (
                f"no TF from {msg.header.frame_id!r} to {self.display_frame!r}")
            return
        self._problems.pop(self.topics.particle_cloud, None)
        parts = msg.particles
        step = max(1, -(-len(parts) // MAX_PARTICLES))
        a = np.array([(p.pose.position.x, p.pose.position.y, p.pose.orientation.z,
                       p.pose.orientation.w, p.weight) for p in parts[::step]],
                     dtype=np.float64).reshape(-1, 5)
        c, s = math.cos(where[2]), math.sin(where[2])
        out = np.empty((a.shape[0], 4), np.float32)
        out[:, 0] = where[0] + c * a[:, 0] - s * a[:, 1]
        out[:, 1] = where[1] + s * a[:, 0] + c * a[:, 1]
        out[:, 2] = 2.0 * np.arctan2(a[:, 2], a[:, 3]) + where[2]
        out[:, 3] = a[:, 4]
        self.hub.post("particles", binary_frame(
            {"t": "particles", "frame": self.display_frame, "n": int(a.shape[0]),
             "total": len(parts)}, out.tobytes()))

    def _on_lookahead(self, msg: Any) -> None:
        self._replay["lookahead"] = (self._on_lookahead, msg)
        if self._throttled("lookahead", _NS // 10):
            return
        where = self._to_display(msg.header.frame_id)
        if where is None:
            self._unplaced.add("lookahead")
            return
        self._unplaced.discard("lookahead")
        x, y, _ = _compose(where, msg.point.x, msg.point.y, 0.0)
        self.hub.post("lookahead", text_frame("lookahead", x=_r(x), y=_r(y)))

    def _on_footprint(self, msg: Any) -> None:
        if self._throttled("footprint", _NS // 5):
            return
        where = self._to_display(msg.header.frame_id)
        if where is None:
            return
        pts = [[_r(v, 3) for v in _compose(where, p.x, p.y, 0.0)[:2]] for p in msg.polygon.points]
        self.hub.post("footprint", text_frame("footprint", pts=pts))

    def _on_description(self, msg: Any) -> None:
        try:
            radius = footprint_from_urdf(str(msg.data))
        except ValueError as exc:
            self._problems[self.topics.robot_description] = str(exc)
            return
        self._problems.pop(self.topics.robot_description, None)
        if radius is None:
            self._problems[self.topics.robot_description] = "no base_link cylinder: footprint kept"
            return
        self.footprint_radius = radius
        self.footprint_source = f"URDF {self.topics.robot_description}"
        self._post_robot()

    def _post_robot(self) -> None:
        self.hub.post("robot", text_frame("robot", radius=_r(self.footprint_radius),
                                          source=self.footprint_source))

    def _on_graph(self, msg: Any) -> None:
        self._keep("graph", msg)  # sent from the status tick, at most once a second

    def _graph_frame(self, msg: Any) -> str:
        layers, nodes, loops = [], 0, 0
        for m in msg.markers:
            kind = "points" if m.type in _POINT_MARKERS else "lines" if m.type in _LINE_MARKERS else None
            if kind is None or m.action != 0:
                continue
            where = self._to_display(m.header.frame_id)
            if where is None:
                self._problems[self.topics.vslam_graph] = (
                    f"no TF from {m.header.frame_id!r} to {self.display_frame!r}")
                continue
            base = _compose(where, m.pose.position.x, m.pose.position.y, _yaw(m.pose.orientation))
            xy = np.array([(p.x, p.y) for p in m.points], np.float64).reshape(-1, 2)
            if m.type == 4 and len(xy) >= 2:  # a strip as the segments of a list
                xy = np.repeat(xy, 2, axis=0)[1:-1]
            if kind == "lines":
                xy = xy[: len(xy) // 2 * 2]
                step = max(1, -(-(len(xy) // 2) // (_MAX_MARKER_POINTS // 2)))
                xy = xy.reshape(-1, 2, 2)[::step].reshape(-1, 2)
            else:
                xy = xy[:: max(1, -(-len(xy) // _MAX_MARKER_POINTS))]
            c, s = math.cos(base[2]), math.sin(base[2])
            gx = base[0] + c * xy[:, 0] - s * xy[:, 1]
            gy = base[1] + s * xy[:, 0] + c * xy[:, 1]
            flat = np.round(np.stack([gx, gy], 1).reshape(-1), 3)
            colour = "#{:02x}{:02x}{:02x}".format(*(round(255 * min(1.0, max(0.0, v)))
                                                   for v in (m.color.r, m.color.g, m.color.b)))
            loop = "loop" in m.ns
            if kind == "points":
                nodes += len(m.points)
            elif loop:
                loops += len(m.points) // 2
            layers.append({"ns": m.ns, "kind": kind, "colour": colour, "loop": loop,
                           "pts": flat.tolist()})
        return text_frame("graph", layers=layers, nodes=nodes, loops=loops)

    def _on_cloud(self, name: str, msg: Any) -> None:
        self._keep(name, msg)  # converted only while a page has the 3D view open

    def _keep(self, name: str, msg: Any) -> None:
        seq = self._clouds[name][0] + 1 if name in self._clouds else 1
        self._clouds[name] = (seq, msg)

    def _cloud_frame(self, name: str, msg: Any) -> bytes | None:
        topic = self.topics.cloud_map if name == "cloud_map" else self.topics.points
        fields = {f.name: f for f in msg.fields}
        if any(k not in fields or int(fields[k].datatype) != 7 for k in "xyz"):  # FLOAT32
            self._problems[topic] = "point cloud without float32 x, y, z fields"
            return None
        n, step = int(msg.width) * int(msg.height), int(msg.point_step)
        buf = np.asarray(msg.data, dtype=np.uint8)
        if n and (buf.size < n * step or step < 12):
            self._problems[topic] = f"point cloud of {buf.size} bytes, expected {n * step}"
            return None
        frame = msg.header.frame_id.lstrip("/") or self.display_frame
        try:
            tr = self.tf.lookup_transform(self.display_frame, frame).transform
        except TransformException:
            self._problems[topic] = f"no TF from {frame!r} to {self.display_frame!r}"
            return None
        self._problems.pop(topic, None)
        limit = MAX_CLOUD_POINTS if name == "cloud_map" else MAX_LIVE_POINTS
        rows = buf[: n * step].reshape(n, step)[:: max(1, -(-n // limit))]
        order = ">" if msg.is_bigendian else "<"

        def column(off: int, kind: str) -> np.ndarray:
            return np.ascontiguousarray(rows[:, off: off + 4]).view(f"{order}{kind}4")[:, 0]

        xyz = np.stack([column(int(fields[k].offset), "f") for k in "xyz"], 1).astype(np.float64)
        keep = np.isfinite(xyz).all(1)
        xyz = xyz[keep]
        r = tr.rotation
        xyz = xyz @ _quat_matrix(r.x, r.y, r.z, r.w).T + (tr.translation.x, tr.translation.y,
                                                          tr.translation.z)
        colour = fields.get("rgb") or fields.get("rgba")
        rgb = b""
        if colour is not None:
            packed = column(int(colour.offset), "u")[keep] if len(rows) else np.zeros(0, np.uint32)
            rgb = np.stack([(packed >> 16) & 255, (packed >> 8) & 255, packed & 255],
                           1).astype(np.uint8).tobytes()
        return binary_frame({"t": "cloud", "name": name, "frame": self.display_frame,
                             "n": int(xyz.shape[0]), "total": n, "rgb": bool(rgb)},
                            xyz.astype(np.float32).tobytes() + rgb)

    def _tf_frame(self) -> str:
        frames = []
        for f in self.tf.all_frames():
            pose = self._to_display(f)
            if pose is not None:
                frames.append([f, _r(pose[0]), _r(pose[1]), _r(pose[2])])
        return text_frame("tf", frame=self.display_frame, frames=frames)

    def _send_views(self, now: int) -> None:
        graph = self._clouds.get("graph")
        if graph is not None and self._cloud_sent.get("graph") != graph[0] \
                and not self._throttled("graph", _NS):
            self._cloud_sent["graph"] = graph[0]
            self.hub.post("graph", self._graph_frame(graph[1]))
        if self.hub.view_open("tf"):
            self.hub.post("tf", self._tf_frame(), view="tf")
        if self.hub.view_open("cloud"):
            for name in ("cloud_map", "points"):
                kept = self._clouds.get(name)
                if kept is None or self._cloud_sent.get(name) == kept[0] \
                        or self._throttled(f"cloud:{name}", _NS // 2):
                    continue
                self._cloud_sent[name] = kept[0]
                frame = self._cloud_frame(name, kept[1])
                if frame is not None:
                    self.hub.post(f"cloud:{name}", frame, view="cloud")

    def view_changed(self, name: str, open_count: int) -> None:
        """A page opened or closed a view (server thread); a reopened cloud view is resent."""
        if name == "cloud" and open_count:
            self._cloud_sent.pop("cloud_map", None)
            self._cloud_sent.pop("points", None)

    # -- the velocity mux ---------------------------------------------------------------
    @staticmethod
    def _mux_inputs(params: dict[str, Any] | None) -> tuple[list[MuxInput], list[MuxInput]]:
        """twist_mux's sources and locks from its parameters (its defaults when None)."""
        out: list[list[MuxInput]] = []
        for group, defaults in (("topics", DEFAULT_TOPICS), ("locks", DEFAULT_LOCKS)):
            if params is None:
                table = {n: (t, to, pr) for n, (t, to, pr) in defaults.items()}
            else:
                names = sorted({k.split(".")[1] for k in params
                                if k.startswith(f"{group}.") and k.count(".") == 2})
                table = {n: (str(params.get(f"{group}.{n}.topic") or ""),
                             float(params.get(f"{group}.{n}.timeout") or 0.0),
                             int(params.get(f"{group}.{n}.priority") or 0)) for n in names}
            out.append([MuxInput(n, t, round(to * 1e9), pr) for n, (t, to, pr) in table.items() if t])
        return out[0], out[1]

    def _mux_topic(self, topic: str) -> str:
        if topic.startswith("/"):
            return topic
        ns = self.topics.twist_mux.rsplit("/", 1)[0]
        return f"{ns}/{topic}"

    def _subscribe_mux(self) -> None:
        for sub in self._mux_subs.values():
            self.destroy_subscription(sub)
        self._mux_subs.clear()
        for src in [*self._mux.sources, *self._mux.locks]:
            is_lock = src in self._mux.locks
            cls = self._bool_cls if is_lock else self._twist_cls

            def cb(m: Any, src: MuxInput = src, is_lock: bool = is_lock) -> None:
                src.last_ns = self._wall.now_ns()
                src.value = bool(m.data) if is_lock else m

            topic = self._mux_topic(src.topic)
            try:
                self._mux_subs[f"{src.name}:{topic}"] = self.create_subscription(cls, topic, cb, 10)
            except TopicTypeMismatchError as exc:
                self._problems[topic] = str(exc)

    def _poll_mux_params(self) -> None:
        """Read the running twist_mux's table once (it is read-only there)."""
        client = self._mux_params
        if client is None or self._mux_query is not None or not client.services_are_ready():
            return
        def got_values(names: list[str], f: Future) -> None:
            if f.exception() is not None:
                self._mux_query = None
                return
            params = {n: value_from_msg(v) for n, v in zip(names, f.result().values, strict=False)}
            sources, locks = self._mux_inputs(params)
            if sources:
                self._mux = TwistMux(sources, locks)
                self._mux_source = f"{self.topics.twist_mux} parameters"
                self._subscribe_mux()
            self._mux_params = None

        def got_names(f: Future) -> None:
            if f.exception() is not None or client is None:
                self._mux_query = None
                return
            names = [n for n in f.result().result.names if n.count(".") == 2]
            self._mux_query = client.get_parameters_async(names)
            self._mux_query.add_done_callback(functools.partial(got_values, names))

        self._mux_query = client.list_parameters_async(["topics", "locks"])
        self._mux_query.add_done_callback(got_names)

    def mux_state(self, now_ns: int) -> dict[str, Any]:
        """Which source drives ``cmd_vel`` now (twist_mux's rule), and which locks hold."""
        chosen = self._mux.select(now_ns)
        locks = [lk.name for lk in self._mux.locks
                 if bool(lk.value) or (lk.timeout_ns > 0 and (
                     lk.last_ns is None or now_ns - lk.last_ns > lk.timeout_ns))]
        return {"active": None if chosen is None else chosen.name,
                "topic": None if chosen is None else self._mux_topic(chosen.topic),
                "locks": locks, "table": self._mux_source}

    # -- periodic -------------------------------------------------------------------------
    def _status_tick(self) -> None:
        now = self._wall.now_ns()
        self._choose_display_frame()
        self._place_grids()
        watched = [self.topics.scan, self.topics.odom, "/tf", "/map", self.topics.image,
                   self.topics.depth, self.topics.plan, self.topics.local_plan, *RANGE_TOPICS,
                   self.topics.battery, self.topics.collisions, *list(GRID_LAYERS.values())[1:],
                   "/tf_static", self.topics.rosout, self.topics.particle_cloud,
                   self.topics.vslam_graph]
        rates, age = {}, {}
        for topic in watched:
            r = self._rates.get(topic)
            rates[topic] = 0.0 if r is None else round(r.hz(now), 1)
            age[topic] = None if r is None or r.last_ns is None else round((now - r.last_ns) / _NS, 1)
        self._replay_unplaced()
        self._poll_mux_params()
        self._send_views(now)
        self.hub.post("status", text_frame(
            "status", frame=self.display_frame, rates=rates, age=age, problems=dict(self._problems),
            nav_server=self._nav.server_is_ready(), estop=self._estop, mux=self.mux_state(now),
            **self._status))
        if self._logs_dirty:
            self._logs_dirty = False
            self.hub.post("log", text_frame("log", lines=list(self._logs)[-60:]))

    def _teleop_tick(self) -> None:
        with self._cmd_lock:
            cmd = self._teleop
            if cmd is None:
                return
            if self._wall.now_ns() - self._teleop_refresh_ns > self.teleop_timeout_s * _NS:
                self._teleop = None
                cmd = (0.0, 0.0)
        self._publish_twist(*cmd)

    # -- commands (called from the web server's thread) ---------------------------------------
    def _publish_twist(self, linear: float, angular: float) -> None:
        twist = self._twist_cls()
        twist.linear.x = float(linear)
        twist.angular.z = float(angular)
        self._cmd_pub.publish(twist)

    def teleop(self, linear: float, angular: float) -> None:
        """Hold (linear, angular) until refreshed or released; zero releases at once."""
        if self._estop and (linear or angular):
            raise CommandError("teleop refused: the emergency stop is engaged")
        with self._cmd_lock:
            if linear == 0.0 and angular == 0.0:
                self._teleop = None
            else:
                start = self._teleop is None
                self._teleop = (linear, angular)
                self._teleop_refresh_ns = self._wall.now_ns()
                if not start:
                    return
        self._publish_twist(linear, angular)

    def _stamp(self, msg: Any) -> None:
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.header.frame_id = self.display_frame

    def _pose_msg(self, x: float, y: float, yaw: float) -> Any:
        ps = self._pose_stamped_cls()
        self._stamp(ps)
        ps.pose.position.x, ps.pose.position.y = float(x), float(y)
        ps.pose.orientation.z, ps.pose.orientation.w = math.sin(yaw / 2), math.cos(yaw / 2)
        return ps

    def send_goal(self, x: float, y: float, yaw: float) -> str:
        """NavigateToPose when a server exists, else ``/goal_pose``; says which."""
        if self._estop:
            raise CommandError("goal refused: the emergency stop is engaged")
        pose = self._pose_msg(x, y, yaw)
        self._goal = {"x": _r(x), "y": _r(y), "yaw": _r(yaw)}
        if self._nav.server_is_ready():
            goal = self._nav.action_type.Goal(pose=pose)
            future = self._nav.send_goal_async(goal)
            future.add_done_callback(self._on_goal_response)
            self._set_goal(None, "sent")
            return "navigate_to_pose"
        self._goal_pub.publish(pose)
        return self.topics.goal_pose

    def _on_goal_response(self, future: Future) -> None:
        if future.exception() is not None:
            self._set_goal(None, f"failed: {future.exception()}")
            return
        handle = future.result()
        if not handle.accepted:
            self._set_goal(None, "rejected")
            return
        self._nav_handles.append(handle)
        self._set_goal(None, "active")
        names = {4: "succeeded", 5: "canceled", 6: "aborted"}

        def done(f: Future) -> None:
            if handle in self._nav_handles:
                self._nav_handles.remove(handle)
            status = "failed" if f.exception() is not None else names.get(int(f.result().status), "ended")
            self._set_goal(None, status)

        handle.get_result_async().add_done_callback(done)

    def set_initial_pose(self, x: float, y: float, yaw: float) -> None:
        """``/initialpose`` with RViz's default covariance (0.25 m², 0.0685 rad²)."""
        msg = self._pose_cov_cls()
        self._stamp(msg)
        p = msg.pose.pose
        p.position.x, p.position.y = float(x), float(y)
        p.orientation.z, p.orientation.w = math.sin(yaw / 2), math.cos(yaw / 2)
        cov = np.zeros(36)
        cov[0], cov[7], cov[35] = 0.25, 0.25, 0.06853891909122467
        msg.pose.covariance = cov
        self._initial_pub.publish(msg)

    def cancel_navigation(self) -> bool:
        """Cancel every navigation goal; False when no server is there."""
        if not self._nav.server_is_ready():
            return False
        self._nav.cancel_all_goals_async()
        self._set_goal(None, "canceling")
        return True

    def estop(self, engage: bool | None = None) -> bool:
        """Engage (zero velocity, lock, cancel goals) or release the lock; returns the state."""
        engage = (not self._estop) if engage is None else engage
        if engage:
            with self._cmd_lock:
                self._teleop = None
            self._publish_twist(0.0, 0.0)
            self._estop_pub.publish(self._bool_cls(data=True))
            self.cancel_navigation()
        else:
            self._estop_pub.publish(self._bool_cls(data=False))
        self._estop = engage
        self.hub.post("estop", text_frame("estop", locked=engage))
        return engage

    def save_map(self, name: str, done: Callable[[bool, str], None]) -> None:
        """Ask map_saver (else slam_toolbox) to save; ``done(ok, text)`` runs when it answers."""
        if self._map_saver.service_is_ready():
            req = self._map_saver.srv_type.Request(map_topic="map", map_url=name or "map")
            fut = self._map_saver.call_async(req)
            what = self.topics.map_saver
        elif self._slam_saver.service_is_ready():
            req = self._slam_saver.srv_type.Request()
            req.name.data = name or "map"
            fut = self._slam_saver.call_async(req)
            what = self.topics.slam_saver
        else:
            done(False, f"no map saver: neither {self.topics.map_saver} nor {self.topics.slam_saver} exists")
            return

        def answered(f: Future) -> None:
            if f.exception() is not None:
                done(False, f"{what}: {f.exception()}")
                return
            res = f.result()
            ok = bool(res.result) if isinstance(res.result, (bool, np.bool_)) else int(res.result) == 0
            done(ok, f"{what}: {'saved' if ok else 'failed'} ({name or 'map'})")

        fut.add_done_callback(answered)

    # -- keepout zones ----------------------------------------------------------------------
    def _on_keepout_mask(self, msg: Any) -> None:
        with self._cmd_lock:
            self._keepout = map_from_msg(msg)

    def _keepout_base(self) -> OccupancyMap | None:
        """The mask to paint on: the current keepout mask, else an empty one shaped as /map."""
        if self._keepout is not None:
            return self._keepout
        meta = self._grid_meta.get("map")
        if meta is None:
            return None
        return OccupancyMap(np.zeros((meta.height, meta.width), np.int8), meta.resolution,
                            meta.origin, meta.frame_id)

    def paint_keepout(self, rect: tuple[float, float, float, float] | None,
                      done: Callable[[bool, str], None]) -> None:
        """Mark the cells of ``rect`` (x0, y0, x1, y1 in the display frame, m) occupied in the
        keepout mask, or clear the mask (``rect`` None), and hand the mask to the keepout
        mask server's ``load_map``; ``done(ok, text)`` runs when it answers."""
        server = self.topics.keepout_mask_server
        if not self._mask_loader.service_is_ready():
            done(False, f"no keepout mask server: {server} does not answer (eddie nav "
                        "--dashboard starts one)")
            return
        with self._cmd_lock:
            base = self._keepout_base()
        if base is None:
            done(False, "keepout: no map yet to shape the mask on")
            return
        data = np.zeros_like(base.data) if rect is None else base.data.copy()
        cells = 0
        if rect is not None:
            where = self._to_display(base.frame_id)
            if where is None:
                done(False, f"keepout: the mask frame {base.frame_id} is not placed in the "
                            f"display frame {self.display_frame} yet")
                return
            jj, ii = np.mgrid[0:base.height, 0:base.width]
            centres = map_to_world(base, np.stack([ii, jj], axis=-1))
            c, s = math.cos(where[2]), math.sin(where[2])
            dx = where[0] + c * centres[..., 0] - s * centres[..., 1]
            dy = where[1] + s * centres[..., 0] + c * centres[..., 1]
            x0, y0, x1, y1 = rect
            inside = ((dx >= min(x0, x1)) & (dx <= max(x0, x1))
                      & (dy >= min(y0, y1)) & (dy <= max(y0, y1)))
            cells = int(inside.sum())
            if cells == 0:
                done(False, "keepout: the rectangle covers no cell of the mask")
                return
            data[inside] = 100
        if self._keepout_dir is None:
            self._keepout_dir = Path(tempfile.mkdtemp(prefix="eddie_keepout_"))
        self._keepout_count += 1
        try:
            path = save_map(OccupancyMap(data, base.resolution, base.origin, base.frame_id),
                            self._keepout_dir / f"keepout_{self._keepout_count}")
        except OSError as exc:
            done(False, f"keepout: cannot write the mask: {exc}")
            return
        fut = self._mask_loader.call_async(self._mask_loader.srv_type.Request(map_url=str(path)))
        what = f"{cells} cells kept out" if rect is not None else "keepout zones cleared"

        def answered(f: Future) -> None:
            if f.exception() is not None:
                done(False, f"{server}: {f.exception()}")
                return
            code = int(f.result().result)
            done(code == 0, f"{server}: {what} ({path.name})" if code == 0
                 else f"{server}: load_map failed with result {code} ({path})")

        fut.add_done_callback(answered)

    @property
    def estop_engaged(self) -> bool:
        return self._estop
