"""Eddie's drive as the control board sees it: two wheels under the firmware's 50 Hz loop.

The firmware (FW 1.1 source, ``PDLoop``/``PDIteration``) keeps, per wheel, a reference point
``MidPosition`` that moves according to the control mode, and drives the motor towards it.
This plant runs the same reference update every 20 ms and lets each wheel follow the
reference ideally (dead-beat, limited to the motor's no-load speed), so position moves end
on exactly the commanded count:

* ``POWER`` (``GO``, ``STOP 0``): motor power ramps towards the set power by
  ``MAX_ON_TIME/16`` per tick (so full power → 0 within 0.32 s); wheel speed is proportional
  to power, ±127 ↔ ± no-load speed (≈ 90 positions/s for the 150 RPM motors).
* ``VELOCITY`` (``GOSPD``): the reference speed ramps towards the set speed by at most
  ``ACC`` positions/s² (boot default 200).
* ``POSITION`` (``TRVL``, ``TURN``): the reference speed ramps up at ``ACC`` to the move's
  speed and the position follows the deceleration curve ``v = √(2·ACC·remaining)``.
* ``STOPPING`` (``STOP d``): the reference slows on ``v = √(2·a·remaining)`` with ``a``
  chosen, as the firmware does, to stop ``d`` positions further on.

Wheel positions are continuous floats (forward positive for both wheels, positions);
integer counts are their floor.  The plant also integrates the ideal-drive pose of
``base_footprint`` in its start frame (REP-103, m/rad) from the wheel motion, exactly per
constant-speed segment.  Time is integer nanoseconds, so identical inputs give identical
outputs.  Differences from the firmware, on purpose: the deceleration curve is applied to
both directions (FW 1.1 takes the square root of a negative remainder as unsigned and so
stops reverse moves abruptly), and the reference starts from the wheel's continuous
position instead of the integer count plus a power offset.
"""

from __future__ import annotations

import enum
import math
from collections import deque
from dataclasses import dataclass, field

from eddiebot.robot.constants import (
    CONTROL_LOOP_HZ,
    MAX_ON_TIME,
    POSITIONS_PER_REV,
    POSITIONS_PER_SPIN,
    TRACK_M,
    metres_per_position,
)

__all__ = ["ControlMode", "DrivePlant", "PlantConfig"]

TICK_NS = 1_000_000_000 // CONTROL_LOOP_HZ
_TICK_S = TICK_NS / 1e9
_MAX_POW_ACCEL = MAX_ON_TIME // 16
_SPEED_WINDOW_TICKS = CONTROL_LOOP_HZ // 2  # the Position Controller reports per 0.5 s
_EPS = 1e-9


class ControlMode(enum.Enum):
    """Control mode of the firmware loop (FW ``Mode``), plus ``DISABLED`` (motor power cut)."""

    POWER = 0
    VELOCITY = 1
    STOPPING = 2
    POSITION = 3
    DISABLED = 4


@dataclass
class PlantConfig:
    """Plant parameters.

    ``max_speed_pos_s`` is the no-load wheel speed in positions/s (``None``: 2.5 rev/s, i.e.
    90 positions/s at 36 counts/rev).  ``positions_per_spin`` is the firmware's L−R
    difference for 360° (``None``: 186 scaled by ``counts_per_rev/36``).
    """

    counts_per_rev: int = POSITIONS_PER_REV
    track_m: float = TRACK_M
    max_speed_pos_s: float | None = None
    positions_per_spin: int | None = None
    acceleration: int = 200

    def resolved_max_speed(self) -> float:
        """No-load speed in positions/s."""
        if self.max_speed_pos_s is not None:
            return float(self.max_speed_pos_s)
        return 2.5 * self.counts_per_rev

    def resolved_positions_per_spin(self) -> int:
        """L−R positions per 360° spin."""
        if self.positions_per_spin is not None:
            return self.positions_per_spin
        return round(POSITIONS_PER_SPIN * self.counts_per_rev / POSITIONS_PER_REV)


@dataclass
class _Wheel:
    pos: float = 0.0  # continuous position, positions, forward +
    vel: float = 0.0  # speed over the current tick, positions/s
    power: float = 0.0  # motor power, -MAX_ON_TIME..MAX_ON_TIME
    set_power: float = 0.0
    mid_pos: float = 0.0
    mid_vel: float = 0.0
    set_vel: float = 0.0
    set_pos: float = 0.0
    decel: float = 0.0
    history: deque[int] = field(default_factory=lambda: deque(maxlen=_SPEED_WINDOW_TICKS + 1))

    def count(self) -> int:
        return math.floor(self.pos + _EPS)


class DrivePlant:
    """Two wheels under the board's 50 Hz loop; stepped on an integer-nanosecond clock.

    Commands (``set_power``, ``set_velocity``, ``move``, ``stop``, ``disable``) take effect
    at the next 20 ms tick, as on the board where the loop runs in its own cog.
    """

    def __init__(self, config: PlantConfig | None = None, start_ns: int = 0) -> None:
        self.config = config or PlantConfig()
        self.max_speed = self.config.resolved_max_speed()
        self.positions_per_spin = self.config.resolved_positions_per_spin()
        self.metres_per_position = metres_per_position(self.config.counts_per_rev)
        self.acceleration = self.config.acceleration
        self.mode = ControlMode.POWER
        self.left = _Wheel()
        self.right = _Wheel()
        for w in (self.left, self.right):
            w.history.append(0)
        self._t_ns = start_ns
        self._tick_index = -(-start_ns // TICK_NS)  # next tick at _tick_index * TICK_NS
        self._x = 0.0
        self._y = 0.0
        self._theta = 0.0
        self._cos, self._sin = 1.0, 0.0
        self._speed_report = (0, 0)

    # --- state -----------------------------------------------------------------------------

    @property
    def time_ns(self) -> int:
        """Plant time in nanoseconds."""
        return self._t_ns

    @property
    def time_s(self) -> float:
        """Plant time in seconds."""
        return self._t_ns / 1e9

    @property
    def wheel_positions(self) -> tuple[float, float]:
        """Continuous (left, right) wheel positions in encoder positions, forward positive."""
        return self.left.pos, self.right.pos

    @property
    def counts(self) -> tuple[int, int]:
        """Integer (left, right) encoder counts, forward positive (the board's MotorPosition)."""
        return self.left.count(), self.right.count()

    @property
    def wheel_velocities(self) -> tuple[float, float]:
        """Current (left, right) wheel speeds in positions/s."""
        return self.left.vel, self.right.vel

    @property
    def speed_report(self) -> tuple[int, int]:
        """What ``SPD`` reports: positions moved in the last 0.5 s, times 2 (positions/s)."""
        return self._speed_report

    @property
    def true_pose(self) -> tuple[float, float, float]:
        """Ideal-drive pose (x m, y m, θ rad) of base_footprint in the start frame, REP-103."""
        return self._x, self._y, self._theta

    # --- commands --------------------------------------------------------------------------

    def set_acceleration(self, rate: int) -> None:
        """``ACC``: reference-speed slew limit in positions/s²."""
        self.acceleration = rate

    def set_power(self, left: int, right: int) -> None:
        """``GO``: open-loop power, ±127 ↔ ±100 % duty (values sign-extended by the caller)."""
        self._leave_closed_loop()
        self.mode = ControlMode.POWER
        self.left.set_power = max(-127, min(127, left)) * MAX_ON_TIME // 127
        self.right.set_power = max(-127, min(127, right)) * MAX_ON_TIME // 127

    def cut_power(self) -> None:
        """``STOP 0``: power mode with set power 0; the power then ramps down."""
        self._leave_closed_loop()
        self.mode = ControlMode.POWER
        self.left.set_power = self.right.set_power = 0

    def disable(self) -> None:
        """Motor power off at once (watchdog, latched encoder fault)."""
        self.mode = ControlMode.DISABLED
        for w in (self.left, self.right):
            w.power = w.set_power = 0.0
            w.vel = 0.0

    def set_velocity(self, left: int, right: int) -> None:
        """``GOSPD``: closed-loop wheel speeds in positions/s, ramped at ``ACC``."""
        self._interpolate_mid()
        self.mode = ControlMode.VELOCITY
        self.left.set_vel = float(left)
        self.right.set_vel = float(right)

    def move(self, left_delta: int, right_delta: int, speed: int) -> None:
        """``TRVL``/``TURN``: move each wheel by a number of positions at ``speed`` pos/s.

        Targets are relative to the integer counts, as in the firmware.
        """
        self._interpolate_mid()
        self.mode = ControlMode.POSITION
        for w, delta in ((self.left, left_delta), (self.right, right_delta)):
            w.set_pos = float(w.count() + delta)
            w.set_vel = float(speed)
            direction = math.copysign(1.0, w.set_pos - w.mid_pos)
            w.mid_vel = max(0.0, w.vel * direction)

    def stop(self, distance: int) -> None:
        """``STOP d`` (d > 0): decelerate to a stop ``d`` positions further on."""
        if distance <= 0:
            self.cut_power()
            return
        self._interpolate_mid()
        self.mode = ControlMode.STOPPING
        for w in (self.left, self.right):
            count = w.count()
            if w.vel > _EPS:
                w.set_pos = float(count + distance)
            elif w.vel < -_EPS:
                w.set_pos = float(count - distance)
            else:
                w.set_pos = float(count)
            v = abs(w.vel)
            remaining = abs(w.set_pos - w.pos)
            denom = v - CONTROL_LOOP_HZ * remaining
            w.decel = abs(-25.0 * v * v / denom) if denom != 0 else 0.0
            w.mid_vel = v

    def reset_history(self) -> None:
        """Forget the 0.5 s speed window (used when counts are redefined)."""
        for w in (self.left, self.right):
            w.history.clear()
            w.history.append(w.count())

    # --- time ------------------------------------------------------------------------------

    def step(self, dt_s: float) -> None:
        """Advance by ``dt_s`` seconds."""
        self.advance_to_ns(self._t_ns + round(dt_s * 1e9))

    def advance_to(self, t_s: float) -> None:
        """Advance to absolute time ``t_s`` seconds (no-op if in the past)."""
        self.advance_to_ns(round(t_s * 1e9))

    def advance_to_ns(self, t_ns: int) -> None:
        """Advance to absolute time ``t_ns`` nanoseconds (no-op if in the past)."""
        t = self._t_ns
        if t_ns <= t:
            return
        k = self._tick_index
        next_tick = k * TICK_NS
        while next_tick <= t_ns:
            if next_tick > t:
                self._integrate((next_tick - t) * 1e-9)
            t = self._t_ns = next_tick
            self._tick()
            k += 1
            next_tick += TICK_NS
        self._tick_index = k
        if t_ns > t:
            self._integrate((t_ns - t) * 1e-9)
            self._t_ns = t_ns

    # --- internals -------------------------------------------------------------------------

    def _interpolate_mid(self) -> None:
        # FW InterpolateMidVariables: the reference restarts at the wheel, at the wheel's speed,
        # when the loop next runs -- where the wheel will be at the next tick (its speed is
        # constant within a tick). Restarting at the wheel's position *now* would drop the part
        # of the tick still to run: a GOSPD repeated every 50 ms then lost ~30 % of the speed.
        lead_s = (self._tick_index * TICK_NS - self._t_ns) * 1e-9
        for w in (self.left, self.right):
            w.mid_pos = w.pos + w.vel * lead_s
            w.mid_vel = w.vel

    def _leave_closed_loop(self) -> None:
        # Power that would give the current speed, so GO/STOP 0 continue smoothly.
        if self.mode is not ControlMode.POWER:
            for w in (self.left, self.right):
                w.power = w.vel / self.max_speed * MAX_ON_TIME

    def _tick(self) -> None:
        mode = self.mode
        acc = self.acceleration
        acc_tick = acc / CONTROL_LOOP_HZ
        vmax = self.max_speed
        for w in (self.left, self.right):
            # Speed report: positions over the last 0.5 s, doubled (the firmware's MotorSpeed).
            w.history.append(math.floor(w.pos + _EPS))
            if mode is ControlMode.VELOCITY:
                dv = w.set_vel - w.mid_vel
                if dv:
                    w.mid_vel += acc_tick if dv > acc_tick else (
                        -acc_tick if dv < -acc_tick else dv)
                w.mid_pos += w.mid_vel * _TICK_S
            elif mode is ControlMode.POSITION:
                dv = w.set_vel - w.mid_vel
                if dv:
                    w.mid_vel += acc_tick if dv > acc_tick else (
                        -acc_tick if dv < -acc_tick else dv)
                remaining = w.set_pos - w.mid_pos
                if remaining:
                    limit = min(w.mid_vel, math.sqrt(2.0 * acc * abs(remaining)))
                    step = limit * _TICK_S
                    w.mid_pos += step if remaining > step else (
                        -step if remaining < -step else remaining)
            elif mode is ControlMode.STOPPING:
                remaining = w.set_pos - w.mid_pos
                if remaining:
                    step = math.sqrt(2.0 * w.decel * abs(remaining)) * _TICK_S
                    w.mid_pos += step if remaining > step else (
                        -step if remaining < -step else remaining)
            elif mode is ControlMode.POWER:
                dp = w.set_power - w.power
                if dp:
                    w.power += _MAX_POW_ACCEL if dp > _MAX_POW_ACCEL else (
                        -_MAX_POW_ACCEL if dp < -_MAX_POW_ACCEL else dp)
                w.vel = w.power / MAX_ON_TIME * vmax
                continue
            else:
                w.vel = 0.0
                continue
            # The wheel follows the reference (dead-beat), limited to the no-load speed.
            v = (w.mid_pos - w.pos) / _TICK_S
            w.vel = vmax if v > vmax else (-vmax if v < -vmax else v)
        lh, rh = self.left.history, self.right.history
        self._speed_report = (
            max(-128, min(127, lh[-1] - lh[0])) * 2,
            max(-128, min(127, rh[-1] - rh[0])) * 2,
        )

    def _integrate(self, dt: float) -> None:
        vl, vr = self.left.vel, self.right.vel
        if dt <= 0.0 or (vl == 0.0 and vr == 0.0):
            return
        self.left.pos += vl * dt
        self.right.pos += vr * dt
        m = self.metres_per_position
        v = 0.5 * (vl + vr) * m
        omega = (vr - vl) * m / self.config.track_m
        c0, s0 = self._cos, self._sin
        if -1e-12 < omega < 1e-12:
            self._x += v * dt * c0
            self._y += v * dt * s0
            return
        th1 = self._theta + omega * dt
        if th1 > math.pi:
            th1 -= 2.0 * math.pi
        elif th1 <= -math.pi:
            th1 += 2.0 * math.pi
        c1, s1 = math.cos(th1), math.sin(th1)
        r = v / omega
        self._x += r * (s1 - s0)
        self._y -= r * (c1 - c0)
        self._theta, self._cos, self._sin = th1, c1, s1
