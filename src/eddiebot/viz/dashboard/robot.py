"""The dashboard's robot layers: its pose from TF, footprint (from the URDF or the local
costmap), laser scan, range sensors and camera images.
"""

from __future__ import annotations

import math
from typing import Any
from xml.etree import ElementTree

import numpy as np

from eddiebot.robot.urdf import BASE_RADIUS_M
from eddiebot.viz.dashboard.core import (
    binary_frame,
    colorize_depth,
    depth_to_metres,
    encode_jpeg,
    image_to_bgr,
    text_frame,
)
from eddiebot.viz.dashboard.display import _NS, DisplayNode, _compose, _r

__all__ = ["FOOTPRINT_RADIUS", "RANGE_TOPICS", "RobotLayers", "footprint_from_urdf"]

#: Eddie's footprint radius (m): the URDF's base_link cylinder, until /robot_description says.
FOOTPRINT_RADIUS = BASE_RADIUS_M
RANGE_TOPICS = ("/eddie/ir/left", "/eddie/ir/center", "/eddie/ir/right",
                "/eddie/ping/left", "/eddie/ping/right")


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


class RobotLayers(DisplayNode):
    """The robot's pose, footprint and sensors in the display frame."""

    footprint_radius: float
    footprint_source: str
    _image_period_ns: int
    _pose_period_ns: int
    _last_image_ns: dict[str, int]
    _last_pose_ns: int
    _last_range_ns: dict[str, int]

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
