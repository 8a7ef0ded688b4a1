"""Path and point-cloud conversions of the navigation nodes (vectorised)."""

from __future__ import annotations

import math

import numpy as np

from eddiebot.msgs.sensor_msgs import PointCloud2, PointField
from eddiebot.nav.nodes._common import path_from_msg, path_to_msg, pose_stamped
from eddiebot.nav.nodes._costmap import cloud_xyz


def test_path_round_trip_and_headers() -> None:
    yaws = np.array([0.0, 1.0, -2.5, math.pi - 1e-6, -math.pi / 2])
    path = np.column_stack([np.arange(5) * 0.5, -np.arange(5) * 0.25, yaws])
    msg = path_to_msg(path, "map", 3_250_000_001)
    assert msg.header.frame_id == "map" and msg.header.stamp.sec == 3
    assert msg.header.stamp.nanosec == 250_000_001
    assert len(msg.poses) == 5 and msg.poses[4].header.frame_id == "map"
    # the same message as one pose at a time
    one = pose_stamped(*path[2], "map", 3_250_000_001)
    assert one.pose.orientation.z == msg.poses[2].pose.orientation.z
    back = path_from_msg(msg)
    assert np.allclose(back[:, :2], path[:, :2])
    assert np.allclose(np.angle(np.exp(1j * (back[:, 2] - yaws))), 0.0, atol=1e-9)
    assert path_from_msg(path_to_msg(np.zeros((0, 3)), "map")).shape == (0, 3)


def test_cloud_xyz_offsets_padding_and_endianness() -> None:
    # fields in the order z, x, y with padding, 20-byte points; big-endian
    pts = np.zeros(4, dtype=np.dtype({"names": ["z", "x", "y"], "formats": [">f4"] * 3,
                                       "offsets": [0, 8, 12], "itemsize": 20}))
    pts["x"] = [1.0, np.nan, 3.0, 4.0]
    pts["y"] = [2.0, 0.0, np.inf, 5.0]
    pts["z"] = [0.5, 0.0, 0.0, 6.0]
    msg = PointCloud2(height=2, width=2, point_step=20, row_step=40, is_bigendian=True,
                      fields=[PointField(name="z", offset=0, datatype=7, count=1),
                              PointField(name="x", offset=8, datatype=7, count=1),
                              PointField(name="y", offset=12, datatype=7, count=1)],
                      data=np.frombuffer(pts.tobytes(), dtype=np.uint8))
    assert cloud_xyz(msg).tolist() == [[1.0, 2.0, 0.5], [4.0, 5.0, 6.0]]
    # subsampling keeps at most max_points, evenly
    assert cloud_xyz(msg, max_points=1).tolist() == [[1.0, 2.0, 0.5]]
