"""Odometry against exact integration of integer wheel counts."""

import math

import numpy as np
import pytest

from eddiebot.base.kinematics import twist_to_wheel_positions, wheel_positions_to_twist
from eddiebot.base.odometry import DiffDriveOdometry, OdometryConfig, integrate_arc
from eddiebot.robot.constants import METRES_PER_POSITION, POSITIONS_PER_REV, TRACK_M

RAD_PER_COUNT = 2 * math.pi / POSITIONS_PER_REV


def reference(counts, sep=TRACK_M, mpc=METRES_PER_POSITION):
    """Independent closed-form integration of count increments."""
    x = y = th = 0.0
    for (l0, r0), (l1, r1) in zip(counts[:-1], counts[1:]):
        dl, dr = (l1 - l0) * mpc, (r1 - r0) * mpc
        ds, dth = (dl + dr) / 2, (dr - dl) / sep
        if dth == 0:
            x += ds * math.cos(th)
            y += ds * math.sin(th)
        else:
            x += ds / dth * (math.sin(th + dth) - math.sin(th))
            y += -ds / dth * (math.cos(th + dth) - math.cos(th))
        th = math.atan2(math.sin(th + dth), math.cos(th + dth))
    return x, y, th


def test_matches_exact_integration_of_counts():
    rng = np.random.default_rng(3)
    counts = [(0, 0)]
    for _ in range(2000):
        l, r = counts[-1]
        counts.append((l + int(rng.integers(-2, 5)), r + int(rng.integers(-2, 5))))
    odo = DiffDriveOdometry()
    for i, (l, r) in enumerate(counts):
        odo.update(l * RAD_PER_COUNT, r * RAD_PER_COUNT, i * 50_000_000)
    x, y, th = reference(counts)
    assert odo.x == pytest.approx(x, abs=1e-9)
    assert odo.y == pytest.approx(y, abs=1e-9)
    assert odo.theta == pytest.approx(th, abs=1e-9)
    assert -math.pi < odo.theta <= math.pi


def test_straight_and_spin():
    odo = DiffDriveOdometry()
    odo.update(0, 0, 0)
    s = odo.update(75 * RAD_PER_COUNT, 75 * RAD_PER_COUNT, 1_000_000_000)
    assert s.x == pytest.approx(75 * METRES_PER_POSITION)
    assert s.y == pytest.approx(0.0)
    assert s.linear == pytest.approx(75 * METRES_PER_POSITION)
    # spin in place: right forward, left back
    odo.reset()
    odo.update(0, 0, 0)
    s = odo.update(-10 * RAD_PER_COUNT, 10 * RAD_PER_COUNT, 500_000_000)
    assert s.theta == pytest.approx(20 * METRES_PER_POSITION / TRACK_M)
    assert math.hypot(s.x, s.y) < 1e-12
    assert s.angular > 0


def test_duplicate_out_of_order_and_reset():
    odo = DiffDriveOdometry()
    odo.update(0, 0, 0)
    odo.update(10 * RAD_PER_COUNT, 10 * RAD_PER_COUNT, 100_000_000)
    x = odo.x
    assert odo.update(10 * RAD_PER_COUNT, 10 * RAD_PER_COUNT, 100_000_000) is None
    assert odo.update(5 * RAD_PER_COUNT, 5 * RAD_PER_COUNT, 50_000_000) is None
    assert odo.x == x
    # the driver restarted: counters back at 0 after having been at 5000
    odo.update(5000 * RAD_PER_COUNT, 5000 * RAD_PER_COUNT, 200_000_000)  # big jump → reset
    assert odo.resets == 1 and odo.x == x
    s = odo.update(5003 * RAD_PER_COUNT, 5003 * RAD_PER_COUNT, 300_000_000)
    assert s.x == pytest.approx(x + 3 * METRES_PER_POSITION)


def test_velocity_is_rolling_mean_and_covariance_grows():
    odo = DiffDriveOdometry(OdometryConfig(velocity_rolling_window_size=10))
    odo.update(0, 0, 0)
    # alternate 1 and 0 counts per 50 ms: per-sample twist jumps 0.27 ↔ 0 m/s
    n = 0
    for i in range(1, 41):
        n += i % 2
        s = odo.update(n * RAD_PER_COUNT, n * RAD_PER_COUNT, i * 50_000_000)
    assert s.linear == pytest.approx(0.5 * METRES_PER_POSITION / 0.05, rel=1e-9)
    c1 = s.pose_covariance[0, 0]
    for i in range(41, 200):
        n += 1
        s = odo.update(n * RAD_PER_COUNT, n * RAD_PER_COUNT, i * 50_000_000)
    assert s.pose_covariance[0, 0] > c1 > 0
    assert np.all(np.linalg.eigvalsh(s.pose_covariance) >= -1e-15)


def test_integrate_arc_small_turn_uses_midpoint():
    x, y, th = integrate_arc(0, 0, 0, 1.0, 1.0 + 1e-9, TRACK_M)
    assert x == pytest.approx(1.0) and abs(y) < 1e-8


def test_kinematics_saturates_keeping_curvature():
    l, r = twist_to_wheel_positions(2.0, 1.0, max_positions_per_s=90)
    assert max(abs(l), abs(r)) == 90
    v, w = wheel_positions_to_twist(l, r)
    assert w / v == pytest.approx(0.5, rel=0.02)  # curvature kept
    assert twist_to_wheel_positions(float("nan"), 0.0, max_positions_per_s=90) == (0, 0)
    l, r = twist_to_wheel_positions(0.5, 0.0, max_positions_per_s=90)
    assert l == r == round(0.5 / METRES_PER_POSITION)


def test_veto_sees_the_path_not_the_door_jambs():
    import math as _m

    from eddiebot.base.safety import SafetyConfig, VetoState, limit_twist
    from eddiebot.robot.constants import IR_SENSORS, PING_SENSORS

    mounts = {s.name: (s.x_m, s.y_m, s.yaw_rad) for s in (*IR_SENSORS, *PING_SENSORS)}
    cfg = SafetyConfig(veto_distance=0.25, slowdown_distance=0.0)

    def forward(state: VetoState, linear: float) -> float:
        return limit_twist(linear, 0.0, state, cfg, 0)[0]

    jambs = VetoState(mounts=mounts)
    jambs.update({"ir_left": 0.2, "ir_right": 0.2, "ir_center": _m.inf}, 0)  # a door frame beside
    assert forward(jambs, 0.3) == 0.3
    wall = VetoState(mounts=mounts)
    wall.update({"ir_center": 0.2}, 0)  # a wall 0.2 m ahead of the front sensor
    assert forward(wall, 0.3) == 0.0
    assert forward(wall, -0.05) == -0.05  # backing away is allowed
    too_close = VetoState(mounts=mounts)
    too_close.update({"ping_left": -_m.inf}, 0)  # REP-117: closer than measurable
    assert forward(too_close, 0.3) == 0.0
    far = VetoState(mounts=mounts)
    far.update({"ping_left": 1.0, "ping_right": _m.nan}, 0)
    assert forward(far, 0.3) == 0.3
