"""Differential drive, slip statistics, encoder noise, collisions, people."""

from __future__ import annotations

import math

import numpy as np
import pytest

from eddiebot.sim import (
    DriveParams,
    RobotState,
    collision_geometry,
    init_people,
    parse_world,
    people_positions,
    step,
    step_people,
    twist_to_wheel_speeds,
)

EMPTY = collision_geometry(parse_world({"start": {"x": 0, "y": 0}}))


def _wall_world(thickness=0.02, x=3.0):
    return parse_world({
        "start": {"x": 0, "y": 0},
        "walls": [{"points": [[x, -5], [x, 5]], "thickness": thickness, "height": 2.0}],
    })


def test_straight_and_rotation_kinematics():
    p = DriveParams()
    s = RobotState()
    for _ in range(50):
        s = step(s, twist_to_wheel_speeds(0.5, 0.0, p), 0.02, EMPTY, p)
    assert (s.x, s.y, s.theta) == pytest.approx((0.5, 0.0, 0.0), abs=1e-9)
    assert s.left_angle == pytest.approx(0.5 / 0.0762)
    s = RobotState()
    for _ in range(100):
        s = step(s, twist_to_wheel_speeds(0.0, math.pi / 2, p), 0.01, EMPTY, p)
    assert s.theta == pytest.approx(math.pi / 2, abs=1e-9)
    assert math.hypot(s.x, s.y) < 1e-9
    # an arc: quarter circle of radius 1 m
    s = RobotState()
    for _ in range(100):
        s = step(s, twist_to_wheel_speeds(math.pi / 2, math.pi / 2, p), 0.01, EMPTY, p)
    assert (s.x, s.y, s.theta) == pytest.approx((1.0, 1.0, math.pi / 2), abs=1e-6)


@pytest.mark.parametrize(("speed", "dt", "heading"), [(2.0, 0.1, 0.0), (2.0, 0.1, 0.7),
                                                       (10.0, 1.0, 0.0), (2.0, 0.1, -2.9)])
def test_no_tunnelling(speed, dt, heading):
    world = _wall_world(thickness=0.02)
    geom = collision_geometry(world)
    p = DriveParams()
    # head at the wall (x = 3) from the origin, or away from it for the last case
    s = RobotState(theta=heading)
    wheels = twist_to_wheel_speeds(speed, 0.0, p)
    for _ in range(100):
        s = step(s, wheels, dt, geom, p)
        assert s.x < 3.0 - 0.01 - p.robot_radius + 1e-9  # never through or into the wall
    if abs(heading) < 1.5:
        assert s.in_contact
        assert s.collisions == 1  # counted once per contact, not per blocked step
        assert s.x == pytest.approx(3.0 - 0.01 - p.robot_radius, abs=5e-3)
    else:
        assert s.collisions == 0


def test_contact_then_back_away_and_turn():
    geom = collision_geometry(_wall_world())
    p = DriveParams()
    s = RobotState()
    for _ in range(40):
        s = step(s, twist_to_wheel_speeds(1.0, 0.0, p), 0.1, geom, p)
    assert s.in_contact
    s = step(s, twist_to_wheel_speeds(0.0, 1.0, p), 0.1, geom, p)  # turning in place is free
    assert s.theta == pytest.approx(0.1)
    x = s.x
    s = step(s, twist_to_wheel_speeds(-0.5, 0.0, p), 0.1, geom, p)
    assert s.x < x - 0.04 and not s.in_contact
    for _ in range(10):
        s = step(s, twist_to_wheel_speeds(1.0, 0.0, p), 0.1, geom, p)
    assert s.collisions == 2


def test_cylinder_and_people_block():
    world = parse_world({"start": {"x": 0, "y": 0},
                         "cylinders": [{"center": [2.0, 0.0], "radius": 0.1, "height": 1.0}]})
    geom = collision_geometry(world)
    p = DriveParams()
    s = RobotState()
    for _ in range(30):
        s = step(s, twist_to_wheel_speeds(2.0, 0.0, p), 0.1, geom, p)
    assert s.x == pytest.approx(2.0 - 0.1 - p.robot_radius, abs=5e-3)
    s = RobotState(y=3.0)
    people = np.array([[1.0, 3.0, 0.25]])
    for _ in range(30):
        s = step(s, twist_to_wheel_speeds(2.0, 0.0, p), 0.1, geom, p, people=people)
    assert s.x == pytest.approx(1.0 - 0.25 - p.robot_radius, abs=5e-3)


def test_slip_drift_statistics_match_configuration():
    sigma, n_steps, dt, trials = 0.05, 100, 0.05, 300
    p = DriveParams(slip_std=sigma)
    wheels = twist_to_wheel_speeds(0.4, 0.0, p)
    rng = np.random.default_rng(42)
    headings, dists = [], []
    for _ in range(trials):
        s = RobotState()
        for _ in range(n_steps):
            s = step(s, wheels, dt, EMPTY, p, rng)
        headings.append(s.theta)
        dists.append(s.x)
    # per step: dθ = r·ω·dt·(ε_r − ε_l)/track, ds = r·ω·dt·(ε_l + ε_r)/2
    per_wheel = 0.4 * dt
    want_heading = math.sqrt(n_steps) * per_wheel * math.sqrt(2) * sigma / p.track
    assert np.std(headings) == pytest.approx(want_heading, rel=0.15)
    assert np.mean(headings) == pytest.approx(0.0, abs=3 * want_heading / math.sqrt(trials))
    assert np.mean(dists) == pytest.approx(2.0, abs=0.01)
    # a bias makes a systematic curve; the encoders don't see it
    p = DriveParams(slip_bias_left=-0.02)
    s = RobotState()
    for _ in range(n_steps):
        s = step(s, wheels, dt, EMPTY, p)
    assert s.theta == pytest.approx(n_steps * per_wheel * 0.02 / p.track, rel=1e-6)
    assert s.left_angle == pytest.approx(s.right_angle)


def test_encoder_noise_and_seeding():
    p = DriveParams(encoder_noise_std=0.01, slip_std=0.01)
    wheels = (1.0, 1.0)

    def run(seed):
        rng = np.random.default_rng(seed)
        s = RobotState()
        for _ in range(100):
            s = step(s, wheels, 0.1, EMPTY, p, rng)
        return s

    a, b, c = run(1), run(1), run(2)
    assert a == b and a != c
    errs = [run(k).left_angle - 10.0 for k in range(60)]
    assert np.std(errs) == pytest.approx(0.1, rel=0.3)
    with pytest.raises(ValueError, match="rng"):
        step(RobotState(), wheels, 0.1, EMPTY, p)


def test_a_yielding_person_steps_out_of_the_way_the_robot_is_heading():
    # the person walks east along y = 0; the robot stands just north-east of their path,
    # facing north into a doorway: stepping "away from the robot" would be south, but a
    # robot facing south (towards the person's path) makes them step north, out of its way
    world = parse_world({"start": {"x": 0, "y": 0},
                         "people": [{"path": [[0, 0], [10, 0]], "speed": 1.0, "loop": False}]})
    for theta, north in ((math.pi / 2, False), (-math.pi / 2, True)):
        ps = init_people(world)
        robot = RobotState(x=1.2, y=0.05, theta=theta)
        for _ in range(20):
            ps = step_people(world, ps, robot, 0.1)
        y = people_positions(world, ps)[0, 1]
        assert ps.waiting[0]
        assert (y > 0.3) if north else (y < -0.3), (theta, y)


def test_person_walks_and_yields():
    world = parse_world({"start": {"x": 0, "y": 0},
                         "people": [{"path": [[0, 5], [10, 5]], "speed": 1.0, "loop": False}]})
    ps = init_people(world)
    robot = RobotState(x=20.0, y=20.0)
    for _ in range(30):
        ps = step_people(world, ps, robot, 0.1)
    assert people_positions(world, ps)[0, :2] == pytest.approx((3.0, 5.0))
    robot = RobotState(x=4.0, y=5.0)  # in the way: the person waits, steps aside, passes
    waited, min_clear = False, np.inf
    for _ in range(60):
        ps = step_people(world, ps, robot, 0.1)
        waited = waited or ps.waiting[0]
        px, py = people_positions(world, ps)[0, :2]
        min_clear = min(min_clear, np.hypot(px - 4.0, py - 5.0) - 0.25 - 0.2245)
    assert waited
    assert min_clear > 0.0  # never walked into the robot
    assert people_positions(world, ps)[0, 0] > 4.0  # got past it
    robot = RobotState(x=20.0, y=20.0)  # moved away: walk on, turn round at the end
    for _ in range(100):
        ps = step_people(world, ps, robot, 0.1)
    assert ps.direction[0] == -1


def test_a_person_stepping_aside_never_steps_into_a_robot_facing_the_path():
    # the warehouse's aisle walker passing a robot stopped 0.47-0.55 m beside its path and
    # facing it: the step away from the robot's heading point is towards the robot
    world = parse_world({"start": {"x": 0, "y": 0},
                         "people": [{"path": [[2.0, 7.8], [28.0, 7.8]], "speed": 0.8,
                                     "loop": False}]})
    worst = np.inf
    for theta in np.linspace(-math.pi, math.pi, 16, endpoint=False):
        for dy in (0.3, 0.47, 0.55, -0.47):
            ps = init_people(world)
            robot = RobotState(x=20.0, y=7.8 + dy, theta=theta)
            for _ in range(2000):  # 40 s: past the robot
                ps = step_people(world, ps, robot, 0.02)
                px, py = people_positions(world, ps)[0, :2]
                worst = min(worst, math.hypot(px - robot.x, py - robot.y) - 0.25 - 0.2245)
            assert people_positions(world, ps)[0, 0] > 20.5, (theta, dy)  # got past
    assert worst >= 0.0  # before: -0.17 m (overlapping the robot: contacts it never made)
