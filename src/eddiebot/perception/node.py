"""Perception nodes: depthimage_to_laserscan's and depth_image_proc's roles.

``DepthToScanNode`` subscribes ``depth`` (Image) and ``depth_camera_info`` (CameraInfo)
— remap them as upstream users do, e.g. ``depth:=/depth/image_raw`` — and publishes
``scan`` with depthimage_to_laserscan's parameters (scan_time, range_min, range_max,
scan_height, output_frame). ``DepthToCloudNode`` publishes ``points`` (XYZ, or XYZRGB when
``registered`` is true and an RGB image arrives with the same stamp), computed only while
someone subscribes. A bad frame (unknown encoding, size disagreeing with camera_info) is
skipped with one error per topic, never a crash.
"""

from __future__ import annotations

from typing import Any

from eddiebot.core.node import Node
from eddiebot.core.qos import qos_profile_sensor_data
from eddiebot.msgs.sensor_msgs import CameraInfo, Image, LaserScan, PointCloud2
from eddiebot.perception.depth_to_cloud import depth_to_pointcloud2, depth_to_pointcloud2_rgb
from eddiebot.perception.depth_to_scan import DepthToScanParams, depth_image_to_laserscan
from eddiebot.perception.errors import PerceptionError

__all__ = ["DepthToCloudNode", "DepthToScanNode"]


class DepthToScanNode(Node):
    default_node_name = "depthimage_to_laserscan"

    def __init__(self, node_name: str = default_node_name, **kwargs: Any) -> None:
        remaps = {"depth": "/depth/image_raw", "depth_camera_info": "/depth/camera_info",
                  "scan": "/scan"}
        remaps.update(kwargs.pop("remappings", None) or {})
        super().__init__(node_name, remappings=remaps, **kwargs)
        d = DepthToScanParams()
        self.params = DepthToScanParams(
            scan_time=float(self.declare_parameter("scan_time", d.scan_time).value),
            range_min=float(self.declare_parameter("range_min", d.range_min).value),
            range_max=float(self.declare_parameter("range_max", d.range_max).value),
            scan_height=int(self.declare_parameter("scan_height", d.scan_height).value),
            output_frame=str(self.declare_parameter("output_frame", d.output_frame).value),
            row_selection=str(self.declare_parameter("row_selection", d.row_selection).value),
            surface_tolerance=float(
                self.declare_parameter("surface_tolerance", d.surface_tolerance).value),
            surface_tolerance_quadratic=float(self.declare_parameter(
                "surface_tolerance_quadratic", d.surface_tolerance_quadratic).value),
        )
        self.info: Any = None
        self.pub = self.create_publisher(LaserScan, "scan", qos_profile_sensor_data)
        self.create_subscription(CameraInfo, "depth_camera_info", self._on_info, qos_profile_sensor_data)
        self.create_subscription(Image, "depth", self._on_depth, qos_profile_sensor_data)

    def _on_info(self, msg: Any) -> None:
        self.info = msg

    def _on_depth(self, msg: Any) -> None:
        if self.info is None:
            self.get_logger().warning("depth image before any camera_info: waiting", once=True)
            return
        try:
            scan = depth_image_to_laserscan(msg, self.info, self.params)
        except PerceptionError as exc:
            self.get_logger().error(f"{self.resolve_topic_name('depth')}: {exc}", once=True)
            return
        self.pub.publish(scan)


class DepthToCloudNode(Node):
    default_node_name = "point_cloud_xyz"

    def __init__(self, node_name: str = default_node_name, **kwargs: Any) -> None:
        remaps = {"depth": "/depth/image_raw", "depth_camera_info": "/depth/camera_info",
                  "rgb": "/image_raw", "points": "/points"}
        remaps.update(kwargs.pop("remappings", None) or {})
        super().__init__(node_name, remappings=remaps, **kwargs)
        self.registered = bool(self.declare_parameter("registered", False).value)
        self.info: Any = None
        self.rgb: Any = None
        self.pub = self.create_publisher(PointCloud2, "points", qos_profile_sensor_data)
        self.create_subscription(CameraInfo, "depth_camera_info", self._on_info, qos_profile_sensor_data)
        self.create_subscription(Image, "depth", self._on_depth, qos_profile_sensor_data)
        if self.registered:
            self.create_subscription(Image, "rgb", self._on_rgb, qos_profile_sensor_data)

    def _on_info(self, msg: Any) -> None:
        self.info = msg

    def _on_rgb(self, msg: Any) -> None:
        self.rgb = msg

    def _on_depth(self, msg: Any) -> None:
        if self.info is None or self.pub.get_subscription_count() == 0:
            return
        try:
            rgb = self.rgb
            if self.registered and rgb is not None and rgb.header.stamp == msg.header.stamp:
                cloud = depth_to_pointcloud2_rgb(msg, rgb, self.info)
            else:
                cloud = depth_to_pointcloud2(msg, self.info)
        except PerceptionError as exc:
            self.get_logger().error(f"{self.resolve_topic_name('depth')}: {exc}", once=True)
            return
        self.pub.publish(cloud)
