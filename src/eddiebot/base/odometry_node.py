"""Odometry node: ``/joint_states`` wheel angles → ``/odom`` and TF ``odom → base_footprint``.

The board node stamps ``/joint_states`` with the time the board sampled its counters (Encoders has
no header), so the pose is integrated on the sample times, not on callback times.
Parameters carry diff_drive_controller's names.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from eddiebot.base.odometry import DiffDriveOdometry, OdometryConfig, OdometryState
from eddiebot.core.node import Node
from eddiebot.core.parameters import ParameterDescriptor
from eddiebot.core.time import ns_to_stamp, stamp_to_ns
from eddiebot.geometry import yaw_to_quaternion
from eddiebot.msgs.geometry_msgs import TransformStamped
from eddiebot.msgs.nav_msgs import Odometry
from eddiebot.msgs.sensor_msgs import JointState
from eddiebot.msgs.tf2_msgs import TFMessage

__all__ = ["OdometryNode", "odometry_to_msg"]

#: read once at start; `param set` is refused rather than silently ignored
_RO = ParameterDescriptor(read_only=True)

#: variance reported for the unobserved dimensions (z, roll, pitch), as REP-105 users expect
_UNOBSERVED = 1e6


def odometry_to_msg(state: OdometryState, odom_frame: str, base_frame: str) -> Any:
    """An ``OdometryState`` as nav_msgs/Odometry (6×6 covariances, row-major)."""
    msg = Odometry()
    msg.header.stamp = ns_to_stamp(state.stamp_ns)
    msg.header.frame_id = odom_frame
    msg.child_frame_id = base_frame
    p = msg.pose.pose
    p.position.x, p.position.y = state.x, state.y
    qx, qy, qz, qw = yaw_to_quaternion(state.theta)
    p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w = qx, qy, qz, qw
    pc = np.zeros((6, 6))
    idx = [0, 1, 5]
    pc[np.ix_(idx, idx)] = state.pose_covariance
    pc[2, 2] = pc[3, 3] = pc[4, 4] = _UNOBSERVED
    msg.pose.covariance = pc.reshape(36)
    msg.twist.twist.linear.x = state.linear
    msg.twist.twist.angular.z = state.angular
    tc = np.zeros((6, 6))
    tc[0, 0], tc[5, 5] = state.twist_covariance[0, 0], state.twist_covariance[1, 1]
    tc[1, 1] = tc[2, 2] = tc[3, 3] = tc[4, 4] = _UNOBSERVED
    msg.twist.covariance = tc.reshape(36)
    return msg


class OdometryNode(Node):
    """Wheel odometry for a differential drive."""

    default_node_name = "eddie_odom"

    def __init__(self, node_name: str = default_node_name, **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        cfg = OdometryConfig()
        self.left_names = self.declare_parameter("left_wheel_names", ["left_wheel_joint"], _RO).value
        self.right_names = self.declare_parameter("right_wheel_names", ["right_wheel_joint"], _RO).value
        self.odom_frame = self.declare_parameter("odom_frame_id", "odom", _RO).value
        self.base_frame = self.declare_parameter("base_frame_id", "base_footprint", _RO).value
        self.enable_tf = self.declare_parameter("enable_odom_tf", True, _RO).value
        config = OdometryConfig(
            wheel_separation=self.declare_parameter("wheel_separation", cfg.wheel_separation, _RO).value,
            wheel_radius=self.declare_parameter("wheel_radius", cfg.wheel_radius, _RO).value,
            counts_per_rev=self.declare_parameter("counts_per_rev", cfg.counts_per_rev, _RO).value,
            wheel_separation_multiplier=self.declare_parameter("wheel_separation_multiplier", 1.0, _RO).value,
            left_wheel_radius_multiplier=self.declare_parameter("left_wheel_radius_multiplier", 1.0, _RO).value,
            right_wheel_radius_multiplier=self.declare_parameter("right_wheel_radius_multiplier", 1.0, _RO).value,
            velocity_rolling_window_size=self.declare_parameter(
                "velocity_rolling_window_size", cfg.velocity_rolling_window_size, _RO
            ).value,
        )
        self.odometry = DiffDriveOdometry(config)
        self._indices: tuple[int, int] | None = None
        self._warned_names = False
        self._resets_seen = 0
        self.odom_pub = self.create_publisher(Odometry, "odom", 50)
        self.tf_pub = self.create_publisher(TFMessage, "/tf", 100)
        self.create_subscription(JointState, "joint_states", self._on_joints, 50)

    def _wheel_indices(self, names: list[str]) -> tuple[int, int] | None:
        if self._indices is not None and len(names) > max(self._indices):
            li, ri = self._indices
            if names[li] in self.left_names and names[ri] in self.right_names:
                return self._indices
        left = next((i for i, n in enumerate(names) if n in self.left_names), None)
        right = next((i for i, n in enumerate(names) if n in self.right_names), None)
        if left is None or right is None:
            return None
        self._indices = (left, right)
        return self._indices

    def _on_joints(self, msg: Any) -> None:
        idx = self._wheel_indices(list(msg.name))
        if idx is None or len(msg.position) <= max(idx):
            if not self._warned_names:
                self.get_logger().warning(
                    f"joint_states without wheels {self.left_names}/{self.right_names}: got {list(msg.name)}"
                )
                self._warned_names = True
            return
        stamp = stamp_to_ns(msg.header.stamp)
        state = self.odometry.update(float(msg.position[idx[0]]), float(msg.position[idx[1]]), stamp)
        if self.odometry.resets != self._resets_seen:
            self._resets_seen = self.odometry.resets
            self.get_logger().warning("wheel counters jumped (driver restart?): odometry re-baselined")
        if state is None:
            return
        self.odom_pub.publish(odometry_to_msg(state, self.odom_frame, self.base_frame))
        if self.enable_tf:
            t = TransformStamped()
            t.header.stamp = ns_to_stamp(state.stamp_ns)
            t.header.frame_id = self.odom_frame
            t.child_frame_id = self.base_frame
            t.transform.translation.x, t.transform.translation.y = state.x, state.y
            q = yaw_to_quaternion(state.theta)
            r = t.transform.rotation
            r.x, r.y, r.z, r.w = q
            self.tf_pub.publish(TFMessage(transforms=[t]))
