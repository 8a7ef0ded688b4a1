"""image_transport's compressed republishers, as a node with a rate limit.

``/image_raw`` → ``/image_raw/compressed`` (sensor_msgs/CompressedImage, JPEG, format
``"rgb8; jpeg compressed bgr8"`` as compressed_image_transport writes it) and
``/depth/image_raw`` → ``/depth/image_raw/compressedDepth`` (16UC1 as PNG behind
compressed_depth_image_transport's 12-byte ConfigHeader: format PNG and two unused floats).
``max_rate`` (Hz, default 5) throttles both, so recording RGB-D stays small: raw 30 Hz
640×480 RGB-D is 46 MB per second.
"""

from __future__ import annotations

import struct
from typing import Any

import cv2
import numpy as np

from eddiebot.core.node import Node
from eddiebot.core.qos import qos_profile_sensor_data
from eddiebot.core.time import stamp_to_ns
from eddiebot.msgs.sensor_msgs import CompressedImage, Image

__all__ = ["ImageCompressorNode", "compress_depth_png", "compress_rgb_jpeg"]

_PNG = 1  # compressed_depth_image_transport::compressionFormat::PNG


def compress_rgb_jpeg(msg: Any, quality: int = 80) -> Any:
    """A rgb8/bgr8 Image as a JPEG CompressedImage with the same header."""
    h, w = int(msg.height), int(msg.width)
    arr = np.frombuffer(bytes(msg.data), dtype=np.uint8).reshape(h, int(msg.step))[:, : w * 3].reshape(h, w, 3)
    bgr = arr[..., ::-1] if msg.encoding == "rgb8" else arr
    ok, buf = cv2.imencode(".jpg", np.ascontiguousarray(bgr), [cv2.IMWRITE_JPEG_QUALITY, quality])
    if not ok:
        raise ValueError("JPEG encoding failed")
    return CompressedImage(header=msg.header, format=f"{msg.encoding}; jpeg compressed bgr8",
                           data=np.frombuffer(buf.tobytes(), dtype=np.uint8))


def compress_depth_png(msg: Any) -> Any:
    """A 16UC1 depth Image as compressedDepth (ConfigHeader + 16-bit PNG)."""
    if msg.encoding != "16UC1":
        raise ValueError(f"compressedDepth here takes 16UC1, not {msg.encoding!r}")
    h, w = int(msg.height), int(msg.width)
    arr = np.frombuffer(bytes(msg.data), dtype=np.uint16).reshape(h, int(msg.step) // 2)[:, :w]
    ok, buf = cv2.imencode(".png", np.ascontiguousarray(arr), [cv2.IMWRITE_PNG_COMPRESSION, 1])
    if not ok:
        raise ValueError("PNG encoding failed")
    header = struct.pack("<iff", _PNG, 0.0, 0.0)
    return CompressedImage(header=msg.header, format="16UC1; compressedDepth png",
                           data=np.frombuffer(header + buf.tobytes(), dtype=np.uint8))


class ImageCompressorNode(Node):
    default_node_name = "image_compressor"

    def __init__(self, node_name: str = default_node_name, **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        rate = float(self.declare_parameter("max_rate", 5.0).value)
        self.period_ns = round(1e9 / rate) if rate > 0 else 0
        self.quality = int(self.declare_parameter("jpeg_quality", 80).value)
        self._last: dict[str, int] = {}
        self.rgb_pub = self.create_publisher(CompressedImage, "/image_raw/compressed", qos_profile_sensor_data)
        self.depth_pub = self.create_publisher(CompressedImage, "/depth/image_raw/compressedDepth",
                                               qos_profile_sensor_data)
        self.create_subscription(Image, "/image_raw", self._on_rgb, qos_profile_sensor_data)
        self.create_subscription(Image, "/depth/image_raw", self._on_depth, qos_profile_sensor_data)

    def _due(self, key: str, msg: Any) -> bool:
        t = stamp_to_ns(msg.header.stamp)
        last = self._last.get(key)
        if last is not None and 0 <= t - last < self.period_ns:
            return False
        self._last[key] = t
        return True

    def _on_rgb(self, msg: Any) -> None:
        if self._due("rgb", msg):
            try:
                self.rgb_pub.publish(compress_rgb_jpeg(msg, self.quality))
            except ValueError as exc:
                self.get_logger().error(f"/image_raw: {exc}", once=True)

    def _on_depth(self, msg: Any) -> None:
        if self._due("depth", msg):
            try:
                self.depth_pub.publish(compress_depth_png(msg))
            except ValueError as exc:
                self.get_logger().error(f"/depth/image_raw: {exc}", once=True)
