"""Depth → PointCloud2 and depth registration."""

from __future__ import annotations

import numpy as np
import pytest

from eddiebot.perception import (
    ImageSizeError,
    depth_to_pointcloud2,
    depth_to_pointcloud2_rgb,
    register_depth,
    register_depth_array,
)
from eddiebot.sim.camera import (
    KINECT_DEPTH,
    KINECT_RGB,
    camera_info_msg,
    depth_image_msg,
    rgb_image_msg,
)


def _xyz(cloud):
    dt = np.dtype({"names": ["x", "y", "z"], "formats": ["<f4"] * 3, "offsets": [0, 4, 8],
                   "itemsize": cloud.point_step})
    return np.frombuffer(cloud.data.tobytes(), dtype=dt).reshape(cloud.height, cloud.width)


def test_xyz_cloud_geometry_and_layout():
    depth = np.full((480, 640), 2000, np.uint16)
    depth[10, 20] = 0
    info = camera_info_msg(KINECT_DEPTH)
    cloud = depth_to_pointcloud2(depth_image_msg(depth, 7), info)
    assert (cloud.height, cloud.width, cloud.point_step, cloud.row_step) == (480, 640, 16, 640 * 16)
    assert [(f.name, f.offset, f.datatype) for f in cloud.fields] == [("x", 0, 7), ("y", 4, 7), ("z", 8, 7)]
    assert cloud.is_dense is False and cloud.header.frame_id == "camera_depth_optical_frame"
    pts = _xyz(cloud)
    u, v = 600, 400
    assert pts[v, u]["z"] == pytest.approx(2.0)
    assert pts[v, u]["x"] == pytest.approx((u - KINECT_DEPTH.cx) * 2.0 / KINECT_DEPTH.fx, rel=1e-5)
    assert pts[v, u]["y"] == pytest.approx((v - KINECT_DEPTH.cy) * 2.0 / KINECT_DEPTH.fy, rel=1e-5)
    assert np.isnan(pts[10, 20]["z"])


def test_xyzrgb_cloud_packs_colour():
    depth = np.full((480, 640), 1.5, np.float32)
    rgb = np.zeros((480, 640, 3), np.uint8)
    rgb[5, 6] = (10, 20, 30)
    info = camera_info_msg(KINECT_RGB, frame_id="camera_rgb_optical_frame")
    cloud = depth_to_pointcloud2_rgb(depth_image_msg(depth), rgb_image_msg(rgb), info)
    assert cloud.point_step == 32 and [f.name for f in cloud.fields] == ["x", "y", "z", "rgb"]
    raw = cloud.data.reshape(480, 640, 32)
    packed = raw[5, 6, 16:20].view("<u4")[0]
    assert packed == (10 << 16) | (20 << 8) | 30
    with pytest.raises(ImageSizeError):
        depth_to_pointcloud2_rgb(depth_image_msg(depth[:240, :320]), rgb_image_msg(rgb), info)


def test_register_identity_and_shift():
    depth = np.full((480, 640), 2000, np.uint16)
    depth[:, :100] = 0
    k = (KINECT_DEPTH.fx, KINECT_DEPTH.fy, KINECT_DEPTH.cx, KINECT_DEPTH.cy)
    same = register_depth_array(depth, k, k, (640, 480), np.eye(4))
    assert np.array_equal(same[:, 101:-1], depth[:, 101:-1])
    # the RGB camera 2.5 cm to the right of the depth camera (x in the optical frame):
    # points shift left by fx·0.025/z pixels
    t = np.eye(4)
    t[0, 3] = -0.025
    shifted = register_depth_array(depth, k, k, (640, 480), t)
    du = KINECT_DEPTH.fx * 0.025 / 2.0
    first = np.argmax(shifted[240] > 0)
    assert first == pytest.approx(100 - du, abs=1.5)
    # message form: RGB size and frame, depth stamp
    rgb_info = camera_info_msg(KINECT_RGB.scaled(320, 240), frame_id="camera_rgb_optical_frame")
    out = register_depth(depth_image_msg(depth, 42), camera_info_msg(KINECT_DEPTH), rgb_info, np.eye(4))
    assert (out.width, out.height, out.encoding) == (320, 240, "16UC1")
    assert out.header.frame_id == "camera_rgb_optical_frame" and out.header.stamp.nanosec == 42
    vals = out.data.view("<u2").reshape(240, 320)
    assert np.median(vals[vals > 0]) == 2000
