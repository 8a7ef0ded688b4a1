"""nav2_amcl as a lifecycle node: particle-filter localisation on a known map.

Parameters are Nav2's (``alpha1..5``, ``laser_*``, ``max_particles``, ``update_min_d``,
``transform_tolerance``, ``set_initial_pose`` with ``initial_pose.{x,y,z,yaw}`` …, see
:class:`eddiebot.nav.amcl.AmclConfig`). Subscribes ``map`` (transient local), ``scan`` and
``initialpose``; publishes ``amcl_pose`` (transient local), ``particle_cloud`` and, with
``tf_broadcast``, TF ``map → odom`` future-dated by ``transform_tolerance`` as Nav2 does.
Odometry comes from TF (``odom_frame_id → base_frame_id`` at the scan's stamp): as Nav2's
``tf2_ros::MessageFilter`` (queue of 10), a scan waits until that transform exists, and is
dropped once it is ``transform_tolerance`` older than the clock without one.
"""

from __future__ import annotations

import math
from collections import deque
from typing import Any

import numpy as np

from eddiebot.core.lifecycle import State, TransitionCallbackReturn
from eddiebot.core.qos import DurabilityPolicy, QoSProfile, qos_profile_sensor_data
from eddiebot.core.tf import (
    Buffer,
    ExtrapolationException,
    TransformBroadcaster,
    TransformException,
    TransformListener,
    make_transform_2d,
)
from eddiebot.core.time import stamp_to_ns
from eddiebot.maps import map_from_msg
from eddiebot.nav.amcl import Amcl, AmclConfig, LocalizationLimits, localization_problem
from eddiebot.nav.errors import LocalizationError
from eddiebot.nav.nodes._common import NavServer, pose_from_msg
from eddiebot.nav.params import from_params

__all__ = ["AmclNode", "LocalizationWatch"]

_LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
#: scans waiting for their odometry transform (Nav2's laser_scan_filter_ queue size)
_SCAN_QUEUE = 10
#: how often queued scans are retried (s)
_RETRY_PERIOD = 0.01


def _se2_compose(a: Any, b: Any) -> np.ndarray:
    c, s = math.cos(a[2]), math.sin(a[2])
    return np.array([a[0] + c * b[0] - s * b[1], a[1] + s * b[0] + c * b[1], a[2] + b[2]])


def _se2_inverse(a: Any) -> np.ndarray:
    c, s = math.cos(a[2]), math.sin(a[2])
    return np.array([-c * a[0] - s * a[1], s * a[0] - c * a[1], -a[2]])


class LocalizationWatch:
    """Tells a node that commands motion when it must stop because localization is lost:
    ``map → odom`` missing or older than ``limits.tf_timeout``, or the last pose published on
    ``pose_topic`` (``amcl_pose``) with a standard deviation beyond the limits (see
    :func:`eddiebot.nav.amcl.localization_problem`). :meth:`problem` returns the reason, or ""
    when driving is allowed. A controller uses it as::

        self._loc = LocalizationWatch(self, self.tf_buffer)          # on_activate
        if (why := self._loc.problem(now)): abort(why)               # every cycle
    """

    def __init__(self, node: Any, buffer: Buffer, limits: LocalizationLimits | None = None, *,
                 global_frame: str = "map", odom_frame: str = "odom",
                 pose_topic: str = "amcl_pose") -> None:
        from eddiebot.msgs.geometry_msgs import PoseWithCovarianceStamped

        self.node = node
        self.buffer = buffer
        self.limits = limits or LocalizationLimits()
        self.global_frame, self.odom_frame = global_frame, odom_frame
        self.covariance: np.ndarray | None = None
        self._sub = node.create_subscription(PoseWithCovarianceStamped, pose_topic,
                                             self._on_pose, _LATCHED)

    def _on_pose(self, msg: Any) -> None:
        self.covariance = np.asarray(msg.pose.covariance, dtype=np.float64).copy()

    def problem(self, now_ns: int) -> str:
        try:
            stamp: int | None = self.buffer.get_latest_common_time(
                self.global_frame, self.odom_frame).nanoseconds
        except TransformException:
            stamp = None
        return localization_problem(self.limits, now_ns, self.covariance, stamp)

    def destroy(self) -> None:
        if self._sub is not None:
            self.node.destroy_subscription(self._sub)
            self._sub = None

    @classmethod
    def from_parameters(cls, node: Any, buffer: Buffer, odom_frame: str) -> LocalizationWatch:
        """From a server's ``localization_*`` and ``global_frame_id`` parameters (the collision
        monitor's and the controller server's)."""
        limits = LocalizationLimits(float(node.param("localization_max_xy_std")),
                                    float(node.param("localization_max_yaw_std")),
                                    float(node.param("localization_tf_timeout")))
        return cls(node, buffer, limits, global_frame=str(node.param("global_frame_id")),
                   odom_frame=odom_frame, pose_topic=str(node.param("localization_pose_topic")))


class AmclNode(NavServer):
    default_node_name = "amcl"
    PARAMETERS = {k: v for k, v in AmclConfig().__dict__.items() if not k.startswith("initial_pose_")}
    PARAMETERS.update({"initial_pose.x": 0.0, "initial_pose.y": 0.0, "initial_pose.z": 0.0,
                       "initial_pose.yaw": 0.0,
                       # nav2_amcl samples with drand48, which it never seeds, so every run
                       # repeats the same draws: 0 does the same here (-1 draws from entropy)
                       "random_seed": 0})

    def __init__(self, node_name: str = "amcl", **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        self.amcl: Amcl | None = None
        self.tf_buffer = Buffer(node=self)
        self._listener: TransformListener | None = None
        self._tf: TransformBroadcaster | None = None
        self._subs: list[Any] = []
        self._pose_pub: Any = None
        self._cloud_pub: Any = None
        self._map_to_odom: np.ndarray | None = None
        self._initialised = False
        self._have_map = False
        self._pending: deque[Any] = deque(maxlen=_SCAN_QUEUE)
        self._retry_timer: Any = None

    def on_configure(self, state: State) -> TransitionCallbackReturn:
        def build() -> None:
            from eddiebot.msgs.geometry_msgs import PoseWithCovarianceStamped
            from eddiebot.msgs.nav2_msgs import ParticleCloud

            tree = self.params_tree()
            init = tree.pop("initial_pose", {}) or {}
            seed = int(tree.pop("random_seed"))
            for k in ("x", "y", "z", "yaw"):
                tree[f"initial_pose_{k}"] = init.get(k, 0.0)
            cfg = from_params(AmclConfig, tree, server=self.get_name())
            self.amcl = Amcl(cfg, seed=None if seed < 0 else seed)
            self._initialised = cfg.set_initial_pose
            self._pose_pub = self.create_lifecycle_publisher(PoseWithCovarianceStamped, "amcl_pose", _LATCHED)
            self._cloud_pub = self.create_lifecycle_publisher(ParticleCloud, "particle_cloud", 1)
        return self.configure_with(build)

    def on_activate(self, state: State) -> TransitionCallbackReturn:
        from eddiebot.msgs.geometry_msgs import PoseWithCovarianceStamped
        from eddiebot.msgs.nav_msgs import OccupancyGrid
        from eddiebot.msgs.sensor_msgs import LaserScan

        assert self.amcl is not None
        cfg = self.amcl.config
        self._listener = TransformListener(self.tf_buffer, self)
        self._tf = TransformBroadcaster(self)
        self._subs = [
            self.create_subscription(OccupancyGrid, cfg.map_topic, self._on_map, _LATCHED),
            self.create_subscription(LaserScan, cfg.scan_topic, self._on_scan, qos_profile_sensor_data),
            self.create_subscription(PoseWithCovarianceStamped, "initialpose", self._on_initial_pose, 1),
        ]
        self._retry_timer = self.create_timer(_RETRY_PERIOD, self._drain)
        return TransitionCallbackReturn.SUCCESS

    def on_deactivate(self, state: State) -> TransitionCallbackReturn:
        for s in self._subs:
            self.destroy_subscription(s)
        self._subs = []
        if self._retry_timer is not None:
            self.destroy_timer(self._retry_timer)
            self._retry_timer = None
        self._pending.clear()
        if self._listener is not None:
            self._listener.unregister()
            self._listener = None
        return TransitionCallbackReturn.SUCCESS

    def on_cleanup(self, state: State) -> TransitionCallbackReturn:
        for p in (self._pose_pub, self._cloud_pub):
            if p is not None:
                self.destroy_lifecycle_publisher(p)
        self._pose_pub = self._cloud_pub = None
        self.amcl = None
        self._have_map = False
        return TransitionCallbackReturn.SUCCESS

    # -- inputs -------------------------------------------------------------------------------
    def _on_map(self, msg: Any) -> None:
        assert self.amcl is not None
        if self._have_map and self.amcl.config.first_map_only:
            return
        self.amcl.set_map(map_from_msg(msg))
        self._have_map = True
        cfg = self.amcl.config
        if cfg.set_initial_pose and (cfg.always_reset_initial_pose or not self._initialised
                                     or self.amcl.particles.shape[0] == 0):
            # Nav2: a PoseWithCovarianceStamped with a zero covariance (no spread)
            self.amcl.initialize((cfg.initial_pose_x, cfg.initial_pose_y, cfg.initial_pose_yaw),
                                 np.zeros((3, 3)))
            self._initialised = True

    def _on_initial_pose(self, msg: Any) -> None:
        assert self.amcl is not None
        if msg.header.frame_id and msg.header.frame_id != self.amcl.config.global_frame_id:
            self.get_logger().warning(
                f"initial pose in frame {msg.header.frame_id!r}, expected "
                f"{self.amcl.config.global_frame_id!r}; ignored")
            return
        pose = pose_from_msg(msg.pose.pose)
        c = np.asarray(msg.pose.covariance, dtype=np.float64).reshape(6, 6)
        # used as given (handleInitialPose): all zero puts every particle on the pose
        cov = np.array([[c[0, 0], c[0, 1], 0.0], [c[1, 0], c[1, 1], 0.0], [0.0, 0.0, c[5, 5]]])
        self.amcl.initialize(pose, cov)
        self._initialised = True
        self.get_logger().info(f"initial pose set to ({pose[0]:.2f}, {pose[1]:.2f}, {pose[2]:.2f})")

    def _on_scan(self, msg: Any) -> None:
        assert self.amcl is not None
        if not self._have_map or not self._initialised:
            self.get_logger().warning("waiting for a map and an initial pose", once=True)
            return
        self._pending.append(msg)
        self._drain()

    def _drain(self) -> None:
        """Process the queued scans, oldest first, while odometry at their stamps exists."""
        while self._pending:
            odom = self._odom_at(self._pending[0])
            if odom is None:
                return
            msg = self._pending.popleft()
            if odom.size:
                self._process_scan(msg, odom)

    def _odom_at(self, msg: Any) -> np.ndarray | None:
        """``odom → base`` at the scan's stamp; None to wait for it, empty to drop the scan."""
        assert self.amcl is not None
        cfg = self.amcl.config
        stamp = stamp_to_ns(msg.header.stamp)
        try:
            return np.array(self.tf_buffer.lookup_pose2d(cfg.odom_frame_id, cfg.base_frame_id, stamp))
        except ExtrapolationException as exc:
            try:
                latest = self.tf_buffer.get_latest_common_time(cfg.odom_frame_id,
                                                               cfg.base_frame_id).nanoseconds
            except TransformException:
                latest = -1
            waited = self.now().nanoseconds - stamp
            if stamp > latest and waited <= round(cfg.transform_tolerance * 1e9):
                return None
            self.get_logger().warning(f"scan dropped, no odometry at its stamp: {exc}", once=True)
        except TransformException as exc:
            self.get_logger().warning(f"no odometry transform: {exc}", once=True)
        return np.zeros(0)

    def _process_scan(self, msg: Any, odom: np.ndarray) -> None:
        assert self.amcl is not None
        cfg = self.amcl.config
        stamp = stamp_to_ns(msg.header.stamp)
        try:
            laser = self.tf_buffer.lookup_pose2d(cfg.base_frame_id, msg.header.frame_id, 0)
        except TransformException as exc:
            self.get_logger().warning(f"no transform to the laser frame: {exc}", once=True)
            return
        try:
            updated = self.amcl.update(odom, msg.ranges, msg.angle_min, msg.angle_increment,
                                       msg.range_min, msg.range_max, laser)
        except LocalizationError as exc:
            self.get_logger().warning(str(exc), once=True)
            return
        est, cov = self.amcl.estimate
        if updated or self._map_to_odom is None:
            self._map_to_odom = _se2_compose(est, _se2_inverse(odom))
            self._publish_pose(est, cov, msg.header.stamp)
            self._publish_cloud(msg.header.stamp)
        if cfg.tf_broadcast and self._tf is not None and self._map_to_odom is not None:
            future = (stamp or self.now().nanoseconds) + round(cfg.transform_tolerance * 1e9)
            self._tf.sendTransform(make_transform_2d(cfg.global_frame_id, cfg.odom_frame_id,
                                                     future, *self._map_to_odom))

    def _publish_pose(self, est: Any, cov: Any, stamp: Any) -> None:
        from eddiebot.msgs.geometry_msgs import PoseWithCovarianceStamped

        assert self.amcl is not None
        msg = PoseWithCovarianceStamped()
        msg.header.stamp = stamp
        msg.header.frame_id = self.amcl.config.global_frame_id
        msg.pose.pose.position.x, msg.pose.pose.position.y = float(est[0]), float(est[1])
        msg.pose.pose.orientation.z = math.sin(est[2] / 2.0)
        msg.pose.pose.orientation.w = math.cos(est[2] / 2.0)
        c = np.zeros((6, 6))
        c[:2, :2] = cov[:2, :2]
        c[5, 5] = cov[2, 2]
        msg.pose.covariance = c.reshape(-1)
        self._pose_pub.publish(msg)

    def _publish_cloud(self, stamp: Any) -> None:
        from eddiebot.msgs.geometry_msgs import Point, Pose, Quaternion
        from eddiebot.msgs.nav2_msgs import Particle, ParticleCloud
        from eddiebot.msgs.std_msgs import Header

        assert self.amcl is not None
        if self._cloud_pub.get_subscription_count() == 0:
            return
        p, w = self.amcl.particles, self.amcl.weights
        self._cloud_pub.publish(ParticleCloud(
            header=Header(stamp=stamp, frame_id=self.amcl.config.global_frame_id),
            particles=[Particle(pose=Pose(position=Point(x=float(x), y=float(y), z=0.0),
                                          orientation=Quaternion(x=0.0, y=0.0, z=math.sin(t / 2),
                                                                 w=math.cos(t / 2))),
                                weight=float(wt)) for (x, y, t), wt in zip(p, w)]))
