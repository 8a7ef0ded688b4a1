"""Controllers (RPP, DWB) in a kinematic simulation; regulation formulas; checkers."""

from __future__ import annotations

import math

import numpy as np
import pytest
from navtest_helpers import make_costmap, simulate

from eddiebot.nav.controllers import (
    DWBConfig,
    DWBController,
    RegulatedPurePursuitConfig,
    RegulatedPurePursuitController,
    SimpleGoalChecker,
    SimpleGoalCheckerConfig,
    SimpleProgressChecker,
    build_controller_server,
)
from eddiebot.nav.controllers.rpp import circle_segment_intersection
from eddiebot.nav.errors import InvalidController, NoValidControl, ParameterError
from eddiebot.nav.types import Twist2D

LINE = np.stack([np.linspace(0.5, 5.0, 100), np.full(100, 3.0), np.zeros(100)], axis=1)
_TH = np.linspace(-np.pi / 2, np.pi / 2, 200)
ARC = np.stack([2.0 + 1.5 * np.cos(_TH), 3.0 + 1.5 * np.sin(_TH), _TH + np.pi / 2], axis=1)


def _dwb() -> DWBController:
    return DWBController(DWBConfig(
        max_vel_x=0.26, max_speed_xy=0.26, max_vel_theta=1.0, acc_lim_x=2.5, acc_lim_theta=3.2,
        decel_lim_x=-2.5, decel_lim_theta=-3.2, vy_samples=1,
        critics=("RotateToGoal", "Oscillation", "BaseObstacle", "GoalAlign", "PathAlign",
                 "PathDist", "GoalDist"),
        BaseObstacle_scale=0.02, PathAlign_scale=32.0, GoalAlign_scale=8.0,
        PathAlign_forward_point_distance=0.1, GoalAlign_forward_point_distance=0.1,
        PathDist_scale=32.0, GoalDist_scale=8.0, RotateToGoal_scale=32.0))
    # Goal critics at 8, not the Nav2 sample file's 24: with upstream's critic semantics
    # (PathAlign weighted resolution/2, local goal 2 m ahead) 24 cuts the 1.5 m arc's chord
    # by 0.48 m, beyond this test's cross-track bound.


@pytest.mark.parametrize("make", [RegulatedPurePursuitController, _dwb], ids=["rpp", "dwb"])
@pytest.mark.parametrize(("path", "start"), [(LINE, (0.5, 3.05, 0.0)), (ARC, (2.0, 1.5, 0.0))],
                         ids=["straight", "curved"])
def test_tracks_path_to_goal(empty_costmap, make, path, start) -> None:
    ctrl = make()
    checker = SimpleGoalChecker()
    pose, reached, log = simulate(ctrl, path, empty_costmap, start, checker, steps=1500)
    assert reached
    assert math.hypot(pose[0] - path[-1, 0], pose[1] - path[-1, 1]) <= 0.25
    assert abs((pose[2] - path[-1, 2] + math.pi) % (2 * math.pi) - math.pi) < 0.25
    # Stays near the path all the way (cross-track error).
    d = np.min(np.hypot(log[:, None, 0] - path[None, :, 0], log[:, None, 1] - path[None, :, 1]), axis=1)
    assert d.max() < 0.15


def test_rpp_regulation_formulas(empty_costmap) -> None:
    cfg = RegulatedPurePursuitConfig()
    ctrl = RegulatedPurePursuitController(cfg)
    long_path = np.stack([np.linspace(0, 5, 200), np.zeros(200), np.zeros(200)], axis=1)
    pose = np.array([1.0, 3.0, 0.0])
    tpath = long_path.copy()
    # Curvature: radius 0.45 < 0.9 -> v * 0.45 / 0.9.
    v = ctrl._apply_constraints(1.0 / 0.45, pose, tpath, 0.5, 1.0, empty_costmap)
    assert v == pytest.approx(0.25)
    v = ctrl._apply_constraints(1.0 / 0.6, pose, tpath, 0.5, 1.0, empty_costmap)
    assert v == pytest.approx(0.5 * 0.6 / 0.9)
    # Approach: remaining 0.3 m < 0.6 m -> v * 0.3 / 0.6, floored at min_approach_linear_velocity.
    short = np.stack([np.linspace(0, 0.3, 10), np.zeros(10), np.zeros(10)], axis=1)
    assert ctrl._apply_constraints(0.0, pose, short, 0.5, 1.0, empty_costmap) == pytest.approx(0.25)
    tiny = np.stack([np.linspace(0, 0.03, 3), np.zeros(3), np.zeros(3)], axis=1)
    assert ctrl._apply_constraints(0.0, pose, tiny, 0.5, 1.0, empty_costmap) == pytest.approx(0.05)


def test_rpp_cost_regulation() -> None:
    occ = np.zeros((80, 80), dtype=np.int8)
    occ[40, 48] = 100
    cm = make_costmap(occ, robot_radius=0.2, inflation_radius=0.55, cost_scaling_factor=3.0)
    ctrl = RegulatedPurePursuitController(RegulatedPurePursuitConfig(
        use_regulated_linear_velocity_scaling=False, regulated_linear_scaling_min_speed=0.0))
    pose = np.array([2.025, 2.025, 0.0])
    c = cm.master.cost_at_world(pose[0], pose[1])
    assert 0 < c < 253
    dist = (3.0 * cm.inscribed_radius - math.log(c) + math.log(253.0)) / 3.0
    long_path = np.stack([np.linspace(0, 5, 50), np.zeros(50), np.zeros(50)], axis=1)
    v = ctrl._apply_constraints(0.0, pose, long_path, 0.5, 1.0, cm)
    assert v == pytest.approx(0.5 * dist / 0.6)


def test_rpp_rotates_to_path_heading_with_accel_limit(empty_costmap) -> None:
    ctrl = RegulatedPurePursuitController()
    # Path straight behind the robot: rotate in place, w limited by max_angular_accel * dt.
    cmd = ctrl.compute_velocity_commands((3.0, 3.0, 0.0), Twist2D(), np.stack(
        [np.linspace(3.0, 1.0, 40), np.full(40, 3.1), np.full(40, math.pi)], axis=1),
        empty_costmap, 0.05)
    assert cmd.vx == 0.0
    assert abs(cmd.wz) == pytest.approx(3.2 * 0.05)


def test_rpp_collision_ahead_raises() -> None:
    occ = np.zeros((100, 100), dtype=np.int8)
    occ[:, 60] = 100
    cm = make_costmap(occ, robot_radius=0.2, inflation_radius=0.3)
    path = np.stack([np.linspace(2.5, 4.5, 60), np.full(60, 2.5), np.zeros(60)], axis=1)
    ctrl = RegulatedPurePursuitController()
    with pytest.raises(NoValidControl) as exc:
        ctrl.compute_velocity_commands((2.6, 2.5, 0.0), Twist2D(0.5, 0, 0), path, cm, 0.05)
    assert exc.value.result_code == 106


def test_circle_segment_intersection() -> None:
    p = circle_segment_intersection(np.array([0.5, 0.0]), np.array([2.0, 0.0]), 1.0)
    assert np.allclose(p, [1.0, 0.0])
    p = circle_segment_intersection(np.array([0.0, 0.5]), np.array([0.0, -2.0]), 1.0)
    assert np.allclose(p, [0.0, -1.0])


def test_rpp_parameter_errors() -> None:
    with pytest.raises(ParameterError) as exc:
        RegulatedPurePursuitController(RegulatedPurePursuitConfig(allow_reversing=True))
    assert exc.value.key == "allow_reversing"


def test_goal_checker_stateful_and_not() -> None:
    gc = SimpleGoalChecker()
    goal = np.array([1.0, 1.0, 0.0])
    assert not gc.is_goal_reached((1.1, 1.1, 1.0), goal)  # xy ok, yaw not: xy latched
    assert gc.is_goal_reached((1.4, 1.0, 0.1), goal)  # drifted beyond 0.25 m: still ok
    gc.reset()
    assert not gc.is_goal_reached((1.4, 1.0, 0.1), goal)
    gc2 = SimpleGoalChecker(SimpleGoalCheckerConfig(stateful=False))
    assert not gc2.is_goal_reached((1.1, 1.1, 1.0), goal)
    assert not gc2.is_goal_reached((1.4, 1.0, 0.1), goal)
    assert gc2.is_goal_reached((1.1, 1.1, -0.2), goal)
    assert gc.tolerances() == (0.25, 0.25)


def test_progress_checker() -> None:
    pc = SimpleProgressChecker()
    s = 1_000_000_000
    assert pc.check((0, 0, 0), 0)
    assert pc.check((0.3, 0, 0), 9 * s)
    assert not pc.check((0.4, 0, 0), 10 * s + 1)
    assert pc.check((0.6, 0, 0), 11 * s)  # moved beyond 0.5 m: new baseline
    assert pc.check((0.6, 0, 0), 20 * s)
    assert not pc.check((0.6, 0, 0), 22 * s)
    pc.reset()
    assert pc.check((0.6, 0, 0), 30 * s)


def test_controller_server_registry() -> None:
    srv = build_controller_server({
        "controller_plugins": ["FollowPath", "DWB"],
        "goal_checker_plugins": ["general_goal_checker"],
        "FollowPath": {"plugin": "nav2_regulated_pure_pursuit_controller::RegulatedPurePursuitController",
                       "desired_linear_vel": 0.4},
        "DWB": {"plugin": "dwb_core::DWBLocalPlanner", "max_vel_x": 0.3,
                "critics": ["BaseObstacle", "PathDist"], "BaseObstacle.scale": 0.02},
        "general_goal_checker": {"plugin": "nav2_controller::SimpleGoalChecker",
                                 "xy_goal_tolerance": 0.1},
    })
    assert srv.controller("FollowPath").config.desired_linear_vel == 0.4
    dwb = srv.controller("DWB")
    assert dwb.config.max_vel_x == 0.3 and dwb.config.BaseObstacle_scale == 0.02
    assert srv.goal_checkers["general_goal_checker"].config.xy_goal_tolerance == 0.1
    assert "progress_checker" in srv.progress_checkers
    with pytest.raises(InvalidController) as exc:
        srv.controller("MPPI")
    assert exc.value.result_code == 101
    with pytest.raises(ParameterError):
        build_controller_server({"FollowPath": {"plugin": "dwb_core::DWBLocalPlanner",
                                                "critics": ["Spiral"]}})


def test_rpp_reverses_when_allowed(empty_costmap) -> None:
    ctrl = RegulatedPurePursuitController(RegulatedPurePursuitConfig(
        allow_reversing=True, use_rotate_to_heading=False))
    path = np.stack([np.linspace(3.0, 1.0, 40), np.full(40, 3.0), np.zeros(40)], axis=1)
    cmd = ctrl.compute_velocity_commands((3.0, 3.0, 0.0), Twist2D(), path, empty_costmap, 0.05)
    assert cmd.vx < 0.0 and abs(cmd.wz) < 1e-6


def test_rpp_velocity_scaled_lookahead_and_speed_limit(empty_costmap) -> None:
    ctrl = RegulatedPurePursuitController(RegulatedPurePursuitConfig(
        use_velocity_scaled_lookahead_dist=True))
    path = np.stack([np.linspace(1.0, 5.0, 200), np.full(200, 3.0), np.zeros(200)], axis=1)
    ctrl.compute_velocity_commands((1.0, 3.0, 0.0), Twist2D(0.5, 0, 0), path, empty_costmap, 0.05)
    assert math.hypot(*(ctrl.last_carrot - [0, 0])) == pytest.approx(0.75, abs=1e-6)  # 0.5*1.5
    ctrl.set_speed_limit(50.0, True)
    cmd = ctrl.compute_velocity_commands((1.0, 3.0, 0.0), Twist2D(0.5, 0, 0), path,
                                         empty_costmap, 0.05)
    assert cmd.vx == pytest.approx(0.25)
    ctrl.set_speed_limit(0.0, True)
    cmd = ctrl.compute_velocity_commands((1.0, 3.0, 0.0), Twist2D(0.5, 0, 0), path,
                                         empty_costmap, 0.05)
    assert cmd.vx == pytest.approx(0.5)


def test_follow_path_run_to_success_and_failure_tolerance() -> None:
    from eddiebot.nav.controllers import ControllerServerConfig
    from eddiebot.nav.controllers.follow_path import FollowPathRun, RunStatus

    occ = np.zeros((120, 120), dtype=np.int8)
    cm = make_costmap(occ)
    cfg = ControllerServerConfig(failure_tolerance=0.3)
    run = FollowPathRun(cfg, RegulatedPurePursuitController(), SimpleGoalChecker(),
                        SimpleProgressChecker(), LINE, 0)
    pose = np.array([0.5, 3.0, 0.0])
    vel = Twist2D()
    for k in range(1, 400):
        st = run.step(pose, vel, cm, k * 50_000_000)
        if st.status is not RunStatus.RUNNING:
            break
        vel = st.cmd
        pose[0] += vel.vx * math.cos(pose[2]) * 0.05
        pose[1] += vel.vx * math.sin(pose[2]) * 0.05
        pose[2] += vel.wz * 0.05
    assert st.status is RunStatus.SUCCEEDED and st.distance_to_goal <= 0.25
    # Blocked: collision ahead is tolerated for failure_tolerance seconds, then fails.
    occ[:, 40] = 100
    blocked = make_costmap(occ, robot_radius=0.2, inflation_radius=0.3)
    run = FollowPathRun(cfg, RegulatedPurePursuitController(), SimpleGoalChecker(),
                        SimpleProgressChecker(), LINE, 0)
    statuses = [run.step((1.6, 3.0, 0.0), Twist2D(0.3, 0, 0), blocked, k * 100_000_000).status
                for k in range(1, 6)]
    assert statuses[:2] == [RunStatus.RUNNING] * 2 and statuses[-1] is RunStatus.FAILED


def test_a_new_path_resets_the_stateful_goal_checker() -> None:
    # Nav2's setPlannerPath resets the goal checker with every new path. Without it the xy
    # test latched on the old goal stayed passed: exploring, a preempting goal home 15 m
    # away was "reached" 2 s later when the turning robot's yaw passed the start's heading.
    from eddiebot.nav.controllers import ControllerServerConfig
    from eddiebot.nav.controllers.follow_path import FollowPathRun, RunStatus

    cm = make_costmap(np.zeros((120, 120), dtype=np.int8))
    checker = SimpleGoalChecker()
    run = FollowPathRun(ControllerServerConfig(), RegulatedPurePursuitController(), checker,
                        SimpleProgressChecker(), LINE, 0)
    end = LINE[-1]
    # on the goal's spot, turned away from its heading: the xy test passes and latches
    assert run.step((end[0], end[1], end[2] + 1.5), Twist2D(), cm, 50_000_000).status \
        is RunStatus.RUNNING
    far = np.array([[end[0], end[1], math.pi], [end[0] - 3.0, end[1], math.pi]])
    run.update_path(far)
    # facing the new goal's heading, 3 m from it: not there
    st = run.step((end[0], end[1], math.pi), Twist2D(), cm, 100_000_000)
    assert st.status is RunStatus.RUNNING and st.distance_to_goal == pytest.approx(3.0)
