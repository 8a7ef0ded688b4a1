"""A kinematic robot for the navigation-server tests: unicycle on ``/cmd_vel_safe`` in a
synthetic map, ``/odom`` + TF ``odom → base_footprint`` at 50 Hz, a 360-beam ``/scan`` ray-cast
against the map at 10 Hz, and a static ``map → odom`` (perfect localisation)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from eddiebot.core import Node, StaticTransformBroadcaster, TransformBroadcaster
from eddiebot.core.tf import make_transform_2d
from eddiebot.maps import OccupancyMap
from eddiebot.msgs.geometry_msgs import Twist
from eddiebot.msgs.nav_msgs import Odometry
from eddiebot.msgs.sensor_msgs import LaserScan


def room_map(size_m: float = 6.0, res: float = 0.05, box: tuple[float, float, float, float] | None
             = (2.6, 2.0, 3.4, 4.0)) -> OccupancyMap:
    """A walled square room (origin at its corner) with an optional box (x0, y0, x1, y1)."""
    n = round(size_m / res)
    data = np.zeros((n, n), dtype=np.int8)
    data[:2, :] = data[-2:, :] = 100
    data[:, :2] = data[:, -2:] = 100
    if box is not None:
        x0, y0, x1, y1 = (round(v / res) for v in box)
        data[y0:y1, x0:x1] = 100
    return OccupancyMap(data, res, (0.0, 0.0, 0.0), "map")


class StubRobot(Node):
    def __init__(self, occ: OccupancyMap, pose: tuple[float, float, float], *,
                 cmd_topic: str = "/cmd_vel_safe", static_map_odom: bool = True,
                 **kwargs: Any) -> None:
        super().__init__("stub_robot", **kwargs)
        self.map = occ
        self.pose = np.array(pose, dtype=np.float64)
        self.start = self.pose.copy()
        self.cmd = (0.0, 0.0)
        self.publish_tf = True
        #: drive in place and backwards only (a robot stuck against something it cannot see)
        self.block_forward = False
        self.commands: list[tuple[int, float, float]] = []
        self.tf = TransformBroadcaster(self)
        statics = [make_transform_2d("base_footprint", "laser", 0, 0.0, 0.0, 0.0)]
        if static_map_odom:
            statics.append(make_transform_2d("map", "odom", 0, *self.start))
        StaticTransformBroadcaster(self).sendTransform(statics)
        self.odom_pub = self.create_publisher(Odometry, "/odom", 10)
        self.scan_pub = self.create_publisher(LaserScan, "/scan", 5)
        self.create_subscription(Twist, cmd_topic, self._on_cmd, 10)
        self._last_ns = self.now().nanoseconds
        self.create_timer(0.02, self._step)
        self.create_timer(0.1, self._scan)

    def _on_cmd(self, msg: Any) -> None:
        v = float(msg.linear.x)
        self.cmd = (min(v, 0.0) if self.block_forward else v, float(msg.angular.z))
        self.commands.append((self.now().nanoseconds, *self.cmd))

    def odom_pose(self) -> tuple[float, float, float]:
        # odom frame = the start pose; map -> odom is static
        dx, dy = self.pose[0] - self.start[0], self.pose[1] - self.start[1]
        c, s = math.cos(-self.start[2]), math.sin(-self.start[2])
        return (c * dx - s * dy, s * dx + c * dy, self.pose[2] - self.start[2])

    def _step(self) -> None:
        now = self.now().nanoseconds
        dt = (now - self._last_ns) * 1e-9
        self._last_ns = now
        v, w = self.cmd
        th = self.pose[2]
        self.pose += np.array([v * math.cos(th) * dt, v * math.sin(th) * dt, w * dt])
        x, y, yaw = self.odom_pose()
        stamp = self.now().to_msg()
        if self.publish_tf:
            self.tf.sendTransform(make_transform_2d("odom", "base_footprint", now, x, y, yaw))
        od = Odometry()
        od.header.stamp = stamp
        od.header.frame_id = "odom"
        od.child_frame_id = "base_footprint"
        od.pose.pose.position.x, od.pose.pose.position.y = x, y
        od.pose.pose.orientation.z, od.pose.pose.orientation.w = math.sin(yaw / 2), math.cos(yaw / 2)
        od.twist.twist.linear.x, od.twist.twist.angular.z = v, w
        self.odom_pub.publish(od)

    def ranges(self, n: int = 360, rmax: float = 4.0) -> np.ndarray:
        occ = self.map
        ang = self.pose[2] + np.linspace(-math.pi, math.pi, n, endpoint=False)
        steps = np.arange(0.0, rmax, occ.resolution / 2.0)
        xs = self.pose[0] + np.outer(np.cos(ang), steps)
        ys = self.pose[1] + np.outer(np.sin(ang), steps)
        i = np.floor((xs - occ.origin[0]) / occ.resolution).astype(int)
        j = np.floor((ys - occ.origin[1]) / occ.resolution).astype(int)
        inside = (i >= 0) & (j >= 0) & (i < occ.width) & (j < occ.height)
        hit = np.zeros_like(inside)
        hit[inside] = occ.data[j[inside], i[inside]] >= 65
        first = np.where(hit.any(axis=1), hit.argmax(axis=1), -1)
        r = np.where(first >= 0, steps[np.maximum(first, 0)], np.inf)
        return r.astype(np.float32)

    def _scan(self) -> None:
        n = 360
        scan = LaserScan()
        scan.header.stamp = self.now().to_msg()
        scan.header.frame_id = "laser"
        scan.angle_min = -math.pi
        scan.angle_increment = 2 * math.pi / n
        scan.angle_max = scan.angle_min + scan.angle_increment * (n - 1)
        scan.range_min, scan.range_max = 0.05, 4.0
        scan.ranges = self.ranges(n)
        self.scan_pub.publish(scan)
