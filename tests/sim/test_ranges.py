"""IR and PING distances for known geometry."""

from __future__ import annotations

import math

import numpy as np
import pytest

from eddiebot.sim import RANGE_MOUNTS, parse_world, range_reading, range_readings


def _wall(x, height=2.0, bottom=0.0):
    return parse_world({"start": {"x": 0, "y": 0},
                        "boxes": [{"center": [x + 0.05, 0], "size": [0.1, 20], "height": height,
                                   "bottom": bottom}]})


def test_ir_center_reads_wall_distance():
    m = RANGE_MOUNTS["ir/center"]
    for d in (0.15, 0.4, 0.75):
        world = _wall(m.x + d)
        assert range_reading(world, (0, 0, 0), m) == pytest.approx(d, abs=1e-9)
    assert range_reading(_wall(m.x + 0.85), (0, 0, 0), m) == math.inf  # beyond 80 cm


def test_ir_side_sensors_at_45_degrees():
    left = RANGE_MOUNTS["ir/left"]
    world = _wall(left.x + 0.3)
    # the beam's ray nearest the wall normal is 1.5° off the 45° axis
    assert range_reading(world, (0, 0, 0), left) == pytest.approx(0.3 / math.cos(math.radians(45 - 1.5)), abs=1e-6)
    # turning the robot by -45° points it straight at the wall
    x, y = left.x, left.y
    th = -math.pi / 4
    sx = math.cos(th) * x - math.sin(th) * y
    world = _wall(sx + 0.5)
    assert range_reading(world, (0, 0, th), left) == pytest.approx(0.5, abs=1e-9)


def test_ping_cone_and_limits():
    m = RANGE_MOUNTS["ping/left"]  # yaw +22.5°, cone 15°
    world = _wall(m.x + 2.0)
    assert range_reading(world, (0, 0, 0), m) == pytest.approx(2.0 / math.cos(math.radians(15)), abs=1e-6)
    assert range_reading(_wall(m.x + 3.5), (0, 0, 0), m) == math.inf  # beyond 3.19 m
    # a thin pole off the axis but inside the cone is seen
    world = parse_world({"start": {"x": 0, "y": 0},
                         "cylinders": [{"center": [m.x + 1.0 * math.cos(math.radians(28)),
                                                   m.y + 1.0 * math.sin(math.radians(28))],
                                        "radius": 0.02, "height": 1.0}]})
    assert range_reading(world, (0, 0, 0), m) == pytest.approx(0.98, abs=0.01)


def test_heights_matter():
    m = RANGE_MOUNTS["ir/center"]  # ray at ~0.166 m
    assert m.z == pytest.approx(0.16625)
    low = _wall(m.x + 0.4, height=0.1)
    assert range_reading(low, (0, 0, 0), m) == math.inf  # a 10 cm step is under the IR beam
    table = _wall(m.x + 0.4, height=0.75, bottom=0.7)
    assert range_reading(table, (0, 0, 0), m) == math.inf
    # PING's cone reaches down: a 10 cm step 0.3 m ahead passes under the lowest ray's
    # height at its face, so that ray (−7.5°) meets the step's top
    p = RANGE_MOUNTS["ping/right"]
    th = math.pi / 8  # point it straight ahead
    sx = math.cos(th) * p.x - math.sin(th) * p.y
    world = _wall(sx + 0.3, height=0.1)
    d = range_reading(world, (0, 0, th), p)
    assert d == pytest.approx((p.z - 0.1) / math.sin(math.radians(7.5)), abs=1e-6)
    world = _wall(sx + 0.3, height=0.14)
    d = range_reading(world, (0, 0, th), p)
    assert d == pytest.approx(0.3 / math.cos(math.radians(7.5)), abs=0.02)


def test_all_readings_and_people():
    world = _wall(1.0)
    r = range_readings(world, (0, 0, 0))
    assert set(r) == {"ir/left", "ir/center", "ir/right", "ping/left", "ping/right"}
    assert r["ir/center"] == pytest.approx(1.0 - RANGE_MOUNTS["ir/center"].x)
    assert r["ping/right"] == pytest.approx(r["ping/left"], abs=0.005)  # URDF offsets are not mirrored
    people = np.array([[0.5, 0.0, 0.1]])
    assert range_reading(world, (0, 0, 0), RANGE_MOUNTS["ir/center"], people) == pytest.approx(0.4 - 0.21, abs=1e-4)


def test_mounts_from_robot_constants_table():
    from eddiebot.robot.constants import IR_SENSORS, PING_SENSORS
    from eddiebot.sim.ranges import mounts_from_table

    mounts = mounts_from_table(IR_SENSORS + PING_SENSORS)
    assert set(mounts) == {"ir_left", "ir_center", "ir_right", "ping_left", "ping_right"}
    for name, ours in RANGE_MOUNTS.items():
        theirs = mounts[name.replace("/", "_")]
        assert (theirs.x, theirs.y, theirs.z, theirs.yaw) == pytest.approx((ours.x, ours.y, ours.z, ours.yaw))
    world = _wall(1.0)
    c = mounts["ir_center"]
    assert range_reading(world, (0, 0, 0), c) == pytest.approx(1.0 - c.x)
