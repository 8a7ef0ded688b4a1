"""The drive plant: time stepping, continuous positions, ideal-drive pose."""

from __future__ import annotations

import math

import pytest

from eddiebot.robot.constants import METRES_PER_POSITION, TRACK_M
from eddiebot.robot.plant import ControlMode, DrivePlant


def test_step_sizes_do_not_change_the_motion() -> None:
    fine, coarse = DrivePlant(), DrivePlant()
    for plant in (fine, coarse):
        plant.set_velocity(50, 20)
    for i in range(1, 3001):
        fine.advance_to_ns(i * 1_000_000)
    coarse.step(1.7)
    coarse.advance_to(3.0)
    assert fine.time_ns == coarse.time_ns == 3_000_000_000
    assert fine.wheel_positions == pytest.approx(coarse.wheel_positions, abs=1e-9)
    assert fine.counts == coarse.counts
    assert fine.true_pose == pytest.approx(coarse.true_pose, abs=1e-9)


def test_commands_take_effect_at_the_next_tick_and_positions_are_continuous() -> None:
    plant = DrivePlant()
    plant.set_acceleration(500)
    plant.set_velocity(40, 40)
    plant.advance_to(0.0)  # the tick at t = 0 starts the ramp
    plant.advance_to(0.01)
    left, _ = plant.wheel_positions
    assert 0.0 < left < 1.0  # half a tick of the first speed step
    assert plant.counts == (0, 0)
    plant.advance_to(2.0)
    assert plant.wheel_velocities == pytest.approx((40.0, 40.0))
    assert isinstance(plant.counts[0], int)
    assert plant.counts[0] == math.floor(plant.wheel_positions[0] + 1e-9)


def test_ideal_drive_pose_matches_the_arc() -> None:
    plant = DrivePlant()
    plant.set_acceleration(10_000)
    plant.set_velocity(30, 60)
    plant.advance_to(0.5)
    start = plant.true_pose
    l0, r0 = plant.wheel_positions
    plant.advance_to(4.5)
    l1, r1 = plant.wheel_positions
    assert (l1 - l0, r1 - r0) == pytest.approx((120.0, 240.0))
    dl, dr = (l1 - l0) * METRES_PER_POSITION, (r1 - r0) * METRES_PER_POSITION
    dtheta = (dr - dl) / TRACK_M
    radius = (dl + dr) / 2 / dtheta
    th0 = start[2]
    expected_x = start[0] + radius * (math.sin(th0 + dtheta) - math.sin(th0))
    expected_y = start[1] - radius * (math.cos(th0 + dtheta) - math.cos(th0))
    x, y, th = plant.true_pose
    assert (x, y) == pytest.approx((expected_x, expected_y), abs=1e-9)
    assert th == pytest.approx(math.remainder(th0 + dtheta, 2 * math.pi), abs=1e-9)


def test_speed_limit_and_disable() -> None:
    plant = DrivePlant()
    plant.set_acceleration(511)
    plant.set_velocity(300, -300)
    plant.advance_to(2.0)
    assert plant.wheel_velocities == pytest.approx((90.0, -90.0))  # no-load speed
    assert plant.speed_report == (90, -90)
    plant.disable()
    assert plant.mode is ControlMode.DISABLED
    plant.advance_to(2.5)
    assert plant.wheel_velocities == (0.0, 0.0)


@pytest.mark.parametrize("period_s", [0.05, 0.033, 0.1])
def test_repeating_the_same_gospd_does_not_slow_the_wheels(period_s: float) -> None:
    # A driver re-sends GOSPD at its own rate, out of phase with the 50 Hz loop: the wheels
    # must still turn at the set speed (each restart of the reference is at the next tick).
    once = DrivePlant()
    once.set_velocity(15, -15)
    once.advance_to(5.0)
    repeated = DrivePlant()
    t = 0.0
    while t < 5.0:
        repeated.set_velocity(15, -15)
        t = min(5.0, t + period_s)
        repeated.advance_to(t)
    assert repeated.wheel_positions[0] == pytest.approx(once.wheel_positions[0], abs=0.05)
    assert repeated.wheel_positions[1] == pytest.approx(once.wheel_positions[1], abs=0.05)
    assert repeated.wheel_velocities[0] == pytest.approx(15.0)
