"""The dashboard's node: subscribes to what the page shows, publishes what the page commands.

Callbacks run on the dashboard's own executor thread and hand ready-made frames to the
:class:`~eddiebot.viz.dashboard.hub.Hub`; commands arrive from the web server's thread and
publish directly. The layers are converted by groups, each a module:
:mod:`~eddiebot.viz.dashboard.display` (the display frame and what they share),
:mod:`~eddiebot.viz.dashboard.grids` (map, costmaps, keepout mask),
:mod:`~eddiebot.viz.dashboard.robot` (pose, footprint, sensors),
:mod:`~eddiebot.viz.dashboard.plans` (plans, goal, particles, lookahead),
:mod:`~eddiebot.viz.dashboard.views` (vSLAM graph, TF view, point clouds),
:mod:`~eddiebot.viz.dashboard.slam_edit` (2D SLAM graph and its editing),
:mod:`~eddiebot.viz.dashboard.explore` (exploration: start, pause, progress) and
:mod:`~eddiebot.viz.dashboard.status` (status, log, velocity mux source). This module wires
them: subscriptions, publishers, timers and the page's commands.
"""

from __future__ import annotations

import functools
import math
import threading
from collections import deque
from collections.abc import Callable
from typing import Any

import numpy as np

from eddiebot.base.twist_mux import TwistMux
from eddiebot.core.action import ActionClient
from eddiebot.core.clock_node import ROSOUT_QOS
from eddiebot.core.context import Context
from eddiebot.core.errors import TopicTypeMismatchError
from eddiebot.core.param_services import ParameterClient
from eddiebot.core.qos import QoSProfile, qos_profile_latched, qos_profile_sensor_data
from eddiebot.core.task import Future
from eddiebot.core.tf import Buffer
from eddiebot.msgs import get_action, get_message, get_service
from eddiebot.viz.dashboard.core import TileCache, text_frame
from eddiebot.viz.dashboard.display import _NS, GRID_LAYERS, _r
from eddiebot.viz.dashboard.errors import CommandError
from eddiebot.viz.dashboard.explore import ExploreLayers
from eddiebot.viz.dashboard.grids import GridLayers
from eddiebot.viz.dashboard.hub import Hub
from eddiebot.viz.dashboard.plans import MAX_PARTICLES, PlanLayers
from eddiebot.viz.dashboard.robot import (
    FOOTPRINT_RADIUS,
    RANGE_TOPICS,
    RobotLayers,
    footprint_from_urdf,
)
from eddiebot.viz.dashboard.slam_edit import SlamEditLayers
from eddiebot.viz.dashboard.status import StatusLayers
from eddiebot.viz.dashboard.topics import DashboardTopics
from eddiebot.viz.dashboard.views import MAX_CLOUD_POINTS, MAX_LIVE_POINTS, ViewLayers

__all__ = ["FOOTPRINT_RADIUS", "GRID_LAYERS", "MAX_CLOUD_POINTS", "MAX_LIVE_POINTS", "MAX_PARTICLES",
           "RANGE_TOPICS",
           "DashboardNode", "DashboardTopics", "footprint_from_urdf"]


class DashboardNode(GridLayers, RobotLayers, PlanLayers, ViewLayers, StatusLayers, SlamEditLayers,
                    ExploreLayers):
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
        self._rates = {}
        self._problems = {}
        self._tiles = {layer: TileCache() for layer in GRID_LAYERS}
        self._grid_meta = {}
        self._grid_placed = {}
        self._image_period_ns = round(_NS / image_rate_hz)
        self._pose_period_ns = round(_NS / pose_rate_hz)
        self._last_image_ns = {}
        self._last_pose_ns = 0
        self._last_range_ns = {}
        self._status = {"battery": None, "linear": None, "angular": None, "collisions": None}
        self._logs = deque(maxlen=200)
        self.footprint_radius = FOOTPRINT_RADIUS
        self.footprint_source = "URDF (built in)"
        self._last_layer_ns = {}
        self._replay = {}
        self._unplaced = set()
        self._clouds = {}
        self._cloud_sent = {}
        self._mux = TwistMux(*self._mux_inputs(None))
        self._mux_source = "twist_mux defaults"
        self._mux_subs = {}
        self._mux_params = None
        self._mux_query = None
        self._logs_dirty = False
        self._goal = None
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
        self._keepout = None
        self._keepout_dir = None
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
        self._setup_slam_edit()
        self._setup_explore()
        self._subscribe_mux()
        try:
            self._mux_params = ParameterClient(self, t.twist_mux)
        except TopicTypeMismatchError as exc:
            self._problems[t.twist_mux] = str(exc)
        self.create_timer(0.2, self._status_tick, clock=self._wall)
        self.create_timer(0.1, self._teleop_tick, clock=self._wall)
        self.hub.post("estop", text_frame("estop", locked=False))
        self._post_robot()

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
        self._send_slam_graph()
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

    @property
    def estop_engaged(self) -> bool:
        return self._estop
