"""Perception cores: depth image to laser scan, depth image to point cloud, depth
registration. Pure functions over ``sensor_msgs`` messages and numpy arrays, matching the
behaviour of ROS 2's ``depthimage_to_laserscan`` and ``depth_image_proc``.
"""

from eddiebot.perception._image import image_to_array
from eddiebot.perception.depth_to_cloud import (
    depth_to_pointcloud2,
    depth_to_pointcloud2_rgb,
    depth_to_points,
)
from eddiebot.perception.depth_to_scan import (
    DepthToScanParams,
    ScanGeometry,
    depth_image_to_laserscan,
    scan_geometry,
)
from eddiebot.perception.errors import (
    ImageSizeError,
    PerceptionError,
    ScanHeightError,
    UnsupportedEncodingError,
)
from eddiebot.perception.register import register_depth, register_depth_array

__all__ = [
    "DepthToScanParams",
    "ImageSizeError",
    "PerceptionError",
    "ScanGeometry",
    "ScanHeightError",
    "UnsupportedEncodingError",
    "depth_image_to_laserscan",
    "depth_to_pointcloud2",
    "depth_to_pointcloud2_rgb",
    "depth_to_points",
    "image_to_array",
    "register_depth",
    "register_depth_array",
    "scan_geometry",
]
