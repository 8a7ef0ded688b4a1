"""Depth image → ``sensor_msgs/PointCloud2``, as depth_image_proc's point_cloud_xyz and
point_cloud_xyzrgb nodes build them.

Every pixel becomes a point in the depth image's optical frame (x right, y down, z forward,
metres): ``x = (u - cx)·z/fx``, ``y = (v - cy)·z/fy``; invalid depths (16UC1 zero, 32FC1
non-finite) give NaN points, so the cloud is organised (height × width) and
``is_dense = False``. Field layout as ``PointCloud2Modifier`` makes it: XYZ is three float32
at offsets 0, 4, 8 with a 16-byte point step; XYZRGB adds a packed float32 ``rgb`` at
offset 16 with a 32-byte point step. The XYZRGB form needs a depth image registered to the
RGB image (`eddiebot.perception.register_depth`), same size as the colour image.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from eddiebot.msgs.sensor_msgs import PointCloud2, PointField
from eddiebot.perception._image import DEPTH_ENCODINGS, check_size, image_to_array
from eddiebot.perception.errors import ImageSizeError

__all__ = ["depth_to_pointcloud2", "depth_to_pointcloud2_rgb", "depth_to_points"]

_FLOAT32 = 7


def depth_to_points(
    depth: npt.NDArray[Any], fx: float, fy: float, cx: float, cy: float, channels: int = 3
) -> npt.NDArray[np.float32]:
    """(H, W, 3) float32 points in the optical frame (m); NaN where the depth is invalid.
    With ``channels`` > 3 the extra channels are zero (padding for PointCloud2)."""
    if depth.dtype == np.uint16:
        z = depth.astype(np.float32) * np.float32(0.001)
        z[depth == 0] = np.nan
    else:
        z = depth.astype(np.float32, copy=True)
        z[~np.isfinite(z)] = np.nan
    h, w = depth.shape
    u = (np.arange(w, dtype=np.float32) - np.float32(cx)) / np.float32(fx)
    v = (np.arange(h, dtype=np.float32) - np.float32(cy)) / np.float32(fy)
    out = np.empty((h, w, channels), dtype=np.float32)
    if channels > 3:
        out[..., 3:] = 0.0
    out[..., 0] = z * u[None, :]
    out[..., 1] = z * v[:, None]
    out[..., 2] = z
    return out


def _intrinsics(camera_info: Any) -> tuple[float, float, float, float]:
    k = np.asarray(camera_info.k, dtype=np.float64)
    return float(k[0]), float(k[4]), float(k[2]), float(k[5])


def _field(name: str, offset: int) -> Any:
    return PointField(name=name, offset=offset, datatype=_FLOAT32, count=1)


def _cloud(header: Any, packed: npt.NDArray[Any], fields: list[Any]) -> Any:
    h, w = packed.shape[:2]
    step = packed[0, 0].nbytes
    return PointCloud2(
        header=header,
        height=h,
        width=w,
        fields=fields,
        is_bigendian=False,
        point_step=step,
        row_step=step * w,
        data=np.ascontiguousarray(packed).view(np.uint8).reshape(-1),
        is_dense=False,
    )


def depth_to_pointcloud2(depth_image: Any, camera_info: Any) -> Any:
    """XYZ ``PointCloud2`` from a depth ``Image`` (16UC1 or 32FC1) and its ``CameraInfo``."""
    check_size(depth_image, camera_info)
    depth = image_to_array(depth_image, DEPTH_ENCODINGS)
    packed = depth_to_points(depth, *_intrinsics(camera_info), channels=4)  # 16-byte points
    fields = [_field("x", 0), _field("y", 4), _field("z", 8)]
    return _cloud(depth_image.header, packed, fields)


def depth_to_pointcloud2_rgb(depth_image: Any, rgb_image: Any, camera_info: Any) -> Any:
    """XYZRGB ``PointCloud2`` from a depth image registered to ``rgb_image`` (rgb8 or bgr8),
    with the RGB camera's ``CameraInfo``. The header (and frame) is the RGB image's."""
    check_size(depth_image, camera_info)
    check_size(rgb_image, camera_info)
    depth = image_to_array(depth_image, DEPTH_ENCODINGS)
    rgb = image_to_array(rgb_image, ("rgb8", "bgr8"))
    if rgb.shape[:2] != depth.shape:
        raise ImageSizeError(f"depth image is {depth.shape[::-1]} but rgb image is "
                             f"{rgb.shape[1::-1]}")
    if rgb_image.encoding == "bgr8":
        rgb = rgb[..., ::-1]
    packed = depth_to_points(depth, *_intrinsics(camera_info), channels=8)  # 32-byte points
    r, g, b = (rgb[..., i].astype(np.uint32) for i in range(3))
    packed[..., 4] = ((r << 16) | (g << 8) | b).view(np.float32)
    fields = [_field("x", 0), _field("y", 4), _field("z", 8), _field("rgb", 16)]
    return _cloud(rgb_image.header, packed, fields)
