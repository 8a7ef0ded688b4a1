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
