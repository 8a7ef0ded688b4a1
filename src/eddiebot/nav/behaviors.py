"""Behaviour cores of Nav2's behaviour server (``nav2_behaviors``): spin, back_up,
drive_on_heading, wait and assisted teleop, as state machines ticked at ``cycle_frequency``.

Each behaviour is started with its goal and then ``update(pose, now_ns, costmap)`` returns a
:class:`BehaviorStep` (command to publish and status). Collision checking projects the
command ``simulate_ahead_time`` ahead on the local costmap (footprint outline cost >= LETHAL
or off the map = collision), as upstream's ``CostmapTopicCollisionChecker``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum
from typing import Any

import numpy.typing as npt

from eddiebot.nav.cost_values import LETHAL_OBSTACLE
from eddiebot.nav.costmap.footprint import transform_footprint
from eddiebot.nav.costmap.layered import LayeredCostmap
from eddiebot.nav.errors import (
    BehaviorError,
    BehaviorTimedOut,
    CollisionAhead,
    InvalidBehaviorInput,
    UnsupportedPlugin,
)
from eddiebot.nav.params import from_params, require
from eddiebot.nav.plugins import NoParameters, PluginContext, PluginFactory, registry
from eddiebot.nav.types import Twist2D, as_pose


@dataclass(frozen=True)
class BehaviorServerConfig:
    """``behavior_server`` parameters (Jazzy code defaults)."""

    cycle_frequency: float = 10.0
    local_frame: str = "odom"
    global_frame: str = "map"
    robot_base_frame: str = "base_link"
    transform_tolerance: float = 0.1
    simulate_ahead_time: float = 2.0
    max_rotational_vel: float = 1.0
    min_rotational_vel: float = 0.4
    rotational_acc_lim: float = 3.2
    projection_time: float = 1.0
    simulation_time_step: float = 0.1
    behavior_plugins: tuple[str, ...] = ("spin", "backup", "drive_on_heading", "assisted_teleop", "wait")

    def validate(self, server: str = "behavior_server") -> None:
        require(self.cycle_frequency > 0.0, server, "cycle_frequency", self.cycle_frequency,
                "must be > 0")
        require(self.max_rotational_vel >= self.min_rotational_vel >= 0.0, server,
                "min_rotational_vel", self.min_rotational_vel,
                "needs 0 <= min_rotational_vel <= max_rotational_vel")


class Status(Enum):
    RUNNING = "running"
    SUCCEEDED = "succeeded"
    FAILED = "failed"


@dataclass(frozen=True)
class BehaviorStep:
    cmd: Twist2D | None
    status: Status
    error: BehaviorError | None = None


def collision_free(pose: npt.ArrayLike, costmap: LayeredCostmap) -> bool:
    p = as_pose(pose)
    cm = costmap.master
    if cm.world_to_map(p[0], p[1]) is None:
        return False
    c = cm.footprint_cost(transform_footprint(p, costmap.footprint))
    return 0 <= c < LETHAL_OBSTACLE


class _Timed:
    def __init__(self, config: BehaviorServerConfig | None = None) -> None:
        self.config = config or BehaviorServerConfig()
        self.config.validate()
        self._start_ns = 0
        self._allowance_ns = 0

    def _begin(self, now_ns: int, time_allowance: float) -> None:
        self._start_ns = now_ns
        self._allowance_ns = round(time_allowance * 1e9)

    def _timed_out(self, now_ns: int) -> bool:
        return self._allowance_ns > 0 and now_ns - self._start_ns > self._allowance_ns

    def _fail(self, err: BehaviorError) -> BehaviorStep:
        return BehaviorStep(Twist2D(), Status.FAILED, err)


class Spin(_Timed):
    """Rotate by ``target_yaw`` (rad, signed) with a sqrt(2·a·remaining) velocity profile."""

    def start(self, pose: npt.ArrayLike, target_yaw: float, now_ns: int,
              time_allowance: float = 10.0) -> None:
        self._prev_yaw = float(as_pose(pose)[2])
        self._relative = 0.0
        self._cmd_yaw = float(target_yaw)
        self._begin(now_ns, time_allowance)

    def update(self, pose: npt.ArrayLike, now_ns: int, costmap: LayeredCostmap) -> BehaviorStep:
        cfg = self.config
        if self._timed_out(now_ns):
            return self._fail(BehaviorTimedOut("spin exceeded its time allowance"))
        p = as_pose(pose)
        delta = p[2] - self._prev_yaw
        if abs(delta) > math.pi:
            delta = math.copysign(2 * math.pi - abs(delta), self._prev_yaw)
        self._relative += delta
        self._prev_yaw = p[2]
        remaining = abs(self._cmd_yaw) - abs(self._relative)
        if remaining < 1e-6:
            return BehaviorStep(Twist2D(), Status.SUCCEEDED)
        vel = math.sqrt(2.0 * cfg.rotational_acc_lim * remaining)
        vel = min(max(vel, cfg.min_rotational_vel), cfg.max_rotational_vel)
        cmd = Twist2D(0.0, 0.0, math.copysign(vel, self._cmd_yaw))
        cycles = int(cfg.cycle_frequency * cfg.simulate_ahead_time)
        for i in range(cycles):
            change = cmd.wz * (i / cfg.cycle_frequency)
            if i > 0 and abs(self._relative + change) > abs(self._cmd_yaw):
                break
            if not collision_free((p[0], p[1], p[2] + change), costmap):
                return self._fail(CollisionAhead("collision ahead while spinning"))
        return BehaviorStep(cmd, Status.RUNNING)


@dataclass(frozen=True)
class DriveOnHeadingConfig:
    """Per-instance ``<name>.acceleration_limit`` (m/s², > 0), ``<name>.deceleration_limit``
    (m/s², < 0) and ``<name>.minimum_speed`` (m/s) of DriveOnHeading and BackUp (Kilted's
    parameters and defaults; a limit given with the wrong sign is taken by magnitude, as
    upstream does)."""

    acceleration_limit: float = 2.5
    deceleration_limit: float = -2.5
    minimum_speed: float = 0.10

    def validate(self, server: str = "behavior_server") -> None:
        require(self.minimum_speed >= 0.0, server, "minimum_speed", self.minimum_speed,
                "must be >= 0")


class DriveOnHeading(_Timed):
    """Drive straight ``distance`` m at ``speed`` m/s (both signed alike); :class:`BackUp`
    forces both negative.

    Each cycle the command moves from the last one by at most ``acceleration_limit`` (or
    ``deceleration_limit``) / ``cycle_frequency``, is capped at ``sqrt(-2·deceleration_limit·
    remaining distance)`` so it stops on the target, and is at least ``minimum_speed``.
    """

    reverse = False

    def __init__(self, config: BehaviorServerConfig | None = None,
                 drive: DriveOnHeadingConfig | None = None) -> None:
        super().__init__(config)
        self.drive = drive or DriveOnHeadingConfig()
        self.drive.validate()
        self._last_vel = 0.0

    def start(self, pose: npt.ArrayLike, distance: float, speed: float, now_ns: int,
              time_allowance: float = 10.0) -> None:
        if self.reverse:
            distance, speed = -abs(distance), -abs(speed)
        elif distance * speed < 0.0 or speed == 0.0:
            raise InvalidBehaviorInput("distance and speed must be non-zero with the same sign")
        self._initial = as_pose(pose)
        self._distance = float(distance)
        self._speed = float(speed)
        self._last_vel = 0.0
        self._begin(now_ns, time_allowance)

    def update(self, pose: npt.ArrayLike, now_ns: int, costmap: LayeredCostmap) -> BehaviorStep:
        cfg = self.config
        if self._timed_out(now_ns):
            return self._fail(BehaviorTimedOut("drive exceeded its time allowance"))
        p = as_pose(pose)
        travelled = math.hypot(p[0] - self._initial[0], p[1] - self._initial[1])
        if travelled >= abs(self._distance):
            return BehaviorStep(Twist2D(), Status.SUCCEEDED)
        cmd = Twist2D(self._ramped_speed(abs(self._distance) - travelled), 0.0, 0.0)
        cycles = int(cfg.simulate_ahead_time * cfg.cycle_frequency)
        for i in range(cycles):
            change = cmd.vx * (i / cfg.cycle_frequency)
            if travelled + abs(change) >= abs(self._distance):
                break
            q = (p[0] + change * math.cos(p[2]), p[1] + change * math.sin(p[2]), p[2])
            if not collision_free(q, costmap):
                return self._fail(CollisionAhead("collision ahead while driving"))
        self._last_vel = cmd.vx
        return BehaviorStep(cmd, Status.RUNNING)

    def _ramped_speed(self, remaining: float) -> float:
        acc = abs(self.drive.acceleration_limit) / self.config.cycle_frequency
        dec = -abs(self.drive.deceleration_limit)
        v0 = self._last_vel
        forward = self._speed > 0.0
        lo, hi = (v0 + dec / self.config.cycle_frequency, v0 + acc) if forward else \
            (v0 - acc, v0 - dec / self.config.cycle_frequency)
        v = min(max(self._speed, lo), hi)
        v_stop = math.sqrt(-2.0 * dec * max(remaining, 0.0))
        if v_stop < abs(v):
            v = v_stop if forward else -v_stop
        if abs(v) < self.drive.minimum_speed:
            v = self.drive.minimum_speed if forward else -self.drive.minimum_speed
        return v


class BackUp(DriveOnHeading):
    reverse = True


class Wait(_Timed):
    def start(self, duration: float, now_ns: int) -> None:
        self._begin(now_ns, 0.0)
        self._duration_ns = round(duration * 1e9)

    def update(self, pose: npt.ArrayLike | None, now_ns: int,
               costmap: LayeredCostmap | None = None) -> BehaviorStep:
        if now_ns - self._start_ns >= self._duration_ns:
            return BehaviorStep(None, Status.SUCCEEDED)
        return BehaviorStep(None, Status.RUNNING)

    def time_left(self, now_ns: int) -> float:
        return max(0.0, (self._duration_ns - (now_ns - self._start_ns)) * 1e-9)


class AssistedTeleop(_Timed):
    """Pass the teleop twist through, scaled down by the time to the first projected collision
    within ``projection_time`` (zero if the first step already collides)."""

    def start(self, now_ns: int, time_allowance: float = 0.0) -> None:
        self._begin(now_ns, time_allowance)
        self.teleop = Twist2D()

    def set_teleop(self, twist: Twist2D) -> None:
        self.teleop = twist

    def update(self, pose: npt.ArrayLike, now_ns: int, costmap: LayeredCostmap) -> BehaviorStep:
        cfg = self.config
        if self._timed_out(now_ns):
            return BehaviorStep(Twist2D(), Status.SUCCEEDED)
        p = as_pose(pose).copy()
        tw = self.teleop
        dt = cfg.simulation_time_step
        t = dt
        out = tw
        while t < cfg.projection_time:
            p[0] += (tw.vx * math.cos(p[2]) - tw.vy * math.sin(p[2])) * dt
            p[1] += (tw.vx * math.sin(p[2]) + tw.vy * math.cos(p[2])) * dt
            p[2] += tw.wz * dt
            if not collision_free(p, costmap):
                if math.isclose(t, dt):
                    out = Twist2D()
                else:
                    s = t / cfg.projection_time
                    out = Twist2D(tw.vx * s, tw.vy * s, tw.wz * s)
                break
            t += dt
        return BehaviorStep(out, Status.RUNNING)



#: the ``behaviors`` plugin registry (``pkg/Type`` spellings are normalised to ``pkg::Type``);
#: a factory gets the :class:`BehaviorServerConfig` as ``context.server_config``
BEHAVIOR_PLUGINS = registry("behaviors")


def _server_only(cls: type[_Timed]) -> PluginFactory:
    """Factory of a behaviour with no parameters of its own: ``cls(server_config)``."""

    def factory(params: dict[str, Any], name: str, context: PluginContext) -> Any:
        return cls(context.server_config)

    return factory


def _drive(cls: type[DriveOnHeading]) -> PluginFactory:
    """``cls(server_config, DriveOnHeadingConfig)`` from the instance's parameters."""

    def factory(params: dict[str, Any], name: str, context: PluginContext) -> Any:
        return cls(context.server_config,
                   from_params(DriveOnHeadingConfig, params, server=context.where))

    return factory


BEHAVIOR_PLUGINS.register("nav2_behaviors::Spin", _server_only(Spin), NoParameters,
                          source="built-in")
BEHAVIOR_PLUGINS.register("nav2_behaviors::BackUp", _drive(BackUp), DriveOnHeadingConfig,
                          source="built-in")
BEHAVIOR_PLUGINS.register("nav2_behaviors::DriveOnHeading", _drive(DriveOnHeading),
                          DriveOnHeadingConfig, source="built-in")
BEHAVIOR_PLUGINS.register("nav2_behaviors::Wait", _server_only(Wait), NoParameters,
                          source="built-in")
BEHAVIOR_PLUGINS.register("nav2_behaviors::AssistedTeleop", _server_only(AssistedTeleop),
                          NoParameters, source="built-in")


def build_behaviors(params: dict[str, object], server: str = "behavior_server"
                    ) -> tuple[BehaviorServerConfig, dict[str, Any]]:
    """Behaviour server config and ``{name: behaviour}`` from its ``ros__parameters``."""
    flat = {k: v for k, v in params.items() if not isinstance(v, dict)}
    cfg = from_params(BehaviorServerConfig, flat, server=server)
    out: dict[str, Any] = {}
    for name in cfg.behavior_plugins:
        sub = params.get(name, {})
        sub = sub if isinstance(sub, dict) else {}
        plugin = str(sub.get("plugin", ""))
        if not plugin:
            raise UnsupportedPlugin(server, f"{name}.plugin", None,
                                    f"missing plugin type; known: {sorted(BEHAVIOR_PLUGINS)}")
        out[name] = BEHAVIOR_PLUGINS.create(plugin, sub, name, PluginContext(server, name, cfg))
    return cfg, out


__all__ = [
    "BEHAVIOR_PLUGINS",
    "AssistedTeleop",
    "BackUp",
    "BehaviorServerConfig",
    "BehaviorStep",
    "DriveOnHeading",
    "DriveOnHeadingConfig",
    "Spin",
    "Status",
    "Wait",
    "build_behaviors",
    "collision_free",
]
