"""Eddie's robot description (URDF), generated from the one constants module.

The link tree and fixed-joint offsets follow the original ``eddiebot.urdf.xacro`` (hardware
reference §3, §5); the wheel joints are placed from ``TRACK_M`` and ``WHEEL_RADIUS_M`` so
odometry, the board node, the simulator and the description agree (the original URDF put
the wheels 0.381 m apart while its code used 0.39 m). Range sensors come from the sensor
table (``IR_SENSORS``, ``PING_SENSORS``) with frames ``<name>_link``.

Every body link carries an ``<inertial>`` estimated from its parts (:func:`link_inertials`,
≈ 11.4 kg in all against the 11.5 kg the platform guide gives); the pure coordinate frames
(:data:`FRAME_LINKS`: the root ``base_footprint`` and the Kinect's optical frames) have none —
KDL refuses an inertia on the root link, and a mass on a frame would be fiction.
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
    SensorKind,
)

__all__ = [
    "BASE_RADIUS_M",
    "CAMERA_DEPTH_OPTICAL_FRAME",
    "CAMERA_RGB_OPTICAL_FRAME",
    "FRAME_LINKS",
    "WHEEL_JOINTS",
    "FixedJoint",
    "Inertial",
    "eddie_urdf",
    "fixed_joints",
    "link_inertials",
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


FRAME_LINKS = frozenset({
    "base_footprint", "camera_rgb_frame", "camera_depth_frame",
    CAMERA_RGB_OPTICAL_FRAME, CAMERA_DEPTH_OPTICAL_FRAME,
})
"""Links that are coordinate frames only, without mass."""


@dataclass(frozen=True)
class Inertial:
    """Mass (kg) and principal moments (kg·m²) about the centre of mass ``xyz`` (m, link
    frame); every part is modelled as a box, cylinder or sphere aligned with its link's
    axes, so the products of inertia are zero."""

    mass: float
    ixx: float
    iyy: float
    izz: float
    xyz: tuple[float, float, float] = (0.0, 0.0, 0.0)


def _box(mass: float, x: float, y: float, z: float) -> Inertial:
    """Solid box of edges x, y, z: I_xx = m (y² + z²) / 12, and so on."""
    return Inertial(mass, mass * (y * y + z * z) / 12, mass * (x * x + z * z) / 12,
                    mass * (x * x + y * y) / 12)


def _cylinder(mass: float, radius: float, length: float, axis: str = "z") -> Inertial:
    """Solid cylinder: m r² / 2 about its axis, m (3 r² + h²) / 12 across it."""
    along, across = mass * radius * radius / 2, mass * (3 * radius * radius + length * length) / 12
    ixx, iyy, izz = (along if a == axis else across for a in "xyz")
    return Inertial(mass, ixx, iyy, izz)


def _sphere(mass: float, radius: float) -> Inertial:
    """Solid sphere: 2 m r² / 5 about every axis."""
    i = 2 * mass * radius * radius / 5
    return Inertial(mass, i, i, i)


#: Eddie's decks: 17.8 in (r 0.2245 m) discs of 3/8 in (9.5 mm) plastic; at HDPE's
#: 950 kg/m³ that is π·0.2245²·0.0095·950 ≈ 1.43 kg each
_DECK_KG = 1.43


def link_inertials(wheel_radius: float = WHEEL_RADIUS_M) -> dict[str, Inertial]:
    """Estimated mass and inertia of every body link (``FRAME_LINKS`` have none).

    Masses are estimates from the parts (PLAT, WK36, the sensors' datasheets), chosen so
    the robot with its Kinect adds up to ≈ 11.4 kg against PLAT's 11.5 kg."""
    out = {
        # lower deck plus the control board, wiring, fuse and switch (≈ 0.3 kg, spread
        # over the deck): a thin cylinder of the deck's size
        "base_link": _cylinder(_DECK_KG + 0.3, BASE_RADIUS_M, 0.0095),
        # two 12 V 7 Ah sealed lead-acid batteries (≈ 2.1 kg each) and their tray: a
        # solid box of the battery box's size
        "battery_box": _box(4.5, 0.1778, 0.3366, 0.0762),
        # #27971 motor, gearbox, mount and Position Controller (≈ 0.85 kg): a cylinder
        # along the axle, 3 cm radius, 10 cm long
        "left_axle_link": _cylinder(0.85, 0.03, 0.10, axis="y"),
        "right_axle_link": _cylinder(0.85, 0.03, 0.10, axis="y"),
        # 6 in pneumatic wheel with hub (≈ 0.45 kg): a solid cylinder along the axle (a
        # tyre's rim-heavy mass puts the true I_yy between m r²/2 and m r²)
        "left_wheel_link": _cylinder(0.45, wheel_radius, 0.0254, axis="y"),
        "right_wheel_link": _cylinder(0.45, wheel_radius, 0.0254, axis="y"),
        # caster wheel and swivel (≈ 0.1 kg) within the 5 cm collision sphere
        "front_caster": _sphere(0.10, 0.05),
        "rear_caster": _sphere(0.10, 0.05),
        # upper deck, bare: the same disc
        "plate_0_link": _cylinder(_DECK_KG, BASE_RADIUS_M, 0.0095),
        # Kinect mounting bracket (≈ 0.1 kg): a 6 × 20 × 1 cm plate
        "camera_mount_link": _box(0.10, 0.06, 0.20, 0.01),
        # Kinect v1 without its tilt base (≈ 0.5 kg): a box of its 7 × 28 × 7 cm visual
        "camera_link": _box(0.50, 0.07, 0.28, 0.07),
    }
    for i in range(4):
        # 5 in (0.127 m) aluminium hex standoff, 3/8 in across flats: ≈ 0.03 kg, as a
        # cylinder of 5 mm radius
        out[f"standoff_5in_{i}_link"] = _cylinder(0.03, 0.005, 0.127)
    for i in range(2):
        # the 30 cm standoffs that carry the Kinect: ≈ 0.06 kg each
        out[f"standoff_30cm_{i}_link"] = _cylinder(0.06, 0.005, 0.30)
    for s in (*IR_SENSORS, *PING_SENSORS):
        if s.kind == SensorKind.IR:
            # GP2Y0A21 (3.5 g, 13.5 × 44.5 × 19 mm) with bracket and cable: 10 g
            out[f"{s.name}_link"] = _box(0.01, 0.0135, 0.0445, 0.019)
        else:
            # PING))) (9 g, 16 × 46 × 21 mm with its transducers) with bracket: 20 g
            out[f"{s.name}_link"] = _box(0.02, 0.016, 0.046, 0.021)
    return out


def _inertial_xml(i: Inertial) -> str:
    return (f'<inertial><origin xyz="{_f(i.xyz)}" rpy="0 0 0"/><mass value="{i.mass:.6g}"/>'
            f'<inertia ixx="{i.ixx:.6g}" ixy="0" ixz="0" iyy="{i.iyy:.6g}" iyz="0" '
            f'izz="{i.izz:.6g}"/></inertial>')


def _f(values: tuple[float, ...]) -> str:
    return " ".join(f"{v:.6g}" for v in values)


def eddie_urdf(track: float = TRACK_M, wheel_radius: float = WHEEL_RADIUS_M) -> str:
    """The URDF text of Eddie with a Kinect v1 (links, joints, simple visuals, inertials)."""
    joints = fixed_joints(track, wheel_radius)
    links = ["base_footprint"] + [j.child for j in joints]
    inertials = link_inertials(wheel_radius)
    lines = ['<?xml version="1.0"?>', '<robot name="eddiebot">']
    wheel_geom = f'<cylinder radius="{wheel_radius:.6g}" length="0.0254"/>'
    for name in links:
        geom = _VISUALS.get(name, "")
        inertial = _inertial_xml(inertials[name]) if name in inertials else ""
        if name.endswith("_wheel_link"):
            lines.append(
                f'  <link name={quoteattr(name)}><visual><origin rpy="{math.pi / 2:.6g} 0 0"/>'
                f"<geometry>{wheel_geom}</geometry></visual>"
                f"<collision><origin rpy=\"{math.pi / 2:.6g} 0 0\"/><geometry>{wheel_geom}</geometry>"
                f"</collision>{inertial}</link>"
            )
        elif geom:
            lines.append(f"  <link name={quoteattr(name)}><visual><geometry>{geom}</geometry></visual>"
                         f"<collision><geometry>{geom}</geometry></collision>{inertial}</link>")
        elif inertial:
            lines.append(f"  <link name={quoteattr(name)}>{inertial}</link>")
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
