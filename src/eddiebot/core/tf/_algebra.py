"""Rigid transforms as 7-tuples ``(tx, ty, tz, qx, qy, qz, qw)``, ``p_parent = R(q) p_child + t``:
compose, invert and interpolate (linear in translation, slerp in rotation) in pure Python,
faster than numpy for single poses."""

from __future__ import annotations

import math
from collections.abc import Sequence

# A transform is (tx, ty, tz, qx, qy, qz, qw): p_parent = R(q) p_child + t.
_Tf = tuple[float, float, float, float, float, float, float]
_IDENTITY: _Tf = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)


def _qmul(ax: float, ay: float, az: float, aw: float,
          bx: float, by: float, bz: float, bw: float) -> tuple[float, float, float, float]:
    return (
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    )


def _qrot(qx: float, qy: float, qz: float, qw: float,
          vx: float, vy: float, vz: float) -> tuple[float, float, float]:
    # v' = v + 2w (q×v) + 2 q×(q×v)
    cx = qy * vz - qz * vy
    cy = qz * vx - qx * vz
    cz = qx * vy - qy * vx
    return (
        vx + 2.0 * (qw * cx + qy * cz - qz * cy),
        vy + 2.0 * (qw * cy + qz * cx - qx * cz),
        vz + 2.0 * (qw * cz + qx * cy - qy * cx),
    )


def _compose(a: _Tf, b: _Tf) -> _Tf:
    """a ∘ b: first b, then a."""
    rx, ry, rz = _qrot(a[3], a[4], a[5], a[6], b[0], b[1], b[2])
    q = _qmul(a[3], a[4], a[5], a[6], b[3], b[4], b[5], b[6])
    return (a[0] + rx, a[1] + ry, a[2] + rz, q[0], q[1], q[2], q[3])


def _inverse(a: _Tf) -> _Tf:
    ix, iy, iz, iw = -a[3], -a[4], -a[5], a[6]
    tx, ty, tz = _qrot(ix, iy, iz, iw, a[0], a[1], a[2])
    return (-tx, -ty, -tz, ix, iy, iz, iw)


def _slerp(a: Sequence[float], b: Sequence[float], t: float) -> tuple[float, float, float, float]:
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    dot = ax * bx + ay * by + az * bz + aw * bw
    if dot < 0.0:
        bx, by, bz, bw, dot = -bx, -by, -bz, -bw, -dot
    if dot > 0.9995:
        s0, s1 = 1.0 - t, t
    else:
        theta = math.acos(min(1.0, dot))
        s = math.sin(theta)
        s0, s1 = math.sin((1.0 - t) * theta) / s, math.sin(t * theta) / s
    x, y, z, w = s0 * ax + s1 * bx, s0 * ay + s1 * by, s0 * az + s1 * bz, s0 * aw + s1 * bw
    n = math.sqrt(x * x + y * y + z * z + w * w)
    return x / n, y / n, z / n, w / n


def _interpolate(a: _Tf, b: _Tf, t: float) -> _Tf:
    q = _slerp(a[3:], b[3:], t)
    return (
        a[0] + (b[0] - a[0]) * t,
        a[1] + (b[1] - a[1]) * t,
        a[2] + (b[2] - a[2]) * t,
        q[0], q[1], q[2], q[3],
    )
