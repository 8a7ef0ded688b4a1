"""robot_state_publisher's role: ``/robot_description`` (latched), static TFs for fixed
joints on ``/tf_static``, and moving-joint TFs on ``/tf`` from ``/joint_states``.

The URDF is parsed with yourdfpy; by default it is Eddie's, generated from the constants.
"""

from __future__ import annotations

import io
from typing import Any

import numpy as np

from eddiebot.core.node import Node
from eddiebot.core.parameters import ParameterDescriptor
from eddiebot.core.qos import DurabilityPolicy, QoSProfile, qos_profile_latched
from eddiebot.geometry import quaternion_to_matrix, se3_to_tq
from eddiebot.msgs.geometry_msgs import TransformStamped
from eddiebot.msgs.sensor_msgs import JointState
from eddiebot.msgs.std_msgs import String
from eddiebot.msgs.tf2_msgs import TFMessage
from eddiebot.robot.constants import TRACK_M, WHEEL_RADIUS_M
from eddiebot.robot.urdf import eddie_urdf

__all__ = ["RobotStatePublisher", "parse_urdf_joints"]

#: read once at start; `param set` is refused rather than silently ignored
_RO = ParameterDescriptor(read_only=True)


def _axis_angle(axis: np.ndarray, angle: float) -> np.ndarray:
    a = axis / np.linalg.norm(axis)
    s = np.sin(angle / 2.0)
    return np.array([a[0] * s, a[1] * s, a[2] * s, np.cos(angle / 2.0)])


def parse_urdf_joints(urdf_text: str) -> list[dict[str, Any]]:
    """Joints of a URDF as dicts: name, type, parent, child, origin (4×4), axis."""
    import yourdfpy

    robot = yourdfpy.URDF.load(io.StringIO(urdf_text), build_scene_graph=False,
                               load_meshes=False, build_collision_scene_graph=False)
    out = []
    for j in robot.robot.joints:
        origin = j.origin if j.origin is not None else np.eye(4)
        axis = np.asarray(j.axis if j.axis is not None else (1.0, 0.0, 0.0), dtype=float)
        out.append({"name": j.name, "type": j.type, "parent": j.parent, "child": j.child,
                    "origin": np.asarray(origin, dtype=float), "axis": axis})
    return out


def _transform(parent: str, child: str, matrix: np.ndarray, stamp: Any) -> Any:
    t = TransformStamped()
    t.header.stamp = stamp
    t.header.frame_id = parent
    t.child_frame_id = child
    tr, q = se3_to_tq(matrix)
    t.transform.translation.x, t.transform.translation.y, t.transform.translation.z = map(float, tr)
    r = t.transform.rotation
    r.x, r.y, r.z, r.w = map(float, q)
    return t


class RobotStatePublisher(Node):
    default_node_name = "robot_state_publisher"

    def __init__(self, node_name: str = default_node_name, **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        track = float(self.declare_parameter("track", TRACK_M, _RO).value)
        wheel_radius = float(self.declare_parameter("wheel_radius", WHEEL_RADIUS_M, _RO).value)
        text = self.declare_parameter("robot_description", "", _RO).value or eddie_urdf(
            track=track, wheel_radius=wheel_radius)
        self.joints = parse_urdf_joints(text)
        self.moving = {j["name"]: j for j in self.joints if j["type"] in ("continuous", "revolute", "prismatic")}
        self.create_publisher(String, "robot_description", qos_profile_latched).publish(String(data=text))
        static_qos = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        stamp = self.get_clock().now().to_msg()
        fixed = [_transform(j["parent"], j["child"], j["origin"], stamp)
                 for j in self.joints if j["name"] not in self.moving]
        self.create_publisher(TFMessage, "/tf_static", static_qos).publish(TFMessage(transforms=fixed))
        self.tf_pub = self.create_publisher(TFMessage, "/tf", 100)
        self.create_subscription(JointState, "joint_states", self._on_joints, 10)

    def _on_joints(self, msg: Any) -> None:
        out = []
        for name, pos in zip(msg.name, msg.position):
            j = self.moving.get(name)
            if j is None:
                continue
            m = j["origin"].copy()
            motion = np.eye(4)
            if j["type"] == "prismatic":
                motion[:3, 3] = j["axis"] * float(pos)
            else:
                motion[:3, :3] = quaternion_to_matrix(_axis_angle(j["axis"], float(pos)))
            out.append(_transform(j["parent"], j["child"], m @ motion, msg.header.stamp))
        if out:
            self.tf_pub.publish(TFMessage(transforms=out))
