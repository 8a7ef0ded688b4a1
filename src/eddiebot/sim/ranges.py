"""IR (Sharp GP2Y0A21) and PING))) distance models: ray and cone queries against the world.

Each sensor is a mount pose on base_footprint and a beam: a fan of rays spread over
``cone`` (full angle, rad) horizontally and vertically. A ray stops at the floor (no echo
from it) and hits any prism (or person) whose height span it passes through. The reading
is the nearest hit along any ray of the beam (slant distance from the sensor, m), or +Inf
when nothing lies within ``max_range``. Readings below ``min_range`` are returned as they
are: what the hardware reports there (the Sharp's fold-back, the PING's minimum echo time)
is the converter's business (`eddiebot.robot.constants` mount table and ADC/PING units).

Mount poses compose the original URDF's sensor joints (``create_base.urdf.xacro``):
stand link ``_1`` on base_link (z 0.10125 above base_footprint), then ``_2`` and the ray link
``_3``, giving an offset (0, +0.0025, +0.04) (IR) or (0, +0.0025, +0.035) (PING) in the
sensor's frame.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np
import numpy.typing as npt
from numba import njit

from eddiebot.sim.world import World

__all__ = [
    "IR_MODEL",
    "PING_MODEL",
    "RANGE_MOUNTS",
    "RangeModel",
    "RangeMount",
    "mounts_from_table",
    "range_reading",
    "range_readings",
]

_BASE_LINK_Z = 0.10125


@dataclass(frozen=True)
class RangeModel:
    """A beam: full cone angle (rad), rays per axis, limits (m), relative noise (1σ)."""

    kind: str
    cone: float
    rays: int
    min_range: float
    max_range: float
    noise: float = 0.0


IR_MODEL = RangeModel("ir", cone=math.radians(3.0), rays=3, min_range=0.10, max_range=0.80)
"""Sharp GP2Y0A21YK0F: 10–80 cm, a narrow (≈ 3°) beam."""
PING_MODEL = RangeModel("ping", cone=math.radians(15.0), rays=7, min_range=0.02, max_range=3.19)
"""Parallax PING))): 2 cm – 3.19 m (the firmware's echo timeout), ≈ 15° cone."""


@dataclass(frozen=True)
class RangeMount:
    """Sensor ray origin on base_footprint: x, y, z (m), yaw (rad), with its beam model."""

    name: str
    x: float
    y: float
    z: float
    yaw: float
    model: RangeModel


def _mount(name: str, x: float, y: float, z: float, yaw: float, dy: float, dz: float,
           model: RangeModel) -> RangeMount:
    return RangeMount(name, x - math.sin(yaw) * dy, y + math.cos(yaw) * dy,
                      _BASE_LINK_Z + z + dz, yaw, model)


RANGE_MOUNTS: dict[str, RangeMount] = {
    m.name: m
    for m in (
        _mount("ir/left", 0.135, 0.155, 0.025, math.pi / 4, 0.0025, 0.04, IR_MODEL),
        _mount("ir/center", 0.210, 0.0, 0.025, 0.0, 0.0025, 0.04, IR_MODEL),
        _mount("ir/right", 0.135, -0.155, 0.025, -math.pi / 4, 0.0025, 0.04, IR_MODEL),
        _mount("ping/left", 0.195, 0.09, 0.015, math.pi / 8, 0.0025, 0.035, PING_MODEL),
        _mount("ping/right", 0.195, -0.09, 0.015, -math.pi / 8, 0.0025, 0.035, PING_MODEL),
    )
}
"""Eddie's three IR and two PING sensors, keyed as their topics (``/eddie/<name>``)."""


@njit(cache=True)
def _cast_rays(ox: float, oy: float, oz: float, dirs: npt.NDArray[np.float64],
               quads: npt.NDArray[np.float64], quad_z: npt.NDArray[np.float64],
               circles: npt.NDArray[np.float64], circle_z: npt.NDArray[np.float64],
               max_range: float) -> float:
    """Nearest slant distance along unit 3-D rays ``dirs`` (N, 3); Inf if none."""
    best = np.inf
    for i in range(dirs.shape[0]):
        dx, dy, dz = dirs[i, 0], dirs[i, 1], dirs[i, 2]
        hlen = math.hypot(dx, dy)
        if hlen < 1e-9:
            continue
        rx, ry = dx / hlen, dy / hlen  # horizontal unit; parameter t = horizontal distance
        slope = dz / hlen
        t_max = max_range * hlen
        if slope < 0.0:
            t_max = min(t_max, -oz / slope)  # the floor ends the ray
        for k in range(quads.shape[0] + circles.shape[0]):
            if k < quads.shape[0]:
                t_in, t_out = -1e30, 1e30
                ok = True
                for e in range(4):
                    ax, ay = quads[k, e, 0], quads[k, e, 1]
                    bx, by = quads[k, (e + 1) % 4, 0], quads[k, (e + 1) % 4, 1]
                    nx, ny = by - ay, -(bx - ax)
                    num = nx * (ox - ax) + ny * (oy - ay)
                    den = nx * rx + ny * ry
                    if den == 0.0:
                        if num > 0.0:
                            ok = False
                            break
                        continue
                    t = -num / den
                    if den < 0.0:
                        t_in = max(t_in, t)
                    else:
                        t_out = min(t_out, t)
                if not ok or t_in > t_out:
                    continue
                zb, zt = quad_z[k, 0], quad_z[k, 1]
            else:
                c = k - quads.shape[0]
                fx, fy = ox - circles[c, 0], oy - circles[c, 1]
                b = fx * rx + fy * ry
                cc = fx * fx + fy * fy - circles[c, 2] ** 2
                disc = b * b - cc
                if disc < 0.0:
                    continue
                sq = math.sqrt(disc)
                t_in, t_out = -b - sq, -b + sq
                zb, zt = circle_z[c, 0], circle_z[c, 1]
            t_in = max(t_in, 0.0)
            if t_out < t_in or t_in > t_max:
                continue
            t_out = min(t_out, t_max)
            # earliest t in [t_in, t_out] with oz + slope·t within [zb, zt]
            z_in = oz + slope * t_in
            if zb <= z_in <= zt:
                t_hit = t_in
            elif z_in > zt and slope < 0.0:
                t_hit = (zt - oz) / slope
            elif z_in < zb and slope > 0.0:
                t_hit = (zb - oz) / slope
            else:
                continue
            if t_hit > t_out:
                continue
            d = t_hit / hlen
            if d < best:
                best = d
    return best


@lru_cache(maxsize=64)
def _beam_at_zero(model: RangeModel) -> npt.NDArray[np.float64]:
    """Unit ray directions of a round cone pointing along +x (computed once per model)."""
    n = max(1, model.rays)
    half = model.cone / 2
    angles = np.linspace(-half, half, n) if n > 1 else np.zeros(1)
    out = []
    for az in angles:
        for el in angles:
            if az * az + el * el > half * half + 1e-12:
                continue  # a round cone
            out.append((math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)))
    return np.array(out, dtype=np.float64)


def _beam(yaw: float, model: RangeModel) -> npt.NDArray[np.float64]:
    """The cone's rays turned to ``yaw`` (rad) about z."""
    base = _beam_at_zero(model)
    c, s = math.cos(yaw), math.sin(yaw)
    out = np.empty_like(base)
    out[:, 0] = c * base[:, 0] - s * base[:, 1]
    out[:, 1] = s * base[:, 0] + c * base[:, 1]
    out[:, 2] = base[:, 2]
    return out


def range_reading(world: World, robot_pose: npt.ArrayLike, mount: RangeMount,
                  people: npt.NDArray[np.float64] | None = None,
                  rng: np.random.Generator | None = None) -> float:
    """Distance (m) the sensor at ``mount`` reads with the robot at (x, y, theta); +Inf
    when nothing is within ``mount.model.max_range``. ``people`` (N, 3) x, y, radius are
    1.7 m cylinders. ``rng`` adds ``model.noise`` relative Gaussian noise."""
    x, y, th = (float(v) for v in np.asarray(robot_pose, dtype=np.float64)[:3])
    c, s = math.cos(th), math.sin(th)
    ox, oy = x + c * mount.x - s * mount.y, y + s * mount.x + c * mount.y
    arr = world.arrays
    circles, circle_z = arr.circles, arr.circle_z
    if people is not None and len(people):
        p = np.asarray(people, dtype=np.float64).reshape(-1, 3)
        circles = np.concatenate([circles, p])
        circle_z = np.concatenate([circle_z, np.column_stack([np.zeros(len(p)), np.full(len(p), 1.7)])])
    d = _cast_rays(ox, oy, mount.z, _beam(th + mount.yaw, mount.model), arr.quads, arr.quad_z,
                   circles, circle_z, mount.model.max_range)
    if math.isfinite(d) and rng is not None and mount.model.noise > 0:
        d *= 1.0 + mount.model.noise * float(rng.standard_normal())
    return float(d)


def range_readings(world: World, robot_pose: npt.ArrayLike,
                   mounts: dict[str, RangeMount] | None = None,
                   people: npt.NDArray[np.float64] | None = None,
                   rng: np.random.Generator | None = None) -> dict[str, float]:
    """Readings of every sensor in ``mounts`` (default: Eddie's `RANGE_MOUNTS`), m."""
    mounts = RANGE_MOUNTS if mounts is None else mounts
    return {name: range_reading(world, robot_pose, m, people, rng) for name, m in mounts.items()}


def mounts_from_table(sensors: Iterable[Any], rays: int = 5) -> dict[str, RangeMount]:
    """`RangeMount`s from a robot sensor table (`eddiebot.robot.constants.IR_SENSORS`,
    ``PING_SENSORS``: poses on base_link, ``kind``, limits and field of view), keyed by the
    table's names (``ir_left``, ...). Adds the URDF ray-link offset used by `RANGE_MOUNTS`."""
    from eddiebot.robot.constants import BASE_LINK_HEIGHT_M

    out: dict[str, RangeMount] = {}
    for s in sensors:
        kind = str(getattr(s.kind, "value", s.kind))
        dz = 0.04 if kind == "ir" else 0.035
        model = RangeModel(kind, cone=float(s.field_of_view_rad), rays=rays,
                           min_range=float(s.min_range_m), max_range=float(s.max_range_m))
        yaw = float(s.yaw_rad)
        out[s.name] = RangeMount(s.name, s.x_m - math.sin(yaw) * 0.0025,
                                 s.y_m + math.cos(yaw) * 0.0025,
                                 BASE_LINK_HEIGHT_M + s.z_m + dz, yaw, model)
    return out
