"""Small value types shared by the navigation cores.

Poses are float arrays ``(x, y, theta)`` in the costmap's global frame (m, rad); paths are
``(N, 3)`` arrays of such poses.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]


class Twist2D(NamedTuple):
    """Planar velocity in the robot frame: vx, vy (m/s), wz (rad/s)."""

    vx: float = 0.0
    vy: float = 0.0
    wz: float = 0.0

    def is_zero(self) -> bool:
        return self.vx == 0.0 and self.vy == 0.0 and self.wz == 0.0


def wrap_angle(a: float) -> float:
    """Angle wrapped to [-pi, pi)."""
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def as_pose(pose: npt.ArrayLike) -> FloatArray:
    p = np.asarray(pose, dtype=np.float64).reshape(-1)
    if p.shape[0] == 2:
        p = np.array([p[0], p[1], 0.0])
    return p[:3].copy()


def as_path(path: npt.ArrayLike) -> FloatArray:
    """Path as an (N, 3) float array; an (N, 2) input gets headings along its segments."""
    p = np.asarray(path, dtype=np.float64)
    if p.ndim != 2 or p.shape[0] == 0:
        return np.zeros((0, 3))
    if p.shape[1] >= 3:
        return np.ascontiguousarray(p[:, :3])
    out = np.zeros((p.shape[0], 3))
    out[:, :2] = p[:, :2]
    if p.shape[0] > 1:
        d = np.diff(p[:, :2], axis=0)
        yaw = np.arctan2(d[:, 1], d[:, 0])
        out[:-1, 2] = yaw
        out[-1, 2] = yaw[-1]
    return out


def path_length(path: npt.ArrayLike) -> float:
    p = np.asarray(path, dtype=np.float64)
    if p.shape[0] < 2:
        return 0.0
    return float(np.sum(np.hypot(np.diff(p[:, 0]), np.diff(p[:, 1]))))


__all__ = ["FloatArray", "Twist2D", "as_path", "as_pose", "path_length", "wrap_angle"]
