"""The MPPI optimiser (``mppi::Optimizer``, Jazzy), vectorised over the batch.

One cycle: the control sequence plus Gaussian noise gives ``batch_size`` control sequences;
the motion model propagates them into acceleration-limited state velocities; integrating
those from the robot's pose gives trajectories; the critics score them; the new control
sequence is the softmax-weighted (``temperature``) mean of the noised controls, with the
control cost ``gamma``; it is clamped to the velocity and acceleration limits, smoothed with
a 9-point Savitzky-Golay filter over the last four commands, and shifted one ``model_dt``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from eddiebot.nav.controllers.mppi import _kernels
from eddiebot.nav.controllers.mppi.config import MPPIConfig
from eddiebot.nav.controllers.mppi.critics import Critic, CriticData
from eddiebot.nav.costmap.layered import LayeredCostmap
from eddiebot.nav.errors import NoValidControl, ParameterError
from eddiebot.nav.types import Twist2D

F64 = npt.NDArray[np.float64]

#: 9-point quadratic Savitzky-Golay smoothing kernel (``utils::savitskyGolayFilter``)
SAVITZKY_GOLAY = np.array([-21.0, 14.0, 39.0, 54.0, 59.0, 54.0, 39.0, 14.0, -21.0]) / 231.0


@dataclass
class ControlConstraints:
    """``models::ControlConstraints``: the limits in force (speed limits scale them)."""

    vx_max: float
    vx_min: float
    vy: float
    wz: float
    ax_max: float
    ax_min: float
    ay_max: float
    ay_min: float
    az_max: float

    @classmethod
    def of(cls, c: MPPIConfig) -> ControlConstraints:
        return cls(c.vx_max, c.vx_min, c.vy_max, c.wz_max, c.ax_max, c.ax_min, c.ay_max,
                   c.ay_min, c.az_max)


def savitzky_golay(sequence: F64, history: F64) -> F64:
    """Smooth all but the last entry of ``sequence`` with the 9-point kernel; the four
    entries before it are ``history`` (oldest first), the ones past its end its last entry."""
    n = sequence.shape[0] - 1
    ext = np.concatenate([history, sequence, np.repeat(sequence[-1:], 4)])
    out = sequence.copy()
    out[:n] = np.convolve(ext, SAVITZKY_GOLAY[::-1], mode="valid")[:n]
    return out


class _Buffers:
    """Work arrays of one batch, allocated once: fresh 1 MB arrays each cycle cost more in
    page faults than the arithmetic on them."""

    def __init__(self, shape: tuple[int, ...]) -> None:
        self.yaws = np.empty(shape)
        self.x = np.empty(shape)
        self.y = np.empty(shape)
        self.dx = np.empty(shape)
        self.dy = np.empty(shape)
        self.heading = np.empty(shape, dtype=np.float32)
        self.trig = np.empty(shape, dtype=np.float32)


def integrate(pose: F64, vx: F64, wz: F64, dt: float, buffers: _Buffers | None = None
              ) -> tuple[F64, F64, F64]:
    """``integrateStateVelocities``: poses after each step of (…, time_steps) velocities from
    ``pose`` (x, y, yaw); each step moves along the heading reached at the previous one.
    The headings' sines and cosines are taken in float32, as upstream computes throughout.
    With ``buffers`` the results are written into (and returned from) them."""
    b = buffers or _Buffers(np.shape(vx))
    yaw0 = float(pose[2])
    np.cumsum(wz, axis=-1, out=b.yaws)
    b.yaws *= dt
    b.yaws += yaw0
    b.heading[..., 0] = yaw0
    b.heading[..., 1:] = b.yaws[..., :-1]
    for trig, d, out, origin in ((np.cos, b.dx, b.x, pose[0]), (np.sin, b.dy, b.y, pose[1])):
        trig(b.heading, out=b.trig)
        np.multiply(b.trig, vx, out=d)
        np.cumsum(d, axis=-1, out=out)
        out *= dt
        out += origin
    return b.x, b.y, b.yaws


class Optimizer:
    """MPPI over a DiffDrive model. ``seed`` fixes the noise (tests, benchmarks)."""

    def __init__(self, config: MPPIConfig, critics: Sequence[Critic],
                 controller_frequency: float = 20.0, seed: int | None = None,
                 server: str = "controller_server") -> None:
        self.settings = config.normalized()
        self.critics = list(critics)
        self.base_constraints = ControlConstraints.of(self.settings)
        self.constraints = ControlConstraints.of(self.settings)
        self.rng = np.random.default_rng(seed)
        self.shift_control_sequence = self._shift_for(controller_frequency, server)
        self._fail_count = 0
        self.last_command = Twist2D()
        self.reset()

    def _shift_for(self, controller_frequency: float, server: str) -> bool:
        """``setOffset``: shift the sequence each cycle when the controller period equals
        ``model_dt``; a period longer than ``model_dt`` is refused as upstream does."""
        period = 1.0 / controller_frequency
        dt = self.settings.model_dt
        if period + 1e-6 < dt:
            return False
        if abs(period - dt) < 1e-6:
            return True
        raise ParameterError(server, "model_dt", dt,
                             f"controller period 1/controller_frequency = {period:g} s is more "
                             "than model_dt; set model_dt equal to it")

    # --- state -------------------------------------------------------------------------
    def reset(self, reset_speed_limits: bool = True) -> None:
        s = self.settings
        b, t = s.batch_size, s.time_steps
        self.u_vx = np.zeros(t)
        self.u_wz = np.zeros(t)
        self.history = np.zeros((4, 2))
        if s.open_loop:
            self.last_command = Twist2D()
        if reset_speed_limits:
            self.constraints = ControlConstraints.of(self.settings)
        self.costs = np.zeros(b)
        self.vx = np.zeros((b, t))
        self.wz = np.zeros((b, t))
        self.cvx = np.zeros((b, t))
        self.cwz = np.zeros((b, t))
        self._buffers = _Buffers((b, t))
        self.traj_x, self.traj_y, self.traj_yaw = self._buffers.x, self._buffers.y, \
            self._buffers.yaws
        # upstream's noise thread (regenerate_noises) or configure (not) draws them now too
        self._generate_noises()

    def _generate_noises(self) -> None:
        s = self.settings
        shape = (s.batch_size, s.time_steps)
        if getattr(self, "noise_vx", np.empty(0)).shape != shape:
            self.noise_vx = np.empty(shape)
            self.noise_wz = np.empty(shape)
        self.rng.standard_normal(out=self.noise_vx)
        self.noise_vx *= s.vx_std
        self.rng.standard_normal(out=self.noise_wz)
        self.noise_wz *= s.wz_std

    def set_speed_limit(self, speed_limit: float, percentage: bool) -> None:
        """``setSpeedLimit``: 0 restores the base limits; else % of them or an absolute vx_max
        scaling all velocity limits alike."""
        b = self.base_constraints
        c = self.constraints
        if speed_limit == 0.0:
            ratio = 1.0
        elif percentage:
            ratio = speed_limit / 100.0
        else:
            ratio = speed_limit / b.vx_max
        c.vx_max, c.vx_min, c.vy, c.wz = (b.vx_max * ratio, b.vx_min * ratio, b.vy * ratio,
                                          b.wz * ratio)

    # --- one cycle ---------------------------------------------------------------------
    def eval_control(self, pose: F64, speed: Twist2D, path: F64, goal: F64,
                     costmap: LayeredCostmap | None, goal_tolerance: float | None = None
                     ) -> Twist2D:
        """``evalControl``: the command for this cycle (robot frame)."""
        s = self.settings
        state_speed = self.last_command if s.open_loop else speed
        self.costs.fill(0.0)
        data = CriticData(pose=pose, goal=goal, path=path, vx=self.vx, wz=self.wz,
                          traj_x=self.traj_x, traj_y=self.traj_y, traj_yaw=self.traj_yaw,
                          costs=self.costs, model_dt=s.model_dt, costmap=costmap,
                          goal_tolerance=goal_tolerance)
        while True:
            for _ in range(s.iteration_count):
                self._generate_noised_trajectories(pose, state_speed)
                self._refresh(data)
                for critic in self.critics:
                    if data.fail_flag:
                        break
                    critic.score(data)
                self._update_control_sequence()
            if not self._fallback(data.fail_flag):
                break
            data.fail_flag = False
        self.history, self.u_vx, self.u_wz = self._smoothed()
        off = 1 if self.shift_control_sequence else 0
        cmd = Twist2D(float(self.u_vx[off]), 0.0, float(self.u_wz[off]))
        self.last_command = cmd
        if self.shift_control_sequence:
            self._shift()
        return cmd

    def _refresh(self, data: CriticData) -> None:
        data.vx, data.wz = self.vx, self.wz
        data.traj_x, data.traj_y, data.traj_yaw = self.traj_x, self.traj_y, self.traj_yaw
        data.costs = self.costs

    def _fallback(self, fail: bool) -> bool:
        """``fallback``: on all-colliding samples reset (keeping speed limits) and retry, up
        to ``retry_attempt_limit`` times, then fail."""
        if not fail:
            self._fail_count = 0
            return False
        self.reset(reset_speed_limits=False)
        self._fail_count += 1
        if self._fail_count > self.settings.retry_attempt_limit:
            self._fail_count = 0
            raise NoValidControl("Optimizer fail to compute path")
        return True

    def _generate_noised_trajectories(self, pose: F64, speed: Twist2D) -> None:
        s = self.settings
        np.add(self.u_vx, self.noise_vx, out=self.cvx)
        np.add(self.u_wz, self.noise_wz, out=self.cwz)
        if s.regenerate_noises:
            self._generate_noises()
        self.vx[:, 0] = speed.vx
        self.wz[:, 0] = speed.wz
        c = self.constraints
        _kernels.predict_velocities(self.cvx, self.cwz, self.vx, self.wz,
                                    s.model_dt * c.ax_max, s.model_dt * c.ax_min,
                                    s.model_dt * c.az_max)
        self.traj_x, self.traj_y, self.traj_yaw = integrate(pose, self.vx, self.wz, s.model_dt,
                                                            self._buffers)

    def _update_control_sequence(self) -> None:
        s = self.settings
        # control cost: gamma / sigma^2 * u · (v - u), the noise bounded by the clamps
        self.costs += s.gamma / s.vx_std ** 2 * (self.cvx @ self.u_vx - self.u_vx @ self.u_vx)
        self.costs += s.gamma / s.wz_std ** 2 * (self.cwz @ self.u_wz - self.u_wz @ self.u_wz)
        w = np.exp(-(self.costs - self.costs.min()) / s.temperature)
        w /= w.sum()
        self.u_vx = w @ self.cvx
        self.u_wz = w @ self.cwz
        self._apply_constraints()

    def _apply_constraints(self) -> None:
        """``applyControlSequenceConstraints``: velocity limits, then each step's change
        within one ``model_dt`` of acceleration from the previous step."""
        c = self.constraints
        dt = self.settings.model_dt
        vx = np.clip(self.u_vx, c.vx_min, c.vx_max).tolist()
        wz = np.clip(self.u_wz, -c.wz, c.wz).tolist()
        max_dvx, min_dvx, max_dwz = dt * c.ax_max, dt * c.ax_min, dt * c.az_max
        vx_last, wz_last = vx[0], wz[0]
        for i in range(1, len(vx)):
            if vx_last > 0.0:
                v = min(max(vx[i], vx_last + min_dvx), vx_last + max_dvx)
            else:
                v = min(max(vx[i], vx_last - max_dvx), vx_last - min_dvx)
            vx[i] = vx_last = v
            w = min(max(wz[i], wz_last - max_dwz), wz_last + max_dwz)
            wz[i] = wz_last = w
        self.u_vx = np.asarray(vx)
        self.u_wz = np.asarray(wz)

    def _smoothed(self) -> tuple[F64, F64, F64]:
        """``savitskyGolayFilter`` (skipped for fewer than 21 time steps, as upstream) and the
        command history it keeps."""
        vx, wz = self.u_vx, self.u_wz
        if vx.shape[0] - 1 < 20:
            return self.history, vx, wz
        vx = savitzky_golay(vx, self.history[:, 0])
        wz = savitzky_golay(wz, self.history[:, 1])
        off = 1 if self.shift_control_sequence else 0
        history = np.vstack([self.history[1:], [[vx[off], wz[off]]]])
        return history, vx, wz

    def _shift(self) -> None:
        self.u_vx = np.concatenate([self.u_vx[1:], self.u_vx[-1:]])
        self.u_wz = np.concatenate([self.u_wz[1:], self.u_wz[-1:]])

    # --- inspection --------------------------------------------------------------------
    def optimal_trajectory(self, pose: F64) -> F64:
        """``getOptimizedTrajectory``: the control sequence integrated from ``pose``,
        (time_steps, 3) x, y, yaw."""
        x, y, yaw = integrate(np.asarray(pose, dtype=np.float64), self.u_vx, self.u_wz,
                              self.settings.model_dt)
        return np.stack([x, y, yaw], axis=1)


__all__ = ["SAVITZKY_GOLAY", "ControlConstraints", "Optimizer", "integrate", "savitzky_golay"]
