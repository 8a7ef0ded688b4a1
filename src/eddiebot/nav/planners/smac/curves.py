"""Dubins and Reeds-Shepp shortest paths (numba), as OMPL's ``DubinsStateSpace`` and
``ReedsSheppStateSpace`` compute them for ``nav2_smac_planner``.

A path is five segment kinds (``N`` none, ``L`` left arc, ``S`` straight, ``R`` right arc)
with signed lengths in units of the turning radius ``rho`` (negative: driven in reverse);
Dubins paths have three segments and never a negative length. :func:`curve_path` finds the
shortest one between two poses, :func:`curve_sample` gives the pose at a fraction of it.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

SEG_N = 0
SEG_L = 1
SEG_S = 2
SEG_R = 3

_PI = math.pi
_TWO_PI = 2.0 * math.pi
_EPS = 1e-6
_ZERO = 10.0 * 2.220446049250313e-16  # OMPL's Reeds-Shepp ZERO (10 machine epsilons)
_DUBINS_ZERO = -1e-7

# Reeds-Shepp path types (OMPL's reedsSheppPathType)
_RS_TYPES = np.array([
    [SEG_L, SEG_R, SEG_L, SEG_N, SEG_N],  # 0
    [SEG_R, SEG_L, SEG_R, SEG_N, SEG_N],  # 1
    [SEG_L, SEG_R, SEG_L, SEG_R, SEG_N],  # 2
    [SEG_R, SEG_L, SEG_R, SEG_L, SEG_N],  # 3
    [SEG_L, SEG_R, SEG_S, SEG_L, SEG_N],  # 4
    [SEG_R, SEG_L, SEG_S, SEG_R, SEG_N],  # 5
    [SEG_L, SEG_S, SEG_R, SEG_L, SEG_N],  # 6
    [SEG_R, SEG_S, SEG_L, SEG_R, SEG_N],  # 7
    [SEG_L, SEG_R, SEG_S, SEG_R, SEG_N],  # 8
    [SEG_R, SEG_L, SEG_S, SEG_L, SEG_N],  # 9
    [SEG_R, SEG_S, SEG_R, SEG_L, SEG_N],  # 10
    [SEG_L, SEG_S, SEG_L, SEG_R, SEG_N],  # 11
    [SEG_L, SEG_S, SEG_R, SEG_N, SEG_N],  # 12
    [SEG_R, SEG_S, SEG_L, SEG_N, SEG_N],  # 13
    [SEG_L, SEG_S, SEG_L, SEG_N, SEG_N],  # 14
    [SEG_R, SEG_S, SEG_R, SEG_N, SEG_N],  # 15
    [SEG_L, SEG_R, SEG_S, SEG_L, SEG_R],  # 16
    [SEG_R, SEG_L, SEG_S, SEG_R, SEG_L],  # 17
], dtype=np.int64)

# Dubins words LSL, RSR, RSL, LSR, RLR, LRL
_DUBINS_TYPES = np.array([
    [SEG_L, SEG_S, SEG_L, SEG_N, SEG_N],
    [SEG_R, SEG_S, SEG_R, SEG_N, SEG_N],
    [SEG_R, SEG_S, SEG_L, SEG_N, SEG_N],
    [SEG_L, SEG_S, SEG_R, SEG_N, SEG_N],
    [SEG_R, SEG_L, SEG_R, SEG_N, SEG_N],
    [SEG_L, SEG_R, SEG_L, SEG_N, SEG_N],
], dtype=np.int64)


@njit(cache=True)
def _mod2pi_signed(x: float) -> float:
    """Into (-pi, pi] (OMPL's Reeds-Shepp ``mod2pi``)."""
    v = np.fmod(x, _TWO_PI)
    if v < -_PI:
        v += _TWO_PI
    elif v > _PI:
        v -= _TWO_PI
    return v


@njit(cache=True)
def _mod2pi(x: float) -> float:
    """Into [0, 2 pi) (OMPL's Dubins ``mod2pi``)."""
    if x < 0.0 and x > _DUBINS_ZERO:
        return 0.0
    return x - _TWO_PI * math.floor(x / _TWO_PI)


@njit(cache=True)
def _polar(x: float, y: float) -> tuple[float, float]:
    return math.sqrt(x * x + y * y), math.atan2(y, x)


@njit(cache=True)
def _tau_omega(u: float, v: float, xi: float, eta: float, phi: float) -> tuple[float, float]:
    delta = _mod2pi_signed(u - v)
    a = math.sin(u) - math.sin(delta)
    b = math.cos(u) - math.cos(delta) - 1.0
    t1 = math.atan2(eta * a - xi * b, xi * a + eta * b)
    t2 = 2.0 * (math.cos(delta) - math.cos(v) - math.cos(u)) + 3.0
    tau = _mod2pi_signed(t1 + _PI) if t2 < 0 else _mod2pi_signed(t1)
    omega = _mod2pi_signed(tau - u + v - phi)
    return tau, omega


@njit(cache=True)
def _lp_sp_lp(x: float, y: float, phi: float) -> tuple[bool, float, float, float]:
    u, t = _polar(x - math.sin(phi), y - 1.0 + math.cos(phi))
    if t >= -_ZERO:
        v = _mod2pi_signed(phi - t)
        if v >= -_ZERO:
            return True, t, u, v
    return False, 0.0, 0.0, 0.0


@njit(cache=True)
def _lp_sp_rp(x: float, y: float, phi: float) -> tuple[bool, float, float, float]:
    u1, t1 = _polar(x + math.sin(phi), y - 1.0 - math.cos(phi))
    u1 = u1 * u1
    if u1 >= 4.0:
        u = math.sqrt(u1 - 4.0)
        theta = math.atan2(2.0, u)
        t = _mod2pi_signed(t1 + theta)
        v = _mod2pi_signed(t - phi)
        return t >= -_ZERO and v >= -_ZERO, t, u, v
    return False, 0.0, 0.0, 0.0


@njit(cache=True)
def _lp_rm_l(x: float, y: float, phi: float) -> tuple[bool, float, float, float]:
    xi = x - math.sin(phi)
    eta = y - 1.0 + math.cos(phi)
    u1, theta = _polar(xi, eta)
    if u1 <= 4.0:
        u = -2.0 * math.asin(0.25 * u1)
        t = _mod2pi_signed(theta + 0.5 * u + _PI)
        v = _mod2pi_signed(phi - t + u)
        return t >= -_ZERO and u <= _ZERO, t, u, v
    return False, 0.0, 0.0, 0.0


@njit(cache=True)
def _lp_rup_lum_rm(x: float, y: float, phi: float) -> tuple[bool, float, float, float]:
    xi = x + math.sin(phi)
    eta = y - 1.0 - math.cos(phi)
    rho = 0.25 * (2.0 + math.sqrt(xi * xi + eta * eta))
    if rho <= 1.0:
        u = math.acos(rho)
        t, v = _tau_omega(u, -u, xi, eta, phi)
        return t >= -_ZERO and v <= _ZERO, t, u, v
    return False, 0.0, 0.0, 0.0


@njit(cache=True)
def _lp_rum_lum_rp(x: float, y: float, phi: float) -> tuple[bool, float, float, float]:
    xi = x + math.sin(phi)
    eta = y - 1.0 - math.cos(phi)
    rho = (20.0 - xi * xi - eta * eta) / 16.0
    if 0.0 <= rho <= 1.0:
        u = -math.acos(rho)
        if u >= -0.5 * _PI:
            t, v = _tau_omega(u, u, xi, eta, phi)
            return t >= -_ZERO and v >= -_ZERO, t, u, v
    return False, 0.0, 0.0, 0.0


@njit(cache=True)
def _lp_rm_sm_lm(x: float, y: float, phi: float) -> tuple[bool, float, float, float]:
    xi = x - math.sin(phi)
    eta = y - 1.0 + math.cos(phi)
    rho, theta = _polar(xi, eta)
    if rho >= 2.0:
        r = math.sqrt(rho * rho - 4.0)
        u = 2.0 - r
        t = _mod2pi_signed(theta + math.atan2(r, -2.0))
        v = _mod2pi_signed(phi - 0.5 * _PI - t)
        return t >= -_ZERO and u <= _ZERO and v <= _ZERO, t, u, v
    return False, 0.0, 0.0, 0.0


@njit(cache=True)
def _lp_rm_sm_rm(x: float, y: float, phi: float) -> tuple[bool, float, float, float]:
    xi = x + math.sin(phi)
    eta = y - 1.0 - math.cos(phi)
    rho, theta = _polar(-eta, xi)
    if rho >= 2.0:
        t = theta
        u = 2.0 - rho
        v = _mod2pi_signed(t + 0.5 * _PI - phi)
        return t >= -_ZERO and u <= _ZERO and v <= _ZERO, t, u, v
    return False, 0.0, 0.0, 0.0


@njit(cache=True)
def _lp_rm_s_lm_rp(x: float, y: float, phi: float) -> tuple[bool, float, float, float]:
    xi = x + math.sin(phi)
    eta = y - 1.0 - math.cos(phi)
    rho, _theta = _polar(xi, eta)
    if rho >= 2.0:
        u = 4.0 - math.sqrt(rho * rho - 4.0)
        if u <= _ZERO:
            t = _mod2pi_signed(math.atan2((4.0 - u) * xi - 2.0 * eta, -2.0 * xi + (u - 4.0) * eta))
            v = _mod2pi_signed(t - phi)
            return t >= -_ZERO and v >= -_ZERO, t, u, v
    return False, 0.0, 0.0, 0.0


@njit(cache=True)
def _offer(best: np.ndarray, kind: int, a: float, b: float, c: float, d: float, e: float
           ) -> None:
    """Keep (kind, lengths) in ``best`` = [length, kind, l0..l4] if it is shorter."""
    total = abs(a) + abs(b) + abs(c) + abs(d) + abs(e)
    if total < best[0]:
        best[0] = total
        best[1] = kind
        best[2] = a
        best[3] = b
        best[4] = c
        best[5] = d
        best[6] = e


@njit(cache=True)
def _reeds_shepp(x: float, y: float, phi: float) -> np.ndarray:
    best = np.array([np.inf, -1.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    hp = 0.5 * _PI
    # CSC
    ok, t, u, v = _lp_sp_lp(x, y, phi)
    if ok:
        _offer(best, 14, t, u, v, 0.0, 0.0)
    ok, t, u, v = _lp_sp_lp(-x, y, -phi)
    if ok:
        _offer(best, 14, -t, -u, -v, 0.0, 0.0)
    ok, t, u, v = _lp_sp_lp(x, -y, -phi)
    if ok:
        _offer(best, 15, t, u, v, 0.0, 0.0)
    ok, t, u, v = _lp_sp_lp(-x, -y, phi)
    if ok:
        _offer(best, 15, -t, -u, -v, 0.0, 0.0)
    ok, t, u, v = _lp_sp_rp(x, y, phi)
    if ok:
        _offer(best, 12, t, u, v, 0.0, 0.0)
    ok, t, u, v = _lp_sp_rp(-x, y, -phi)
    if ok:
        _offer(best, 12, -t, -u, -v, 0.0, 0.0)
    ok, t, u, v = _lp_sp_rp(x, -y, -phi)
    if ok:
        _offer(best, 13, t, u, v, 0.0, 0.0)
    ok, t, u, v = _lp_sp_rp(-x, -y, phi)
    if ok:
        _offer(best, 13, -t, -u, -v, 0.0, 0.0)
    # CCC
    ok, t, u, v = _lp_rm_l(x, y, phi)
    if ok:
        _offer(best, 0, t, u, v, 0.0, 0.0)
    ok, t, u, v = _lp_rm_l(-x, y, -phi)
    if ok:
        _offer(best, 0, -t, -u, -v, 0.0, 0.0)
    ok, t, u, v = _lp_rm_l(x, -y, -phi)
    if ok:
        _offer(best, 1, t, u, v, 0.0, 0.0)
    ok, t, u, v = _lp_rm_l(-x, -y, phi)
    if ok:
        _offer(best, 1, -t, -u, -v, 0.0, 0.0)
    xb = x * math.cos(phi) + y * math.sin(phi)
    yb = x * math.sin(phi) - y * math.cos(phi)
    ok, t, u, v = _lp_rm_l(xb, yb, phi)
    if ok:
        _offer(best, 0, v, u, t, 0.0, 0.0)
    ok, t, u, v = _lp_rm_l(-xb, yb, -phi)
    if ok:
        _offer(best, 0, -v, -u, -t, 0.0, 0.0)
    ok, t, u, v = _lp_rm_l(xb, -yb, -phi)
    if ok:
        _offer(best, 1, v, u, t, 0.0, 0.0)
    ok, t, u, v = _lp_rm_l(-xb, -yb, phi)
    if ok:
        _offer(best, 1, -v, -u, -t, 0.0, 0.0)
    # CCCC
    ok, t, u, v = _lp_rup_lum_rm(x, y, phi)
    if ok:
        _offer(best, 2, t, u, -u, v, 0.0)
    ok, t, u, v = _lp_rup_lum_rm(-x, y, -phi)
    if ok:
        _offer(best, 2, -t, -u, u, -v, 0.0)
    ok, t, u, v = _lp_rup_lum_rm(x, -y, -phi)
    if ok:
        _offer(best, 3, t, u, -u, v, 0.0)
    ok, t, u, v = _lp_rup_lum_rm(-x, -y, phi)
    if ok:
        _offer(best, 3, -t, -u, u, -v, 0.0)
    ok, t, u, v = _lp_rum_lum_rp(x, y, phi)
    if ok:
        _offer(best, 2, t, u, u, v, 0.0)
    ok, t, u, v = _lp_rum_lum_rp(-x, y, -phi)
    if ok:
        _offer(best, 2, -t, -u, -u, -v, 0.0)
    ok, t, u, v = _lp_rum_lum_rp(x, -y, -phi)
    if ok:
        _offer(best, 3, t, u, u, v, 0.0)
    ok, t, u, v = _lp_rum_lum_rp(-x, -y, phi)
    if ok:
        _offer(best, 3, -t, -u, -u, -v, 0.0)
    # CCSC
    ok, t, u, v = _lp_rm_sm_lm(x, y, phi)
    if ok:
        _offer(best, 4, t, -hp, u, v, 0.0)
    ok, t, u, v = _lp_rm_sm_lm(-x, y, -phi)
    if ok:
        _offer(best, 4, -t, hp, -u, -v, 0.0)
    ok, t, u, v = _lp_rm_sm_lm(x, -y, -phi)
    if ok:
        _offer(best, 5, t, -hp, u, v, 0.0)
    ok, t, u, v = _lp_rm_sm_lm(-x, -y, phi)
    if ok:
        _offer(best, 5, -t, hp, -u, -v, 0.0)
    ok, t, u, v = _lp_rm_sm_rm(x, y, phi)
    if ok:
        _offer(best, 8, t, -hp, u, v, 0.0)
    ok, t, u, v = _lp_rm_sm_rm(-x, y, -phi)
    if ok:
        _offer(best, 8, -t, hp, -u, -v, 0.0)
    ok, t, u, v = _lp_rm_sm_rm(x, -y, -phi)
    if ok:
        _offer(best, 9, t, -hp, u, v, 0.0)
    ok, t, u, v = _lp_rm_sm_rm(-x, -y, phi)
    if ok:
        _offer(best, 9, -t, hp, -u, -v, 0.0)
    ok, t, u, v = _lp_rm_sm_lm(xb, yb, phi)
    if ok:
        _offer(best, 6, v, u, -hp, t, 0.0)
    ok, t, u, v = _lp_rm_sm_lm(-xb, yb, -phi)
    if ok:
        _offer(best, 6, -v, -u, hp, -t, 0.0)
    ok, t, u, v = _lp_rm_sm_lm(xb, -yb, -phi)
    if ok:
        _offer(best, 7, v, u, -hp, t, 0.0)
    ok, t, u, v = _lp_rm_sm_lm(-xb, -yb, phi)
    if ok:
        _offer(best, 7, -v, -u, hp, -t, 0.0)
    ok, t, u, v = _lp_rm_sm_rm(xb, yb, phi)
    if ok:
        _offer(best, 10, v, u, -hp, t, 0.0)
    ok, t, u, v = _lp_rm_sm_rm(-xb, yb, -phi)
    if ok:
        _offer(best, 10, -v, -u, hp, -t, 0.0)
    ok, t, u, v = _lp_rm_sm_rm(xb, -yb, -phi)
    if ok:
        _offer(best, 11, v, u, -hp, t, 0.0)
    ok, t, u, v = _lp_rm_sm_rm(-xb, -yb, phi)
    if ok:
        _offer(best, 11, -v, -u, hp, -t, 0.0)
    # CCSCC
    ok, t, u, v = _lp_rm_s_lm_rp(x, y, phi)
    if ok:
        _offer(best, 16, t, -hp, u, -hp, v)
    ok, t, u, v = _lp_rm_s_lm_rp(-x, y, -phi)
    if ok:
        _offer(best, 16, -t, hp, -u, hp, -v)
    ok, t, u, v = _lp_rm_s_lm_rp(x, -y, -phi)
    if ok:
        _offer(best, 17, t, -hp, u, -hp, v)
    ok, t, u, v = _lp_rm_s_lm_rp(-x, -y, phi)
    if ok:
        _offer(best, 17, -t, hp, -u, hp, -v)
    return best


@njit(cache=True)
def _dubins(d: float, alpha: float, beta: float) -> np.ndarray:
    best = np.array([np.inf, -1.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    if d < _EPS and abs(alpha - beta) < _EPS:
        _offer(best, 0, 0.0, d, 0.0, 0.0, 0.0)
        return best
    ca = math.cos(alpha)
    sa = math.sin(alpha)
    cb = math.cos(beta)
    sb = math.sin(beta)
    # LSL
    tmp = 2.0 + d * d - 2.0 * (ca * cb + sa * sb - d * (sa - sb))
    if tmp >= _DUBINS_ZERO:
        theta = math.atan2(cb - ca, d + sa - sb)
        _offer(best, 0, _mod2pi(-alpha + theta), math.sqrt(max(tmp, 0.0)),
               _mod2pi(beta - theta), 0.0, 0.0)
    # RSR
    tmp = 2.0 + d * d - 2.0 * (ca * cb + sa * sb - d * (sb - sa))
    if tmp >= _DUBINS_ZERO:
        theta = math.atan2(ca - cb, d - sa + sb)
        _offer(best, 1, _mod2pi(alpha - theta), math.sqrt(max(tmp, 0.0)),
               _mod2pi(-beta + theta), 0.0, 0.0)
    # RSL
    tmp = d * d - 2.0 + 2.0 * (ca * cb + sa * sb - d * (sa + sb))
    if tmp >= _DUBINS_ZERO:
        p = math.sqrt(max(tmp, 0.0))
        theta = math.atan2(ca + cb, d - sa - sb) - math.atan2(2.0, p)
        _offer(best, 2, _mod2pi(alpha - theta), p, _mod2pi(beta - theta), 0.0, 0.0)
    # LSR
    tmp = -2.0 + d * d + 2.0 * (ca * cb + sa * sb + d * (sa + sb))
    if tmp >= _DUBINS_ZERO:
        p = math.sqrt(max(tmp, 0.0))
        theta = math.atan2(-ca - cb, d + sa + sb) - math.atan2(-2.0, p)
        _offer(best, 3, _mod2pi(-alpha + theta), p, _mod2pi(-beta + theta), 0.0, 0.0)
    # RLR
    tmp = 0.125 * (6.0 - d * d + 2.0 * (ca * cb + sa * sb + d * (sa - sb)))
    if abs(tmp) < 1.0:
        p = _TWO_PI - math.acos(tmp)
        theta = math.atan2(ca - cb, d - sa + sb)
        t = _mod2pi(alpha - theta + 0.5 * p)
        _offer(best, 4, t, p, _mod2pi(alpha - beta - t + p), 0.0, 0.0)
    # LRL
    tmp = 0.125 * (6.0 - d * d + 2.0 * (ca * cb + sa * sb - d * (sa - sb)))
    if abs(tmp) < 1.0:
        p = _TWO_PI - math.acos(tmp)
        theta = math.atan2(-ca + cb, d + sa - sb)
        t = _mod2pi(-alpha + theta + 0.5 * p)
        _offer(best, 5, t, p, _mod2pi(beta - alpha - t + p), 0.0, 0.0)
    return best


@njit(cache=True)
def curve_path(x0: float, y0: float, th0: float, x1: float, y1: float, th1: float,
               rho: float, reeds_shepp: bool) -> tuple[np.ndarray, np.ndarray, float]:
    """Shortest Dubins (or Reeds-Shepp) path: (segment kinds (5,), signed lengths (5,) in
    units of ``rho``, total length in the units of the poses)."""
    dx = x1 - x0
    dy = y1 - y0
    if reeds_shepp:
        c = math.cos(th0)
        s = math.sin(th0)
        x = c * dx + s * dy
        y = -s * dx + c * dy
        best = _reeds_shepp(x / rho, y / rho, th1 - th0)
        kinds = _RS_TYPES[int(best[1])]
    else:
        d = math.sqrt(dx * dx + dy * dy) / rho
        th = math.atan2(dy, dx)
        best = _dubins(d, _mod2pi(th0 - th), _mod2pi(th1 - th))
        kinds = _DUBINS_TYPES[int(best[1])]
    return kinds.copy(), best[2:7].copy(), best[0] * rho


@njit(cache=True)
def curve_length(x0: float, y0: float, th0: float, x1: float, y1: float, th1: float,
                 rho: float, reeds_shepp: bool) -> float:
    return curve_path(x0, y0, th0, x1, y1, th1, rho, reeds_shepp)[2]


@njit(cache=True)
def curve_sample(x0: float, y0: float, th0: float, kinds: np.ndarray, lengths: np.ndarray,
                 rho: float, fraction: float) -> tuple[float, float, float, bool]:
    """Pose at ``fraction`` of the path's length, and whether it is driven in reverse there
    (OMPL's ``interpolate``)."""
    total = 0.0
    for i in range(5):
        total += abs(lengths[i])
    seg = fraction * total
    x = 0.0
    y = 0.0
    phi = th0
    reverse = False
    for i in range(5):
        if seg <= 0.0 or kinds[i] == SEG_N:
            break
        li = lengths[i]
        v = min(seg, abs(li))
        if li < 0.0:
            v = -v
            reverse = True
        else:
            reverse = False
        seg -= abs(li)
        k = kinds[i]
        if k == SEG_L:
            x += math.sin(phi + v) - math.sin(phi)
            y += -math.cos(phi + v) + math.cos(phi)
            phi += v
        elif k == SEG_R:
            x += -math.sin(phi - v) + math.sin(phi)
            y += math.cos(phi - v) - math.cos(phi)
            phi -= v
        else:
            x += v * math.cos(phi)
            y += v * math.sin(phi)
    return x0 + rho * x, y0 + rho * y, phi, reverse


__all__ = ["SEG_L", "SEG_N", "SEG_R", "SEG_S", "curve_length", "curve_path", "curve_sample"]
