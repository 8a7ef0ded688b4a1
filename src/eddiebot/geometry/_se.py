"""Vectorised SE(2)/SE(3) functions.

SE(2) poses are float arrays of shape (..., 3) holding (x, y, theta) in metres and
radians; every function broadcasts over leading dimensions. Quaternions are (x, y, z, w)
as in geometry_msgs. SE(3) transforms are 4×4 homogeneous matrices.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]

__all__ = [
    "Pose2D",
    "matrix_to_quaternion",
    "matrix_to_se2",
    "quaternion_multiply",
    "quaternion_to_matrix",
    "quaternion_to_rpy",
    "quaternion_to_yaw",
    "rpy_to_quaternion",
    "se2_between",
    "se2_compose",
    "se2_interpolate",
    "se2_inverse",
    "se2_to_matrix",
    "se2_transform_points",
    "se3_from_tq",
    "se3_interpolate",
    "se3_inverse",
    "se3_to_tq",
    "se3_transform_points",
    "slerp",
    "wrap_angle",
    "yaw_to_quaternion",
]


def wrap_angle(angle: ArrayLike) -> FloatArray:
    """Wrap angles (rad) into (−π, π]."""
    a = np.asarray(angle, dtype=np.float64)
    wrapped = np.mod(a + np.pi, 2.0 * np.pi) - np.pi
    # mod maps +π to −π; the half-open interval keeps +π.
    return np.where(wrapped == -np.pi, np.pi, wrapped)


def _pose(p: ArrayLike) -> FloatArray:
    arr = np.asarray(p, dtype=np.float64)
    if arr.shape[-1] != 3:
        raise ValueError(f"SE(2) pose must have last dimension 3 (x, y, theta), got {arr.shape}")
    return arr


def se2_compose(a: ArrayLike, b: ArrayLike) -> FloatArray:
    """a ∘ b: the pose b expressed in a's parent frame."""
    pa, pb = _pose(a), _pose(b)
    c, s = np.cos(pa[..., 2]), np.sin(pa[..., 2])
    x = pa[..., 0] + c * pb[..., 0] - s * pb[..., 1]
    y = pa[..., 1] + s * pb[..., 0] + c * pb[..., 1]
    return np.stack([x, y, wrap_angle(pa[..., 2] + pb[..., 2])], axis=-1)


def se2_inverse(a: ArrayLike) -> FloatArray:
    """The inverse pose: a ∘ inv(a) = identity."""
    pa = _pose(a)
    c, s = np.cos(pa[..., 2]), np.sin(pa[..., 2])
    x = -c * pa[..., 0] - s * pa[..., 1]
    y = s * pa[..., 0] - c * pa[..., 1]
    return np.stack([x, y, wrap_angle(-pa[..., 2])], axis=-1)


def se2_between(a: ArrayLike, b: ArrayLike) -> FloatArray:
    """inv(a) ∘ b: b expressed in a's frame (the relative motion from a to b)."""
    return se2_compose(se2_inverse(a), b)


def se2_transform_points(pose: ArrayLike, points: ArrayLike) -> FloatArray:
    """Points (N, 2) in the pose's frame → the parent frame."""
    p = _pose(pose)
    pts = np.asarray(points, dtype=np.float64)
    c, s = math.cos(float(p[2])), math.sin(float(p[2]))
    out = np.empty_like(pts)
    out[..., 0] = p[0] + c * pts[..., 0] - s * pts[..., 1]
    out[..., 1] = p[1] + s * pts[..., 0] + c * pts[..., 1]
    return out


def se2_interpolate(a: ArrayLike, b: ArrayLike, t: float | ArrayLike) -> FloatArray:
    """Linear interpolation of position and shortest-arc interpolation of heading; t in [0, 1]."""
    pa, pb = _pose(a), _pose(b)
    tt = np.asarray(t, dtype=np.float64)
    xy = pa[..., :2] + (pb[..., :2] - pa[..., :2]) * tt[..., None]
    th = pa[..., 2] + wrap_angle(pb[..., 2] - pa[..., 2]) * tt
    return np.concatenate([xy, wrap_angle(th)[..., None]], axis=-1)


def se2_to_matrix(pose: ArrayLike) -> FloatArray:
    """(x, y, theta) → 3×3 homogeneous matrix."""
    p = _pose(pose)
    c, s = np.cos(p[..., 2]), np.sin(p[..., 2])
    m = np.zeros((*p.shape[:-1], 3, 3))
    m[..., 0, 0], m[..., 0, 1], m[..., 0, 2] = c, -s, p[..., 0]
    m[..., 1, 0], m[..., 1, 1], m[..., 1, 2] = s, c, p[..., 1]
    m[..., 2, 2] = 1.0
    return m


def matrix_to_se2(m: ArrayLike) -> FloatArray:
    """3×3 homogeneous matrix → (x, y, theta)."""
    mm = np.asarray(m, dtype=np.float64)
    return np.stack(
        [mm[..., 0, 2], mm[..., 1, 2], np.arctan2(mm[..., 1, 0], mm[..., 0, 0])], axis=-1
    )


def yaw_to_quaternion(yaw: float) -> tuple[float, float, float, float]:
    """Rotation about z by ``yaw`` rad → (x, y, z, w)."""
    half = 0.5 * yaw
    return (0.0, 0.0, math.sin(half), math.cos(half))


def quaternion_to_yaw(x: float, y: float, z: float, w: float) -> float:
    """Yaw (rad, rotation about z) of a quaternion (x, y, z, w)."""
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def rpy_to_quaternion(roll: float, pitch: float, yaw: float) -> tuple[float, float, float, float]:
    """Fixed-axis roll, pitch, yaw (URDF/tf2 convention: R = Rz(yaw)·Ry(pitch)·Rx(roll))."""
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return (
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
        cr * cp * cy + sr * sp * sy,
    )


def quaternion_to_rpy(x: float, y: float, z: float, w: float) -> tuple[float, float, float]:
    """Inverse of :func:`rpy_to_quaternion`."""
    roll = math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    sinp = max(-1.0, min(1.0, 2 * (w * y - z * x)))
    pitch = math.asin(sinp)
    yaw = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return roll, pitch, yaw


def quaternion_multiply(
    q1: ArrayLike, q2: ArrayLike
) -> FloatArray:
    """Hamilton product q1·q2 of (x, y, z, w) quaternions (broadcasts)."""
    a = np.asarray(q1, dtype=np.float64)
    b = np.asarray(q2, dtype=np.float64)
    x1, y1, z1, w1 = a[..., 0], a[..., 1], a[..., 2], a[..., 3]
    x2, y2, z2, w2 = b[..., 0], b[..., 1], b[..., 2], b[..., 3]
    return np.stack(
        [
            w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
            w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
        ],
        axis=-1,
    )


def quaternion_to_matrix(q: ArrayLike) -> FloatArray:
    """(x, y, z, w) → 3×3 rotation matrix (the quaternion is normalised first)."""
    qq = np.asarray(q, dtype=np.float64)
    qq = qq / np.linalg.norm(qq, axis=-1, keepdims=True)
    x, y, z, w = qq[..., 0], qq[..., 1], qq[..., 2], qq[..., 3]
    m = np.empty((*qq.shape[:-1], 3, 3))
    m[..., 0, 0] = 1 - 2 * (y * y + z * z)
    m[..., 0, 1] = 2 * (x * y - z * w)
    m[..., 0, 2] = 2 * (x * z + y * w)
    m[..., 1, 0] = 2 * (x * y + z * w)
    m[..., 1, 1] = 1 - 2 * (x * x + z * z)
    m[..., 1, 2] = 2 * (y * z - x * w)
    m[..., 2, 0] = 2 * (x * z - y * w)
    m[..., 2, 1] = 2 * (y * z + x * w)
    m[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return m


def matrix_to_quaternion(m: ArrayLike) -> FloatArray:
    """3×3 rotation matrix → (x, y, z, w) with w ≥ 0."""
    r = np.asarray(m, dtype=np.float64)[..., :3, :3]
    tr = r[0, 0] + r[1, 1] + r[2, 2]
    if tr > 0:
        s = math.sqrt(tr + 1.0) * 2
        q = [(r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s, 0.25 * s]
    elif r[0, 0] > r[1, 1] and r[0, 0] > r[2, 2]:
        s = math.sqrt(1.0 + r[0, 0] - r[1, 1] - r[2, 2]) * 2
        q = [0.25 * s, (r[0, 1] + r[1, 0]) / s, (r[0, 2] + r[2, 0]) / s, (r[2, 1] - r[1, 2]) / s]
    elif r[1, 1] > r[2, 2]:
        s = math.sqrt(1.0 + r[1, 1] - r[0, 0] - r[2, 2]) * 2
        q = [(r[0, 1] + r[1, 0]) / s, 0.25 * s, (r[1, 2] + r[2, 1]) / s, (r[0, 2] - r[2, 0]) / s]
    else:
        s = math.sqrt(1.0 + r[2, 2] - r[0, 0] - r[1, 1]) * 2
        q = [(r[0, 2] + r[2, 0]) / s, (r[1, 2] + r[2, 1]) / s, 0.25 * s, (r[1, 0] - r[0, 1]) / s]
    out = np.asarray(q)
    out /= np.linalg.norm(out)
    return -out if out[3] < 0 else out


def slerp(q0: ArrayLike, q1: ArrayLike, t: float) -> FloatArray:
    """Spherical linear interpolation between unit quaternions, shortest arc."""
    a = np.asarray(q0, dtype=np.float64)
    b = np.asarray(q1, dtype=np.float64)
    dot = float(np.dot(a, b))
    if dot < 0.0:
        b, dot = -b, -dot
    if dot > 0.9995:
        out = a + t * (b - a)
        return np.asarray(out / np.linalg.norm(out))
    theta = math.acos(dot)
    s = math.sin(theta)
    return np.asarray((math.sin((1 - t) * theta) * a + math.sin(t * theta) * b) / s)


def se3_from_tq(t: ArrayLike, q: ArrayLike) -> FloatArray:
    """Translation (3,) and quaternion (x, y, z, w) → 4×4 matrix."""
    m = np.eye(4)
    m[:3, :3] = quaternion_to_matrix(q)
    m[:3, 3] = np.asarray(t, dtype=np.float64)
    return m


def se3_to_tq(m: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """4×4 matrix → (translation (3,), quaternion (x, y, z, w))."""
    mm = np.asarray(m, dtype=np.float64)
    return mm[:3, 3].copy(), matrix_to_quaternion(mm[:3, :3])


def se3_inverse(m: ArrayLike) -> FloatArray:
    """Inverse of a rigid 4×4 transform."""
    mm = np.asarray(m, dtype=np.float64)
    out = np.eye(4)
    rt = mm[:3, :3].T
    out[:3, :3] = rt
    out[:3, 3] = -rt @ mm[:3, 3]
    return out


def se3_transform_points(m: ArrayLike, points: ArrayLike) -> FloatArray:
    """Points (N, 3) → m·points."""
    mm = np.asarray(m, dtype=np.float64)
    pts = np.asarray(points, dtype=np.float64)
    return np.asarray(pts @ mm[:3, :3].T + mm[:3, 3])


def se3_interpolate(a: ArrayLike, b: ArrayLike, t: float) -> FloatArray:
    """Interpolate two rigid transforms: linear in translation, slerp in rotation."""
    ta, qa = se3_to_tq(a)
    tb, qb = se3_to_tq(b)
    return se3_from_tq(ta + (tb - ta) * t, slerp(qa, qb, t))


class Pose2D(NamedTuple):
    """An immutable planar pose (x, y in m; theta in rad, CCW positive)."""

    x: float = 0.0
    y: float = 0.0
    theta: float = 0.0

    def as_array(self) -> FloatArray:
        return np.array([self.x, self.y, self.theta])

    @classmethod
    def from_array(cls, a: ArrayLike) -> Pose2D:
        arr = _pose(a)
        return cls(float(arr[0]), float(arr[1]), float(arr[2]))

    def compose(self, other: Pose2D) -> Pose2D:
        return Pose2D.from_array(se2_compose(self.as_array(), other.as_array()))

    def inverse(self) -> Pose2D:
        return Pose2D.from_array(se2_inverse(self.as_array()))

    def between(self, other: Pose2D) -> Pose2D:
        """``other`` expressed in this pose's frame."""
        return Pose2D.from_array(se2_between(self.as_array(), other.as_array()))

    def transform_point(self, px: float, py: float) -> tuple[float, float]:
        c, s = math.cos(self.theta), math.sin(self.theta)
        return (self.x + c * px - s * py, self.y + s * px + c * py)
