"""The Kinect v1 as the driver and the simulator both see it: its optical frames, its
factory intrinsics, and the builders of ``sensor_msgs/Image`` and ``CameraInfo`` messages
from arrays.

Intrinsics are the real Kinect's calibration as the original stack's kinect_ros2 ships it
(``cfg/calibration_rgb.yaml``, ``cfg/calibration_depth.yaml``; 640×480).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from eddiebot.msgs.builtin_interfaces import Time
from eddiebot.msgs.sensor_msgs import CameraInfo, Image
from eddiebot.msgs.std_msgs import Header

__all__ = [
    "DEPTH_OPTICAL_FRAME",
    "KINECT_DEPTH",
    "KINECT_RGB",
    "RGB_OPTICAL_FRAME",
    "CameraIntrinsics",
    "camera_info_msg",
    "depth_image_msg",
    "rgb_image_msg",
    "stamp_from_ns",
]

RGB_OPTICAL_FRAME = "camera_rgb_optical_frame"
DEPTH_OPTICAL_FRAME = "camera_depth_optical_frame"


@dataclass(frozen=True)
class CameraIntrinsics:
    """Pinhole intrinsics in pixels (ROS convention: pixel centres at integer coordinates)."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float

    def scaled(self, width: int, height: int) -> CameraIntrinsics:
        """The same camera at another resolution (focal lengths and centre scale with it)."""
        sx, sy = width / self.width, height / self.height
        return CameraIntrinsics(
            width, height, self.fx * sx, self.fy * sy,
            (self.cx + 0.5) * sx - 0.5, (self.cy + 0.5) * sy - 0.5,
        )

    @property
    def hfov(self) -> float:
        """Horizontal field of view (rad)."""
        return float(np.arctan(self.cx / self.fx) + np.arctan((self.width - 1 - self.cx) / self.fx))

    @property
    def vfov(self) -> float:
        """Vertical field of view (rad)."""
        return float(np.arctan(self.cy / self.fy) + np.arctan((self.height - 1 - self.cy) / self.fy))


KINECT_RGB = CameraIntrinsics(640, 480, 526.60717328, 526.60717328, 318.52510740, 241.18145973)
KINECT_DEPTH = CameraIntrinsics(640, 480, 587.04607160, 587.04607160, 317.39001517, 234.30080720)


def stamp_from_ns(stamp_ns: int) -> Any:
    """``builtin_interfaces/Time`` from integer nanoseconds."""
    return Time(sec=int(stamp_ns // 1_000_000_000), nanosec=int(stamp_ns % 1_000_000_000))


def camera_info_msg(intr: CameraIntrinsics, stamp_ns: int = 0, frame_id: str = DEPTH_OPTICAL_FRAME) -> Any:
    """``CameraInfo`` of an ideal pinhole (plumb_bob, D = 0, R = I, P = [K | 0])."""
    k = np.array([intr.fx, 0.0, intr.cx, 0.0, intr.fy, intr.cy, 0.0, 0.0, 1.0])
    p = np.array([intr.fx, 0.0, intr.cx, 0.0, 0.0, intr.fy, intr.cy, 0.0, 0.0, 0.0, 1.0, 0.0])
    return CameraInfo(
        header=Header(stamp=stamp_from_ns(stamp_ns), frame_id=frame_id),
        height=intr.height,
        width=intr.width,
        distortion_model="plumb_bob",
        d=np.zeros(5),
        k=k,
        r=np.eye(3).reshape(-1),
        p=p,
    )


def _image(arr: npt.NDArray[Any], encoding: str, stamp_ns: int, frame_id: str) -> Any:
    arr = np.ascontiguousarray(arr)
    h, w = arr.shape[:2]
    return Image(
        header=Header(stamp=stamp_from_ns(stamp_ns), frame_id=frame_id),
        height=h,
        width=w,
        encoding=encoding,
        is_bigendian=0,
        step=arr.strides[0],
        data=arr.view(np.uint8).reshape(-1),
    )


def rgb_image_msg(rgb: npt.NDArray[np.uint8], stamp_ns: int = 0, frame_id: str = RGB_OPTICAL_FRAME) -> Any:
    """rgb8 ``Image`` from an (H, W, 3) uint8 array."""
    if rgb.dtype != np.uint8 or rgb.ndim != 3 or rgb.shape[2] != 3:
        raise ValueError(f"rgb8 needs an (H, W, 3) uint8 array, got {rgb.shape} {rgb.dtype}")
    return _image(rgb, "rgb8", stamp_ns, frame_id)


def depth_image_msg(depth: npt.NDArray[Any], stamp_ns: int = 0, frame_id: str = DEPTH_OPTICAL_FRAME) -> Any:
    """16UC1 (uint16 mm) or 32FC1 (float32 m) ``Image`` from an (H, W) array."""
    if depth.ndim != 2:
        raise ValueError(f"depth needs an (H, W) array, got shape {depth.shape}")
    if depth.dtype == np.uint16:
        return _image(depth, "16UC1", stamp_ns, frame_id)
    if depth.dtype == np.float32:
        return _image(depth, "32FC1", stamp_ns, frame_id)
    raise ValueError(f"depth must be uint16 (mm) or float32 (m), got {depth.dtype}")
