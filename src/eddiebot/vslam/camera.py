"""Pinhole camera model of a registered RGB-D frame and depth unit handling."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from eddiebot.vslam.errors import DepthScaleError
from eddiebot.vslam.transforms import OPTICAL_ROTATION

__all__ = [
    "PLAUSIBLE_MEDIAN_DEPTH_M",
    "CameraIntrinsics",
    "camera_info_from_yaml",
    "check_depth_plausible",
    "depth_to_meters",
]

#: Median valid depth (m) of an indoor RGB-D frame read with the right units per metre.
PLAUSIBLE_MEDIAN_DEPTH_M = (0.3, 10.0)


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


def camera_info_from_yaml(data: Mapping[str, Any]) -> CameraIntrinsics:
    """Intrinsics from a parsed ROS camera_info YAML: camera_calibration_parsers' layout
    (``image_width``, ``image_height``, ``camera_matrix: {data: [9]}``) or a
    sensor_msgs/CameraInfo dump (``width``, ``height``, ``k: [9]``)."""
    try:
        if "camera_matrix" in data:
            matrix = data["camera_matrix"]
            k = matrix["data"] if isinstance(matrix, Mapping) else matrix
            width, height = data["image_width"], data["image_height"]
        else:
            k = data.get("k", data.get("K"))
            width, height = data["width"], data["height"]
        kk = np.asarray(k, dtype=np.float64).reshape(3, 3)
    except (KeyError, TypeError, ValueError) as exc:
        raise ValueError(f"not a ROS camera_info YAML ({exc!r}): expected image_width, "
                         "image_height and camera_matrix.data (or width, height and k)") from exc
    if kk[0, 0] <= 0 or kk[1, 1] <= 0:
        raise ValueError(f"camera_info has non-positive focal lengths {kk[0, 0]}, {kk[1, 1]}")
    return CameraIntrinsics.from_k(kk.ravel(), int(width), int(height))


def check_depth_plausible(depth_m: NDArray[np.floating[Any]], depth_scale: float,
                          hint: str = "") -> float:
    """Median valid depth (m) of a frame converted with `depth_scale` units per metre; raises
    `DepthScaleError` when it lies outside `PLAUSIBLE_MEDIAN_DEPTH_M` (a wrong scale puts an
    indoor scene at centimetres or kilometres). `hint` ends the message (what to change)."""
    d = np.asarray(depth_m, dtype=np.float64)
    valid = d[np.isfinite(d) & (d > 0)]
    if valid.size == 0:
        raise DepthScaleError("the first depth image has no valid pixel")
    median = float(np.median(valid))
    lo, hi = PLAUSIBLE_MEDIAN_DEPTH_M
    if not lo <= median <= hi:
        raise DepthScaleError(
            f"median valid depth is {median:.3g} m at {depth_scale:g} units per metre, outside "
            f"the plausible {lo:g}-{hi:g} m: the depth scale is wrong{'; ' + hint if hint else ''}")
    return median
