"""Compressed image republishing: JPEG colour, lossless 16-bit PNG depth, rate limit."""

import struct

import cv2
import numpy as np

from eddiebot.core import Context, Node, SingleThreadedExecutor
from eddiebot.msgs.sensor_msgs import CompressedImage
from eddiebot.perception.compress import ImageCompressorNode, compress_depth_png, compress_rgb_jpeg
from eddiebot.sim.camera import depth_image_msg, rgb_image_msg


def test_depth_is_lossless_and_rgb_close():
    depth = (np.arange(120 * 160, dtype=np.uint32) % 7000).astype(np.uint16).reshape(120, 160)
    c = compress_depth_png(depth_image_msg(depth, 5))
    fmt, _, _ = struct.unpack("<iff", bytes(c.data[:12]))
    assert fmt == 1 and c.format == "16UC1; compressedDepth png"
    back = cv2.imdecode(np.frombuffer(bytes(c.data[12:]), np.uint8), cv2.IMREAD_UNCHANGED)
    np.testing.assert_array_equal(back, depth)
    rgb = np.zeros((120, 160, 3), np.uint8)
    rgb[..., 0] = 200  # red
    j = compress_rgb_jpeg(rgb_image_msg(rgb, 5))
    bgr = cv2.imdecode(np.frombuffer(bytes(j.data), np.uint8), cv2.IMREAD_COLOR)
    assert abs(int(bgr[60, 80, 2]) - 200) < 8 and int(bgr[60, 80, 0]) < 10


def test_rate_limit():
    ctx = Context(use_sim_time=True)
    node = ImageCompressorNode(context=ctx, parameter_overrides={"max_rate": 5.0})
    probe = Node("probe", context=ctx)
    got = []
    probe.create_subscription(CompressedImage, "/depth/image_raw/compressedDepth", got.append, 100)
    pub = probe.create_publisher(type(depth_image_msg(np.zeros((2, 2), np.uint16))), "/depth/image_raw", 100)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    ex.add_node(probe)
    for i in range(30):  # 30 frames at 30 Hz = 1 s
        pub.publish(depth_image_msg(np.full((4, 4), i, np.uint16), i * 33_333_333))
        ex.spin_until_idle()
    assert len(got) == 5
    ctx.shutdown()
