"""Eddie's robot description (URDF), generated from the one constants module.

The link tree and fixed-joint offsets follow the original ``eddiebot.urdf.xacro`` (hardware
reference §3, §5); the wheel joints are placed from ``TRACK_M`` and ``WHEEL_RADIUS_M`` so
odometry, the board node, the simulator and the description agree (the original URDF put
the wheels 0.381 m apart while its code used 0.39 m). Range sensors come from the sensor
table (``IR_SENSORS``, ``PING_SENSORS``) with frames ``<name>_link``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from xml.sax.saxutils import quoteattr

from eddiebot.robot.constants import (
    BASE_LINK_HEIGHT_M,
    IR_SENSORS,
    PING_SENSORS,
    TRACK_M,
    WHEEL_RADIUS_M,
)

__all__ = [
    "BASE_RADIUS_M",
    "CAMERA_DEPTH_OPTICAL_FRAME",
    "CAMERA_RGB_OPTICAL_FRAME",
    "WHEEL_JOINTS",
    "FixedJoint",
    "eddie_urdf",
    "fixed_joints",
]

BASE_RADIUS_M = 0.2245
"""Footprint radius (URDF base_link cylinder; PLAT 17.8 in diameter)."""
CAMERA_RGB_OPTICAL_FRAME = "camera_rgb_optical_frame"
CAMERA_DEPTH_OPTICAL_FRAME = "camera_depth_optical_frame"
WHEEL_JOINTS = ("left_wheel_joint", "right_wheel_joint")

_BATTERY_Z = -0.04285
_AXLE_Y = 0.171475


@dataclass(frozen=True)
class FixedJoint:
    """A joint as (name, parent, child, xyz, rpy, type, axis)."""

    name: str
    parent: str
    child: str
    xyz: tuple[float, float, float]
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)
    type: str = "fixed"
    axis: tuple[float, float, float] | None = None


def fixed_joints(track: float = TRACK_M, wheel_radius: float = WHEEL_RADIUS_M) -> list[FixedJoint]:
    """Every joint of the description, parents before children."""
    wheel_z = wheel_radius - (BASE_LINK_HEIGHT_M + _BATTERY_Z)  # axle height above battery box
    half = track / 2.0
    j = [
        FixedJoint("base_footprint_joint", "base_footprint", "base_link", (0, 0, BASE_LINK_HEIGHT_M)),
        FixedJoint("battery_box_joint", "base_link", "battery_box", (0, 0, _BATTERY_Z)),
        FixedJoint("left_axle_joint", "battery_box", "left_axle_link", (0, _AXLE_Y, wheel_z)),
        FixedJoint("right_axle_joint", "battery_box", "right_axle_link", (0, -_AXLE_Y, wheel_z)),
        FixedJoint("left_wheel_joint", "left_axle_link", "left_wheel_link", (0, half - _AXLE_Y, 0),
                   type="continuous", axis=(0, 1, 0)),
        FixedJoint("right_wheel_joint", "right_axle_link", "right_wheel_link", (0, -(half - _AXLE_Y), 0),
                   type="continuous", axis=(0, 1, 0)),
        FixedJoint("front_caster_joint", "base_link", "front_caster", (0.18745, 0, -0.00475)),
        FixedJoint("rear_caster_joint", "base_link", "rear_caster", (-0.18745, 0, -0.00475)),
        FixedJoint("plate_0_joint", "base_link", "plate_0_link", (0, 0, 0.1365)),
    ]
    for i, (sx, sy) in enumerate([(1, 1), (1, -1), (-1, 1), (-1, -1)]):
        j.append(FixedJoint(f"standoff_5in_{i}_joint", "base_link", f"standoff_5in_{i}_link",
                            (sx * 0.0776402, sy * 0.1314196, 0.06825)))
    j += [
        FixedJoint("standoff_30cm_0_joint", "plate_0_link", "standoff_30cm_0_link", (-0.14, -0.084, 0.15715)),
        FixedJoint("standoff_30cm_1_joint", "plate_0_link", "standoff_30cm_1_link", (-0.14, 0.084, 0.15715)),
        FixedJoint("camera_mount_joint", "plate_0_link", "camera_mount_link", (-0.140, 0, 0.31555)),
        FixedJoint("camera_rgb_joint", "camera_mount_link", "camera_rgb_frame", (0.02, -0.0125, 0.055)),
        FixedJoint("camera_rgb_optical_joint", "camera_rgb_frame", CAMERA_RGB_OPTICAL_FRAME, (0, 0, 0),
                   (-math.pi / 2, 0, -math.pi / 2)),
        FixedJoint("camera_joint", "camera_rgb_frame", "camera_link", (-0.031, 0.0125, -0.016)),
        FixedJoint("camera_depth_joint", "camera_rgb_frame", "camera_depth_frame", (0, 0.025, 0)),
        FixedJoint("camera_depth_optical_joint", "camera_depth_frame", CAMERA_DEPTH_OPTICAL_FRAME,
                   (0, 0, 0), (-math.pi / 2, 0, -math.pi / 2)),
    ]
    for s in (*IR_SENSORS, *PING_SENSORS):
        j.append(FixedJoint(s.urdf_joint, "base_link", f"{s.name}_link", (s.x_m, s.y_m, s.z_m),
                            (0, 0, s.yaw_rad)))
    return j


_VISUALS = {
    "base_link": '<cylinder radius="0.2245" length="0.0095"/>',
    "battery_box": '<box size="0.1778 0.3366 0.0762"/>',
    "left_wheel_link": None,
    "right_wheel_link": None,
    "front_caster": '<sphere radius="0.05"/>',
    "rear_caster": '<sphere radius="0.05"/>',
    "plate_0_link": '<cylinder radius="0.2245" length="0.0095"/>',
    "camera_link": '<box size="0.07 0.28 0.07"/>',
}


def _f(values: tuple[float, ...]) -> str:
    return " ".join(f"{v:.6g}" for v in values)


def eddie_urdf(track: float = TRACK_M, wheel_radius: float = WHEEL_RADIUS_M) -> str:
    """The URDF text of Eddie with a Kinect v1 (links, joints, simple visuals)."""
    joints = fixed_joints(track, wheel_radius)
    links = ["base_footprint"] + [j.child for j in joints]
    lines = ['<?xml version="1.0"?>', '<robot name="eddiebot">']
    wheel_geom = f'<cylinder radius="{wheel_radius:.6g}" length="0.0254"/>'
    for name in links:
        geom = _VISUALS.get(name, "")
        if name.endswith("_wheel_link"):
            lines.append(
                f'  <link name={quoteattr(name)}><visual><origin rpy="{math.pi / 2:.6g} 0 0"/>'
                f"<geometry>{wheel_geom}</geometry></visual>"
                f"<collision><origin rpy=\"{math.pi / 2:.6g} 0 0\"/><geometry>{wheel_geom}</geometry>"
                "</collision></link>"
            )
        elif geom:
            lines.append(f"  <link name={quoteattr(name)}><visual><geometry>{geom}</geometry></visual>"
                         f"<collision><geometry>{geom}</geometry></collision></link>")
        else:
            lines.append(f"  <link name={quoteattr(name)}/>")
    for j in joints:
        axis = f'<axis xyz="{_f(j.axis)}"/>' if j.axis else ""
        lines.append(
            f"  <joint name={quoteattr(j.name)} type={quoteattr(j.type)}>"
            f"<parent link={quoteattr(j.parent)}/><child link={quoteattr(j.child)}/>"
            f'<origin xyz="{_f(j.xyz)}" rpy="{_f(j.rpy)}"/>{axis}</joint>'
        )
    lines.append("</robot>")
    return "\n".join(lines) + "\n"
