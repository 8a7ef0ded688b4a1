"""Small SE(3) helpers for 4×4 homogeneous transforms (m, rad), used across the package."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "OPTICAL_ROTATION",
    "fit_rigid",
    "from_xyz_rpy",
    "from_xyz_yaw",
    "is_3dof",
    "rotation_angle",
    "se3_inverse",
    "to_3dof",
    "xyz_rpy",
    "yaw_of",
]

F64 = NDArray[np.float64]

# Base frame (x forward, y left, z up) → camera optical frame (z forward, x right, y down).
OPTICAL_ROTATION: F64 = np.array(
    [[0.0, 0.0, 1.0, 0.0], [-1.0, 0.0, 0.0, 0.0], [0.0, -1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]]
)


def se3_inverse(t: F64) -> F64:
    """Inverse of a rigid 4×4 transform."""
    out = np.eye(4)
    r = t[:3, :3]
    out[:3, :3] = r.T
    out[:3, 3] = -r.T @ t[:3, 3]
    return out


def xyz_rpy(t: F64) -> tuple[float, float, float, float, float, float]:
    """(x, y, z, roll, pitch, yaw) with ZYX Euler angles."""
    r = t[:3, :3]
    yaw = float(np.arctan2(r[1, 0], r[0, 0]))
    pitch = float(np.arctan2(-r[2, 0], np.hypot(r[2, 1], r[2, 2])))
    roll = float(np.arctan2(r[2, 1], r[2, 2]))
    return float(t[0, 3]), float(t[1, 3]), float(t[2, 3]), roll, pitch, yaw


def from_xyz_rpy(x: float, y: float, z: float, roll: float, pitch: float, yaw: float) -> F64:
    """4×4 transform from translation and ZYX Euler angles."""
    cr, sr, cp, sp, cy, sy = (
        np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch), np.cos(yaw), np.sin(yaw)
    )
    t = np.eye(4)
    t[:3, :3] = np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )
    t[:3, 3] = (x, y, z)
    return t


def from_xyz_yaw(x: float, y: float, yaw: float) -> F64:
    """Planar pose as a 4×4 transform."""
    return from_xyz_rpy(x, y, 0.0, 0.0, 0.0, yaw)


def yaw_of(t: F64) -> float:
    """ZYX yaw of a transform, rad."""
    return float(np.arctan2(t[1, 0], t[0, 0]))


def to_3dof(t: F64) -> F64:
    """RTAB-Map's "to 3DoF": keep x, y and the ZYX yaw; z = roll = pitch = 0."""
    return from_xyz_yaw(float(t[0, 3]), float(t[1, 3]), yaw_of(t))


def is_3dof(t: F64, tol: float = 1e-9) -> bool:
    """True when the transform has no z, roll or pitch."""
    r = t[:3, :3]
    return bool(
        abs(r[0, 2]) < tol
        and abs(r[1, 2]) < tol
        and abs(r[2, 0]) < tol
        and abs(r[2, 1]) < tol
        and abs(r[2, 2] - 1.0) < tol
        and abs(t[2, 3]) < tol
    )


def rotation_angle(t: F64) -> float:
    """Angle of the rotation part, rad in [0, π]."""
    c = (np.trace(t[:3, :3]) - 1.0) / 2.0
    return float(np.arccos(np.clip(c, -1.0, 1.0)))


def fit_rigid(from_points: F64, to_points: F64, weights: F64, three_dof: bool) -> F64:
    """Weighted least-squares rigid transform T with from ≈ T · to (Kabsch; in the plane with
    `three_dof`, z carried over)."""
    w = weights / weights.sum()
    dims = 2 if three_dof else 3
    a, b = to_points[:, :dims], from_points[:, :dims]
    ca, cb = w @ a, w @ b
    h = ((a - ca) * w[:, None]).T @ (b - cb)
    u, _, vt = np.linalg.svd(h)
    d = np.eye(dims)
    d[-1, -1] = np.sign(np.linalg.det(vt.T @ u.T))
    rot = vt.T @ d @ u.T
    t = np.eye(4)
    t[:dims, :dims] = rot
    t[:dims, 3] = cb - rot @ ca
    if three_dof:
        t[2, 3] = float(w @ (from_points[:, 2] - to_points[:, 2]))
    return t
