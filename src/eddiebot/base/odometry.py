"""Differential-drive wheel odometry (pure core).

Integrates left/right wheel travel into a planar pose in the ``odom`` frame by exact arc
integration (second-order Runge–Kutta, i.e. the midpoint heading, when the turn is tiny
— diff_drive_controller's rule), keeps the heading in (−π, π], propagates a covariance from
the encoder's quantisation, and estimates the body-frame twist as a rolling mean over the
last ``velocity_rolling_window_size`` samples (one count per 50 ms is 0.27 m/s, so a
per-sample twist would be noise).

Samples are absolute wheel angles (rad) with the time they were measured. Duplicate or
out-of-order samples are ignored; a counter reset (driver restart) re-baselines without
moving the pose.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from eddiebot.geometry import wrap_angle
from eddiebot.robot.constants import POSITIONS_PER_REV, TRACK_M, WHEEL_RADIUS_M

__all__ = ["DiffDriveOdometry", "OdometryConfig", "OdometryState", "integrate_arc"]

#: |dθ| below which the arc formula is replaced by the midpoint rule (diff_drive_controller).
_SMALL_TURN = 1e-6


@dataclass(frozen=True)
class OdometryConfig:
    """diff_drive_controller's parameter names; Eddie's values as defaults."""

    wheel_separation: float = TRACK_M
    wheel_radius: float = WHEEL_RADIUS_M
    #: calibration factors (UMBmark), as diff_drive_controller's
    wheel_separation_multiplier: float = 1.0
    left_wheel_radius_multiplier: float = 1.0
    right_wheel_radius_multiplier: float = 1.0
    #: encoder positions per wheel revolution (for the quantisation noise model)
    counts_per_rev: int = POSITIONS_PER_REV
    velocity_rolling_window_size: int = 10
    #: extra wheel-travel noise as a fraction of the distance travelled (slip), 1σ
    wheel_slip_fraction: float = 0.01
    #: a jump of wheel travel faster than this (m/s) is taken as a counter reset
    max_plausible_wheel_speed: float = 5.0

    def __post_init__(self) -> None:
        if self.wheel_separation <= 0 or self.wheel_radius <= 0:
            raise ValueError("wheel_separation and wheel_radius must be positive")
        if min(self.wheel_separation_multiplier, self.left_wheel_radius_multiplier,
               self.right_wheel_radius_multiplier) <= 0:
            raise ValueError("calibration multipliers must be positive")
        if self.velocity_rolling_window_size < 1:
            raise ValueError("velocity_rolling_window_size must be >= 1")

    @property
    def separation(self) -> float:
        """The effective wheel separation (m) after calibration."""
        return self.wheel_separation * self.wheel_separation_multiplier

    @property
    def metres_per_count(self) -> float:
        return 2.0 * math.pi * self.wheel_radius / self.counts_per_rev


@dataclass(frozen=True)
class OdometryState:
    """Pose in ``odom`` (m, rad), body-frame twist (m/s, rad/s) and their covariances."""

    stamp_ns: int
    x: float
    y: float
    theta: float
    linear: float
    angular: float
    pose_covariance: np.ndarray = field(repr=False)  # 3×3 over (x, y, θ)
    twist_covariance: np.ndarray = field(repr=False)  # 2×2 over (v, ω)


def integrate_arc(
    x: float, y: float, theta: float, d_left: float, d_right: float, separation: float
) -> tuple[float, float, float]:
    """Move a pose by the wheel travels ``d_left``, ``d_right`` (m) along a circular arc."""
    ds = 0.5 * (d_left + d_right)
    dth = (d_right - d_left) / separation
    if abs(dth) < _SMALL_TURN:
        mid = theta + 0.5 * dth
        x += ds * math.cos(mid)
        y += ds * math.sin(mid)
    else:
        r = ds / dth
        x += r * (math.sin(theta + dth) - math.sin(theta))
        y -= r * (math.cos(theta + dth) - math.cos(theta))
    return x, y, float(wrap_angle(theta + dth))


class DiffDriveOdometry:
    """Stateful integrator; feed it ``update(left_rad, right_rad, stamp_ns)``."""

    def __init__(self, config: OdometryConfig | None = None) -> None:
        self.config = config or OdometryConfig()
        self.resets = 0
        self.reset()

    def reset(self, x: float = 0.0, y: float = 0.0, theta: float = 0.0) -> None:
        """Start again at a pose; the next sample only sets the baseline."""
        self.x, self.y, self.theta = x, y, float(wrap_angle(theta))
        self._cov = np.zeros((3, 3))
        self._last: tuple[float, float, int] | None = None
        self._window: deque[tuple[float, float, float]] = deque(
            maxlen=self.config.velocity_rolling_window_size
        )
        self._state: OdometryState | None = None

    @property
    def state(self) -> OdometryState | None:
        return self._state

    def update(self, left_rad: float, right_rad: float, stamp_ns: int) -> OdometryState | None:
        """Integrate one sample of absolute wheel angles; None if it was only a baseline
        or was ignored (duplicate, out of order)."""
        cfg = self.config
        if self._last is None:
            self._last = (left_rad, right_rad, stamp_ns)
            return None
        last_l, last_r, last_t = self._last
        if stamp_ns <= last_t:
            return None  # repeated or out-of-order sample
        dt = (stamp_ns - last_t) * 1e-9
        d_left = (left_rad - last_l) * cfg.wheel_radius * cfg.left_wheel_radius_multiplier
        d_right = (right_rad - last_r) * cfg.wheel_radius * cfg.right_wheel_radius_multiplier
        self._last = (left_rad, right_rad, stamp_ns)
        limit = cfg.max_plausible_wheel_speed * dt + 2 * cfg.metres_per_count
        if abs(d_left) > limit or abs(d_right) > limit:
            # the counters restarted (driver or board reset): keep the pose, new baseline
            self.resets += 1
            self._window.clear()
            return None
        theta0 = self.theta
        self.x, self.y, self.theta = integrate_arc(
            self.x, self.y, self.theta, d_left, d_right, cfg.separation
        )
        self._propagate_covariance(theta0, d_left, d_right)
        self._window.append((0.5 * (d_left + d_right), (d_right - d_left) / cfg.separation, dt))
        self._state = self._make_state(stamp_ns)
        return self._state

    def _propagate_covariance(self, theta: float, d_left: float, d_right: float) -> None:
        cfg = self.config
        b = cfg.separation
        ds = 0.5 * (d_left + d_right)
        dth = (d_right - d_left) / b
        mid = theta + 0.5 * dth
        c, s = math.cos(mid), math.sin(mid)
        # Jacobians of the midpoint model w.r.t. the pose and the two wheel travels
        f = np.array([[1.0, 0.0, -ds * s], [0.0, 1.0, ds * c], [0.0, 0.0, 1.0]])
        g = np.array(
            [
                [0.5 * c + ds * s / (2 * b), 0.5 * c - ds * s / (2 * b)],
                [0.5 * s - ds * c / (2 * b), 0.5 * s + ds * c / (2 * b)],
                [-1.0 / b, 1.0 / b],
            ]
        )
        q_res = cfg.metres_per_count**2 / 12.0  # uniform quantisation of one count
        q = np.diag(
            [
                q_res + (cfg.wheel_slip_fraction * d_left) ** 2,
                q_res + (cfg.wheel_slip_fraction * d_right) ** 2,
            ]
        )
        if d_left == 0.0 and d_right == 0.0:
            return  # standing still adds no uncertainty
        self._cov = f @ self._cov @ f.T + g @ q @ g.T

    def _make_state(self, stamp_ns: int) -> OdometryState:
        cfg = self.config
        total_dt = sum(w[2] for w in self._window)
        linear = sum(w[0] for w in self._window) / total_dt
        angular = sum(w[1] for w in self._window) / total_dt
        # a rolling mean over the window's span: quantisation of ±1 count at both ends
        sv = cfg.metres_per_count / math.sqrt(6.0) / total_dt
        sw = 2.0 * sv / cfg.separation
        return OdometryState(
            stamp_ns,
            self.x,
            self.y,
            self.theta,
            linear,
            angular,
            self._cov.copy(),
            np.diag([sv * sv, sw * sw]),
        )
