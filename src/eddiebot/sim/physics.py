"""Differential-drive physics with wheel slip, encoder noise, collisions and moving people.

Pure functions: ``step(state, wheel_speeds, dt, world, params, rng) -> state``. The wheels
turn at the commanded angular speeds (rad/s); the encoders count that turning (plus noise).
The body moves as the wheels' ground contact dictates, scaled per wheel and per step by
``1 + slip`` (seeded Gaussian, plus a fixed bias per wheel), so wheel odometry drifts
the way a real base's does. The robot is a circle (radius 0.2245 m); its motion over a step
is swept along the exact arc, cut into chords of at most ``max_chord_rotation`` rad, and
each chord is tested as a swept circle against every obstacle segment, cylinder and person:
no tunnelling at any speed or step. On contact the robot stops a ``skin`` short of the
obstacle (its wheels keep turning: a stalled base on a real floor skids), and the collision
counter increments once per contact (not per blocked step).
"""

from __future__ import annotations

import math
from bisect import bisect_right
from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np
import numpy.typing as npt
from numba import njit

from eddiebot.sim.world import ROBOT_RADIUS, Person, World

__all__ = [
    "CollisionGeometry",
    "DriveParams",
    "PeopleState",
    "RobotState",
    "collision_geometry",
    "init_people",
    "people_positions",
    "step",
    "step_people",
    "twist_to_wheel_speeds",
    "wheel_speeds_to_twist",
]


@dataclass(frozen=True)
class DriveParams:
    """Eddie's drive. Lengths in m, angles in rad."""

    wheel_radius: float = 0.0762
    track: float = 0.39
    robot_radius: float = ROBOT_RADIUS
    slip_std: float = 0.0
    """Per-wheel, per-step multiplicative ground-speed noise (fraction, 1σ)."""
    slip_bias_left: float = 0.0
    """Fixed fraction added to the left wheel's ground speed (e.g. −0.01: 1 % slower)."""
    slip_bias_right: float = 0.0
    encoder_noise_std: float = 0.0
    """Noise added to each wheel's encoder angle per step (rad, 1σ)."""
    max_chord_rotation: float = 0.05
    skin: float = 1e-3
    """Gap kept to obstacles on contact (m)."""


@dataclass(frozen=True)
class RobotState:
    """Ground truth of the simulated robot.

    ``x, y, theta``: pose of base_footprint in the world frame (m, rad).
    ``v, w``: body speed over the last step (m/s, rad/s).
    ``left_angle, right_angle``: wheel rotation as the encoders see it (rad, with noise).
    ``collisions``: contacts so far; ``in_contact``: blocked during the last step.
    """

    x: float = 0.0
    y: float = 0.0
    theta: float = 0.0
    v: float = 0.0
    w: float = 0.0
    left_angle: float = 0.0
    right_angle: float = 0.0
    collisions: int = 0
    in_contact: bool = False
    time: float = 0.0

    @property
    def pose(self) -> npt.NDArray[np.float64]:
        return np.array([self.x, self.y, self.theta])


@dataclass(frozen=True)
class CollisionGeometry:
    """Obstacle outlines the robot can hit: segments (N, 4) x0, y0, x1, y1 and circles
    (M, 3) x, y, r, in the world frame (m)."""

    segments: npt.NDArray[np.float64]
    circles: npt.NDArray[np.float64]


def collision_geometry(world: World) -> CollisionGeometry:
    """Edges of every quad and every circle between ground clearance and robot height."""
    segs: list[tuple[float, float, float, float]] = []
    circles: list[tuple[float, float, float]] = []
    for p in world.obstacles():
        if p.circle is not None:
            circles.append(p.circle)
        elif p.quad is not None:
            q = p.quad
            for i in range(4):
                a, b = q[i], q[(i + 1) % 4]
                segs.append((a[0], a[1], b[0], b[1]))
    return CollisionGeometry(np.array(segs, dtype=np.float64).reshape(-1, 4),
                             np.array(circles, dtype=np.float64).reshape(-1, 3))


def twist_to_wheel_speeds(v: float, w: float, params: DriveParams = DriveParams()) -> tuple[float, float]:
    """(left, right) wheel angular speeds (rad/s) for a body twist (m/s, rad/s)."""
    half = params.track / 2
    return (v - w * half) / params.wheel_radius, (v + w * half) / params.wheel_radius


def wheel_speeds_to_twist(left: float, right: float, params: DriveParams = DriveParams()) -> tuple[float, float]:
    """Body twist (m/s, rad/s) from (left, right) wheel angular speeds (rad/s)."""
    vl, vr = left * params.wheel_radius, right * params.wheel_radius
    return (vl + vr) / 2, (vr - vl) / params.track


@njit(cache=True)
def _sweep(x0: float, y0: float, x1: float, y1: float, radius: float,
           segs: npt.NDArray[np.float64], circles: npt.NDArray[np.float64]) -> float:
    """Earliest fraction in [0, 1] of the move (x0, y0) → (x1, y1) at which a circle of
    ``radius`` touches an obstacle; 2.0 when free. A start already touching blocks only
    moves that go further in."""
    dx, dy = x1 - x0, y1 - y0
    best = 2.0
    for i in range(segs.shape[0]):
        ax, ay, bx, by = segs[i, 0], segs[i, 1], segs[i, 2], segs[i, 3]
        ex, ey = bx - ax, by - ay
        el2 = ex * ex + ey * ey
        # closest point on the segment to the start
        t = 0.0
        if el2 > 0.0:
            t = min(1.0, max(0.0, ((x0 - ax) * ex + (y0 - ay) * ey) / el2))
        cx, cy = ax + t * ex, ay + t * ey
        ox, oy = x0 - cx, y0 - cy
        if ox * ox + oy * oy <= radius * radius:
            if ox * dx + oy * dy < 0.0:  # moving towards it
                return 0.0
            continue
        # capsule = side band ∪ two end discs; earliest entry of the moving point
        if el2 > 0.0:
            el = math.sqrt(el2)
            nx, ny = -ey / el, ex / el
            d0 = (x0 - ax) * nx + (y0 - ay) * ny
            dd = dx * nx + dy * ny
            if dd != 0.0:
                side = radius if d0 > 0 else -radius
                s = (side - d0) / dd
                if 0.0 <= s <= 1.0:
                    px, py = x0 + s * dx, y0 + s * dy
                    u = ((px - ax) * ex + (py - ay) * ey) / el2
                    if 0.0 <= u <= 1.0 and s < best:
                        best = s
        for k in range(2):
            qx, qy = (ax, ay) if k == 0 else (bx, by)
            fx, fy = x0 - qx, y0 - qy
            a = dx * dx + dy * dy
            if a == 0.0:
                continue
            b = 2.0 * (fx * dx + fy * dy)
            c = fx * fx + fy * fy - radius * radius
            disc = b * b - 4 * a * c
            if disc >= 0.0:
                s = (-b - math.sqrt(disc)) / (2 * a)
                if 0.0 <= s <= 1.0 and s < best:
                    best = s
    for i in range(circles.shape[0]):
        r = circles[i, 2] + radius
        fx, fy = x0 - circles[i, 0], y0 - circles[i, 1]
        c = fx * fx + fy * fy - r * r
        if c <= 0.0:
            if fx * dx + fy * dy < 0.0:
                return 0.0
            continue
        a = dx * dx + dy * dy
        if a == 0.0:
            continue
        b = 2.0 * (fx * dx + fy * dy)
        disc = b * b - 4 * a * c
        if disc >= 0.0:
            s = (-b - math.sqrt(disc)) / (2 * a)
            if 0.0 <= s <= 1.0 and s < best:
                best = s
    return best


def _arc(x: float, y: float, th: float, ds: float, dth: float) -> tuple[float, float, float]:
    if abs(dth) < 1e-9:
        return x + ds * math.cos(th), y + ds * math.sin(th), th + dth
    r = ds / dth
    return (x + r * (math.sin(th + dth) - math.sin(th)),
            y - r * (math.cos(th + dth) - math.cos(th)), th + dth)


def step(
    state: RobotState,
    wheel_speeds: tuple[float, float],
    dt: float,
    geometry: CollisionGeometry,
    params: DriveParams = DriveParams(),
    rng: np.random.Generator | None = None,
    people: npt.NDArray[np.float64] | None = None,
) -> RobotState:
    """Advance the robot by ``dt`` seconds at (left, right) wheel speeds (rad/s).

    ``people`` are extra circles (N, 3) (x, y, radius) held still during the step. ``rng``
    drives slip and encoder noise (required when either is non-zero).
    """
    wl, wr = float(wheel_speeds[0]), float(wheel_speeds[1])
    noisy = params.slip_std > 0 or params.encoder_noise_std > 0
    if noisy and rng is None:
        raise ValueError("slip_std or encoder_noise_std is set: pass a seeded rng")
    sl = 1.0 + params.slip_bias_left
    sr = 1.0 + params.slip_bias_right
    if params.slip_std > 0 and rng is not None:
        sl += params.slip_std * float(rng.standard_normal())
        sr += params.slip_std * float(rng.standard_normal())
    dl = wl * dt * params.wheel_radius * sl
    dr = wr * dt * params.wheel_radius * sr
    ds, dth = (dl + dr) / 2, (dr - dl) / params.track

    circles = geometry.circles
    if people is not None and len(people):
        circles = np.concatenate([circles, np.asarray(people, dtype=np.float64).reshape(-1, 3)])
    radius = params.robot_radius + params.skin
    n = max(1, math.ceil(abs(dth) / params.max_chord_rotation))
    x, y, th = state.x, state.y, state.theta
    blocked = False
    for i in range(n):
        nx, ny, nth = _arc(state.x, state.y, state.theta, ds * (i + 1) / n, dth * (i + 1) / n)
        f = _sweep(x, y, nx, ny, radius, geometry.segments, circles)
        if f <= 1.0:
            # stop short: back off so the gap stays >= skin
            seg = math.hypot(nx - x, ny - y)
            back = min(f, max(0.0, f - params.skin / seg)) if seg > 0 else 0.0
            x, y = x + back * (nx - x), y + back * (ny - y)
            th = nth
            blocked = True
            break
        x, y, th = nx, ny, nth
    if blocked:
        th = state.theta + dth  # a circle turns freely in place
    la = state.left_angle + wl * dt
    ra = state.right_angle + wr * dt
    if params.encoder_noise_std > 0 and rng is not None:
        la += params.encoder_noise_std * float(rng.standard_normal())
        ra += params.encoder_noise_std * float(rng.standard_normal())
    moved = math.hypot(x - state.x, y - state.y)
    sign = 1.0 if ds >= 0 else -1.0
    return RobotState(
        x=x, y=y, theta=math.atan2(math.sin(th), math.cos(th)),
        v=sign * moved / dt if dt > 0 else 0.0, w=dth / dt if dt > 0 else 0.0,
        left_angle=la, right_angle=ra,
        collisions=state.collisions + (1 if blocked and not state.in_contact else 0),
        in_contact=blocked, time=state.time + dt,
    )


# ------------------------------------------------------------------------------- people
@dataclass(frozen=True)
class PeopleState:
    """Each person's position along its path: arc length (m) and direction (+1/-1), whether
    they wait for the robot, and how far they stepped aside (m, left of their walking
    direction positive)."""

    s: tuple[float, ...]
    direction: tuple[int, ...]
    waiting: tuple[bool, ...]
    offset: tuple[float, ...] = ()


@lru_cache(maxsize=256)
def _path_geometry(p: Person) -> tuple[tuple[tuple[float, float], ...], tuple[float, ...]]:
    """The path's points (closed when looping) and cumulative arc lengths, as tuples: people
    are stepped every physics tick, and tiny numpy arrays would cost more than the maths."""
    pts = tuple((float(x), float(y)) for x, y in (*p.path, *((p.path[0],) if p.loop else ())))
    cum = [0.0]
    for (x0, y0), (x1, y1) in zip(pts[:-1], pts[1:]):
        cum.append(cum[-1] + math.hypot(x1 - x0, y1 - y0))
    return pts, tuple(cum)


def _path_len(p: Person) -> npt.NDArray[np.float64]:
    return np.asarray(_path_geometry(p)[1])


def _pos_dir(p: Person, s: float) -> tuple[float, float, float, float]:
    """Point at arc length ``s`` and the unit direction of its segment."""
    pts, cum = _path_geometry(p)
    total = cum[-1]
    s = s % total if p.loop else min(max(s, 0.0), total)
    i = min(max(bisect_right(cum, s) - 1, 0), len(cum) - 2)
    seg = max(cum[i + 1] - cum[i], 1e-12)
    t = (s - cum[i]) / seg
    (ax, ay), (bx, by) = pts[i], pts[i + 1]
    return ax + t * (bx - ax), ay + t * (by - ay), (bx - ax) / seg, (by - ay) / seg


def _pos(p: Person, s: float, offset: float = 0.0, direction: int = 1) -> tuple[float, float]:
    x, y, ux, uy = _pos_dir(p, s)
    # the offset is to the left of the walking direction
    return x - direction * uy * offset, y + direction * ux * offset


def init_people(world: World) -> PeopleState:
    n = len(world.people)
    return PeopleState(s=(0.0,) * n, direction=(1,) * n, waiting=(False,) * n, offset=(0.0,) * n)


def people_positions(world: World, state: PeopleState) -> npt.NDArray[np.float64]:
    """(N, 3) x, y, radius of every person now."""
    out = np.zeros((len(world.people), 3))
    offsets = state.offset or (0.0,) * len(world.people)
    for i, p in enumerate(world.people):
        out[i, :2] = _pos(p, state.s[i], offsets[i], state.direction[i])
        out[i, 2] = p.radius
    return out


#: how far a person steps aside to let the robot pass (m), and how fast (m/s)
STEP_ASIDE_M = 0.7
STEP_ASIDE_SPEED = 0.4
#: a yielding person steps away from the point this far ahead of the robot (m): out of the
#: way it is heading (a doorway it turns into), not only away from where it stands
YIELD_LOOKAHEAD_M = 0.6


def step_people(world: World, state: PeopleState, robot: RobotState, dt: float,
                margin: float = 0.15, robot_radius: float = ROBOT_RADIUS) -> PeopleState:
    """Walk everyone ``dt`` seconds along their paths. A person whose next position would
    come within ``margin`` of the robot waits (yields) and steps aside, away from where the
    robot is heading (the point ``YIELD_LOOKAHEAD_M`` ahead of it), by up to
    ``STEP_ASIDE_M``; once clear they drift back onto their path. (People walk through
    walls: their paths and side-steps must have room.)"""
    s_out, d_out, w_out, o_out = [], [], [], []
    offsets = state.offset or (0.0,) * len(world.people)
    for i, p in enumerate(world.people):
        total = _path_geometry(p)[1][-1]
        s, d, off = state.s[i], state.direction[i], offsets[i]
        ns = s + d * p.speed * dt
        nd = d
        if not p.loop and (ns > total or ns < 0):
            nd = -d
            ns = total - (ns - total) if ns > total else -ns
        nx, ny = _pos(p, ns, off, nd)
        clear = math.hypot(nx - robot.x, ny - robot.y) - p.radius - robot_radius
        now_x, now_y = _pos(p, s, off, d)
        now_clear = math.hypot(now_x - robot.x, now_y - robot.y) - p.radius - robot_radius
        if clear < margin and clear < now_clear:
            # blocked: wait, and step aside, out of the robot's way
            _, _, ux, uy = _pos_dir(p, s)
            left = (-d * uy, d * ux)
            hx = robot.x + YIELD_LOOKAHEAD_M * math.cos(robot.theta)
            hy = robot.y + YIELD_LOOKAHEAD_M * math.sin(robot.theta)
            side = 1.0 if (now_x - hx) * left[0] + (now_y - hy) * left[1] >= 0 else -1.0
            if off != 0.0:
                side = math.copysign(1.0, off)
            # ... but never into the robot: a robot facing the path has its heading point
            # on the far side of the path, and the step away from that point is towards it
            for sign in (side, -side):
                # turning to the other side starts from the path (a side once left is not
                # taken again, or the person would dither between the two)
                base = abs(off) if off * sign >= 0 else 0.0
                step_off = sign * min(STEP_ASIDE_M, base + STEP_ASIDE_SPEED * dt)
                ax, ay = _pos(p, s, step_off, d)
                if math.hypot(ax - robot.x, ay - robot.y) - p.radius - robot_radius >= min(
                        now_clear, margin):
                    off = step_off
                    break
            s_out.append(s)
            d_out.append(d)
            w_out.append(True)
        else:
            if off != 0.0 and clear > 2 * margin + 0.3:
                off = math.copysign(max(0.0, abs(off) - STEP_ASIDE_SPEED * dt), off)
            s_out.append(ns % total if p.loop else ns)
            d_out.append(nd)
            w_out.append(False)
        o_out.append(off)
    return replace(state, s=tuple(s_out), direction=tuple(d_out), waiting=tuple(w_out),
                   offset=tuple(o_out))
