"""Pinhole camera model of a registered RGB-D frame and depth unit handling."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from eddiebot.vslam.transforms import OPTICAL_ROTATION

__all__ = ["CameraIntrinsics", "depth_to_meters"]


@dataclass(frozen=True)
class CameraIntrinsics:
    """Rectified pinhole model of the RGB camera (depth is registered to it).

    `local_transform` is the camera optical frame's pose in the robot base frame (4×4, m);
    the default puts the camera at the base origin looking along +x.
    """

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int
    local_transform: NDArray[np.float64] = field(default_factory=lambda: OPTICAL_ROTATION.copy())

    @property
    def matrix(self) -> NDArray[np.float64]:
        """3×3 intrinsic matrix K."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @classmethod
    def from_k(
        cls,
        k: NDArray[np.float64] | list[float],
        width: int,
        height: int,
        local_transform: NDArray[np.float64] | None = None,
    ) -> CameraIntrinsics:
        """From a row-major 3×3 K (sensor_msgs/CameraInfo ``k``)."""
        kk = np.asarray(k, dtype=np.float64).reshape(3, 3)
        lt = OPTICAL_ROTATION.copy() if local_transform is None else np.asarray(local_transform)
        return cls(float(kk[0, 0]), float(kk[1, 1]), float(kk[0, 2]), float(kk[1, 2]),
                   int(width), int(height), lt)

    def scaled(self, factor: float) -> CameraIntrinsics:
        """The model for an image resized by `factor`."""
        return CameraIntrinsics(
            self.fx * factor, self.fy * factor, self.cx * factor, self.cy * factor,
            round(self.width * factor), round(self.height * factor), self.local_transform,
        )


def depth_to_meters(depth: NDArray[np.generic]) -> NDArray[np.float32]:
    """Depth image as float32 metres: uint16 is millimetres (16UC1), floats are metres; 0/NaN = none."""
    if depth.dtype == np.uint16:
        return depth.astype(np.float32) * np.float32(0.001)
    out = depth.astype(np.float32, copy=True)
    out[~np.isfinite(out)] = 0.0
    return out
