"""Behaviour cores: spin, back up, drive on heading, wait, assisted teleop."""

from __future__ import annotations

import math

import numpy as np
import pytest
from navtest_helpers import make_costmap

from eddiebot.nav.behaviors import AssistedTeleop, BackUp, DriveOnHeading, Spin, Status, Wait
from eddiebot.nav.errors import CollisionAhead
from eddiebot.nav.types import Twist2D

NS = 100_000_000  # one 10 Hz cycle


def _run(beh, pose, cm, cycles=400):
    pose = np.array(pose, dtype=float)
    for k in range(1, cycles):
        step = beh.update(pose, k * NS, cm)
        if step.status is not Status.RUNNING:
            return pose, step
        c = step.cmd
        pose[0] += c.vx * math.cos(pose[2]) * 0.1
        pose[1] += c.vx * math.sin(pose[2]) * 0.1
        pose[2] = (pose[2] + c.wz * 0.1 + math.pi) % (2 * math.pi) - math.pi
    return pose, step


def test_spin_turns_by_target(empty_costmap) -> None:
    spin = Spin()
    spin.start((3.0, 3.0, 3.0), math.pi, 0)
    pose, step = _run(spin, (3.0, 3.0, 3.0), empty_costmap)
    assert step.status is Status.SUCCEEDED
    turned = (pose[2] - 3.0) % (2 * math.pi)
    assert turned == pytest.approx(math.pi, abs=0.11)  # within one 0.1 s step at <= 1 rad/s


def test_spin_velocity_profile(empty_costmap) -> None:
    spin = Spin()
    spin.start((3.0, 3.0, 0.0), -1.0, 0)
    step = spin.update((3.0, 3.0, 0.0), NS, empty_costmap)
    assert step.cmd.wz == pytest.approx(-1.0)  # sqrt(2*3.2*1.0) clamped to max 1.0
    step = spin.update((3.0, 3.0, -0.99), 2 * NS, empty_costmap)
    assert step.cmd.wz == pytest.approx(-0.4)  # sqrt(2*3.2*0.01)=0.25 -> min 0.4


def test_backup_and_collision_ahead() -> None:
    occ = np.zeros((120, 120), dtype=np.int8)
    occ[:, 20] = 100  # wall at x = 1.0 m
    cm = make_costmap(occ, robot_radius=0.2, inflation_radius=0.3)
    b = BackUp()
    b.start((3.0, 3.0, 0.0), 0.3, 0.1, 0)
    pose, step = _run(b, (3.0, 3.0, 0.0), cm)
    assert step.status is Status.SUCCEEDED and pose[0] == pytest.approx(2.7, abs=0.011)
    b.start((1.6, 3.0, 0.0), 1.0, 0.2, 0)
    _, step = _run(b, (1.6, 3.0, 0.0), cm)
    assert step.status is Status.FAILED and isinstance(step.error, CollisionAhead)
    assert step.error.result_code == 703


def test_drive_on_heading_and_timeout(empty_costmap) -> None:
    d = DriveOnHeading()
    d.start((1.0, 3.0, 0.0), 0.5, 0.25, 0, time_allowance=1.0)
    _, step = _run(d, (1.0, 3.0, 0.0), empty_costmap)
    assert step.status is Status.FAILED and step.error.result_code == 701
    d.start((1.0, 3.0, 0.0), 0.5, 0.25, 0, time_allowance=10.0)
    pose, step = _run(d, (1.0, 3.0, 0.0), empty_costmap)
    assert step.status is Status.SUCCEEDED and pose[0] >= 1.5


def test_wait() -> None:
    w = Wait()
    w.start(1.0, 0)
    assert w.update(None, 5 * NS).status is Status.RUNNING
    assert w.time_left(5 * NS) == pytest.approx(0.5)
    assert w.update(None, 10 * NS).status is Status.SUCCEEDED


def test_assisted_teleop_scales_near_obstacles() -> None:
    occ = np.zeros((120, 120), dtype=np.int8)
    occ[:, 80] = 100  # wall at x = 4.0 m
    cm = make_costmap(occ, robot_radius=0.2, inflation_radius=0.3)
    a = AssistedTeleop()
    a.start(0)
    a.set_teleop(Twist2D(0.5, 0.0, 0.0))
    assert a.update((1.0, 3.0, 0.0), NS, cm).cmd == Twist2D(0.5, 0.0, 0.0)
    near = a.update((3.5, 3.0, 0.0), NS, cm).cmd
    assert 0.0 < near.vx < 0.5
    assert a.update((3.75, 3.0, 0.0), NS, cm).cmd == Twist2D()


def _commands(beh, pose, cm, cycles=400):
    """Commanded vx per cycle until the behaviour ends (10 Hz, unicycle integration)."""
    pose = np.array(pose, dtype=float)
    out = []
    for k in range(1, cycles):
        step = beh.update(pose, k * NS, cm)
        if step.status is not Status.RUNNING:
            return np.array(out), pose, step
        out.append(step.cmd.vx)
        pose[0] += step.cmd.vx * math.cos(pose[2]) * 0.1
    return np.array(out), pose, step


def test_backup_speed_ramp(empty_costmap) -> None:
    from eddiebot.nav.behaviors import DriveOnHeadingConfig

    b = BackUp(drive=DriveOnHeadingConfig(acceleration_limit=0.5, deceleration_limit=-0.5,
                                          minimum_speed=0.02))
    b.start((3.0, 3.0, 0.0), 0.5, 0.25, 0)
    vx, pose, step = _commands(b, (3.0, 3.0, 0.0), empty_costmap)
    assert step.status is Status.SUCCEEDED
    # 0.5 m/s² at 10 Hz: 0.05 m/s more each cycle up to the commanded 0.25 m/s, backwards.
    np.testing.assert_allclose(vx[:6], [-0.05, -0.10, -0.15, -0.20, -0.25, -0.25])
    # Then capped by sqrt(2·0.5·remaining) so it stops on the target, never below 0.02.
    travelled = np.concatenate([[0.0], np.cumsum(-vx * 0.1)])[:-1]
    np.testing.assert_allclose(-vx, np.minimum.reduce([
        np.full(vx.size, 0.25), np.sqrt(np.maximum(0.5 - travelled, 0.0)),
        np.concatenate([[0.05], -vx[:-1] + 0.05])]).clip(0.02), atol=1e-12)
    assert -vx[-1] <= 0.12 and 3.0 - pose[0] == pytest.approx(0.5, abs=0.013)
    # Defaults (2.5 m/s², minimum 0.1 m/s): full speed after one cycle.
    b = BackUp()
    b.start((3.0, 3.0, 0.0), 0.5, 0.25, 0)
    vx, _, _ = _commands(b, (3.0, 3.0, 0.0), empty_costmap)
    assert vx[0] == pytest.approx(-0.25) and -vx.min() == pytest.approx(0.25)
    assert np.all(np.abs(vx) >= 0.1 - 1e-12)


def test_drive_on_heading_limits_from_params() -> None:
    from eddiebot.nav.behaviors import build_behaviors

    _, behs = build_behaviors({
        "behavior_plugins": ["drive_on_heading", "backup"],
        "drive_on_heading": {"plugin": "nav2_behaviors/DriveOnHeading",
                             "acceleration_limit": 1.0, "deceleration_limit": 2.0},
        "backup": {"plugin": "nav2_behaviors::BackUp", "minimum_speed": 0.05},
    })
    d = behs["drive_on_heading"]
    assert isinstance(d, DriveOnHeading)
    assert (d.drive.acceleration_limit, d.drive.minimum_speed) == (1.0, 0.10)
    assert behs["backup"].drive.minimum_speed == 0.05
    # deceleration_limit 2.0 is taken as -2.0 (upstream corrects the sign): stopping cap
    # sqrt(2·2·0.01) = 0.2 with 0.01 m left.
    d.start((0.0, 0.0, 0.0), 1.0, 0.5, 0)
    d._last_vel = 0.5
    assert d._ramped_speed(0.01) == pytest.approx(0.2)
