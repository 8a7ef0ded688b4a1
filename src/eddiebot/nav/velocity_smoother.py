"""Nav2 velocity smoother core (``nav2_velocity_smoother``), one timer tick at a time.

The two step functions reproduce ``findEtaConstraint`` and ``applyConstraints`` bit for bit:
``accel >= 0`` and ``decel <= 0`` (m/s² or rad/s²), steps sized with the *nominal*
``smoothing_frequency``. :class:`VelocitySmoother` runs the timer body: timeout ramp-down,
OPEN_LOOP / CLOSED_LOOP current velocity, per-axis clamp, common scale factor, deadband.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from enum import Enum

from eddiebot.nav.errors import ParameterError
from eddiebot.nav.params import require
from eddiebot.nav.types import Twist2D


class Feedback(str, Enum):
    OPEN_LOOP = "OPEN_LOOP"
    CLOSED_LOOP = "CLOSED_LOOP"


@dataclass(frozen=True)
class VelocitySmootherConfig:
    """``velocity_smoother`` parameters with the Jazzy node's code defaults; axes [vx, vy, wz]."""

    smoothing_frequency: float = 20.0
    feedback: str = "OPEN_LOOP"
    scale_velocities: bool = False
    max_velocity: tuple[float, ...] = (0.5, 0.0, 2.5)
    min_velocity: tuple[float, ...] = (-0.5, 0.0, -2.5)
    max_accel: tuple[float, ...] = (2.5, 0.0, 3.2)
    max_decel: tuple[float, ...] = (-2.5, 0.0, -3.2)
    deadband_velocity: tuple[float, ...] = (0.0, 0.0, 0.0)
    velocity_timeout: float = 1.0
    odom_topic: str = "odom"
    odom_duration: float = 0.1
    use_realtime_priority: bool = False
    stamp_smoothed_velocity_with_smoothing_time: bool = False
    enable_stamped_cmd_vel: bool = False

    def validate(self, server: str = "velocity_smoother") -> None:
        require(self.smoothing_frequency > 0.0, server, "smoothing_frequency",
                self.smoothing_frequency, "must be > 0")
        require(self.feedback in ("OPEN_LOOP", "CLOSED_LOOP"), server, "feedback", self.feedback,
                "must be OPEN_LOOP or CLOSED_LOOP")
        require(self.velocity_timeout >= 0.0, server, "velocity_timeout", self.velocity_timeout,
                "must be >= 0")
        require(self.odom_duration >= 0.0, server, "odom_duration", self.odom_duration,
                "must be >= 0")
        arrays = {
            "max_velocity": self.max_velocity,
            "min_velocity": self.min_velocity,
            "max_accel": self.max_accel,
            "max_decel": self.max_decel,
            "deadband_velocity": self.deadband_velocity,
        }
        for key, arr in arrays.items():
            require(len(arr) == 3, server, key, list(arr), "must have 3 entries [vx, vy, wz]")
        for i in range(3):
            require(self.max_decel[i] <= 0.0, server, "max_decel", list(self.max_decel),
                    "entries must be <= 0 (signed deceleration)")
            require(self.max_accel[i] >= 0.0, server, "max_accel", list(self.max_accel),
                    "entries must be >= 0")
            require(self.min_velocity[i] <= 0.0, server, "min_velocity", list(self.min_velocity),
                    "entries must be <= 0")
            require(self.max_velocity[i] >= 0.0, server, "max_velocity", list(self.max_velocity),
                    "entries must be >= 0")
            require(self.min_velocity[i] <= self.max_velocity[i], server, "min_velocity",
                    list(self.min_velocity), "must not exceed max_velocity")


def timing_warnings(
    config: VelocitySmootherConfig, stale_command_timeout: float | None = None
) -> list[str]:
    """Warnings about timing that upstream accepts silently.

    A smoothing period longer than a downstream stale-command timeout (e.g. the mux's or the
    board's) means the robot stops between every two smoothed commands; the report's
    ``smoothing_frequency: 0.1`` is such a case (one command every 10 s).
    """
    out: list[str] = []
    period = 1.0 / config.smoothing_frequency
    if stale_command_timeout is not None and period > stale_command_timeout:
        out.append(
            f"velocity_smoother: 1/smoothing_frequency = {period:.3g} s exceeds the stale-command "
            f"timeout {stale_command_timeout:.3g} s: commands expire between ticks"
        )
    if period > config.velocity_timeout > 0.0:
        out.append(
            f"velocity_smoother: 1/smoothing_frequency = {period:.3g} s exceeds velocity_timeout "
            f"{config.velocity_timeout:.3g} s: every command times out before the next tick"
        )
    return out


def _band(v_curr: float, v_cmd: float, accel: float, decel: float, f: float) -> tuple[float, float]:
    if abs(v_cmd) >= abs(v_curr) and v_curr * v_cmd >= 0.0:
        return -accel / f, accel / f
    return decel / f, -decel / f


def find_eta_constraint(
    v_curr: float, v_cmd: float, accel: float, decel: float, smoothing_frequency: float
) -> float:
    """Scale factor that brings this axis onto its step limit, or -1.0 if already feasible."""
    dv = v_cmd - v_curr
    v_min, v_max = _band(v_curr, v_cmd, accel, decel, smoothing_frequency)
    if dv > v_max:
        return v_max / dv
    if dv < v_min:
        return v_min / dv
    return -1.0


def apply_constraints(
    v_curr: float, v_cmd: float, accel: float, decel: float, eta: float,
    smoothing_frequency: float,
) -> float:
    """One tick's velocity on one axis: ``v_curr + clamp(eta * dv, band)``."""
    dv = v_cmd - v_curr
    v_min, v_max = _band(v_curr, v_cmd, accel, decel, smoothing_frequency)
    return v_curr + min(max(eta * dv, v_min), v_max)


class OdomSmoother:
    """``nav2_util::OdomSmoother``: mean twist over a window of ``duration`` s (header stamps)."""

    def __init__(self, duration: float) -> None:
        self._duration_ns = round(duration * 1e9)
        self._buf: deque[tuple[int, Twist2D]] = deque()

    def add(self, twist: Twist2D, stamp_ns: int) -> None:
        while self._buf and stamp_ns - self._buf[0][0] > self._duration_ns:
            self._buf.popleft()
        self._buf.append((stamp_ns, Twist2D(*twist)))

    @property
    def twist(self) -> Twist2D:
        if not self._buf:
            return Twist2D()
        n = len(self._buf)
        return Twist2D(
            sum(t.vx for _, t in self._buf) / n,
            sum(t.vy for _, t in self._buf) / n,
            sum(t.wz for _, t in self._buf) / n,
        )


class VelocitySmoother:
    """State of the smoother between ticks; feed commands/odometry, call :meth:`tick` at the timer.

    Times are integer nanoseconds from the caller's clock.
    """

    def __init__(self, config: VelocitySmootherConfig | None = None) -> None:
        self.config = config or VelocitySmootherConfig()
        self.config.validate()
        self._command: Twist2D | None = None
        self._last_command_ns = 0
        self._last_cmd = Twist2D()
        self._stopped = False
        self._odom = OdomSmoother(self.config.odom_duration)

    def reset(self) -> None:
        self._command = None
        self._last_cmd = Twist2D()
        self._stopped = False
        self._odom = OdomSmoother(self.config.odom_duration)

    @property
    def last_command(self) -> Twist2D:
        """Internal last smoothed output (before deadband), m/s and rad/s."""
        return self._last_cmd

    def set_command(self, cmd: Twist2D, stamp_ns: int) -> bool:
        """Store a new input command; returns False (ignored) if it has a NaN or Inf."""
        if not all(math.isfinite(v) for v in cmd):
            return False
        self._command = Twist2D(*cmd)
        self._last_command_ns = stamp_ns
        return True

    def set_odometry(self, twist: Twist2D, stamp_ns: int) -> None:
        self._odom.add(twist, stamp_ns)

    def tick(self, now_ns: int) -> Twist2D | None:
        """Run one timer tick; returns the command to publish, or None when silent."""
        cfg = self.config
        if self._command is None:
            return None
        f = cfg.smoothing_frequency
        if (now_ns - self._last_command_ns) * 1e-9 > cfg.velocity_timeout:
            if self._last_cmd.is_zero() or self._stopped:
                self._stopped = True
                return None
            self._command = Twist2D()
        self._stopped = False
        current = self._last_cmd if cfg.feedback == Feedback.OPEN_LOOP else self._odom.twist
        cmd = [
            min(max(self._command[i], cfg.min_velocity[i]), cfg.max_velocity[i]) for i in range(3)
        ]
        self._command = Twist2D(*cmd)
        eta = 1.0
        if cfg.scale_velocities:
            for i in range(3):
                curr_eta = find_eta_constraint(
                    current[i], cmd[i], cfg.max_accel[i], cfg.max_decel[i], f
                )
                if curr_eta > 0.0 and abs(1.0 - curr_eta) > abs(1.0 - eta):
                    eta = curr_eta
        out = Twist2D(*(
            apply_constraints(current[i], cmd[i], cfg.max_accel[i], cfg.max_decel[i], eta, f)
            for i in range(3)
        ))
        self._last_cmd = out
        return Twist2D(*(
            0.0 if abs(out[i]) < cfg.deadband_velocity[i] else out[i] for i in range(3)
        ))


__all__ = [
    "Feedback",
    "OdomSmoother",
    "ParameterError",
    "VelocitySmoother",
    "VelocitySmootherConfig",
    "apply_constraints",
    "find_eta_constraint",
    "timing_warnings",
]
