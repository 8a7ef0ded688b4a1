"""DWB critics (``dwb_critics``): the map-grid wavefront, aggregation, the footprint and
velocity critics, and their parameters."""

from __future__ import annotations

import numpy as np
import pytest
from navtest_helpers import make_costmap

from eddiebot.nav.controllers import DWBController, build_controller_server
from eddiebot.nav.controllers.dwb import dwb_config_from_params
from eddiebot.nav.controllers.dwb_critics import (
    adjust_plan_resolution,
    goal_dist_values,
    map_grid_wavefront,
    path_dist_values,
    score_base_obstacle,
    score_map_grid,
    score_obstacle_footprint,
    score_prefer_forward,
    score_twirling,
)
from eddiebot.nav.errors import ParameterError
from eddiebot.nav.types import Twist2D

RES = 0.1


def _walled_grid() -> np.ndarray:
    """20 × 20 free cells with a lethal wall along x = 10 for y = 0..15."""
    grid = np.zeros((20, 20), dtype=np.uint8)
    grid[0:16, 10] = 254
    return grid


def test_wavefront_scores_grid_distance_not_euclidean() -> None:
    vals = map_grid_wavefront(20, 20, np.array([[15, 15]]))
    assert vals[15, 15] == 0.0
    # (5, 5) is 14.1 cells from the seed as the crow flies; the wave counts 10 + 10.
    assert vals[5, 5] == 20.0
    assert vals[15, 3] == 12.0
    assert vals.max() == 30.0  # corner (0, 0)


def test_wavefront_equals_nearest_manhattan_seed() -> None:
    rng = np.random.default_rng(4)
    seeds = rng.integers(0, 30, size=(7, 2))
    vals = map_grid_wavefront(30, 25, seeds[seeds[:, 1] < 25])
    s = seeds[seeds[:, 1] < 25]
    yy, xx = np.mgrid[0:25, 0:30]
    brute = np.min(np.abs(xx[..., None] - s[:, 0]) + np.abs(yy[..., None] - s[:, 1]), axis=-1)
    np.testing.assert_array_equal(vals, brute)


def test_plan_behind_a_wall_scored_by_wavefront_distance() -> None:
    """A plan along x = 1.55 m behind a wall: the cell (0.55, 0.55) scores its grid distance
    (10 cells). Jazzy's queue lets the wave through lethal cells (navigation2#719), so the
    wall neither blocks it nor marks cells as obstacles; PathDist stays legal there."""
    grid = _walled_grid()
    plan = np.stack([np.full(20, 1.55), np.arange(20) * RES + 0.05, np.zeros(20)], axis=1)
    vals = path_dist_values(plan, grid, (0.0, 0.0), RES)
    assert vals is not None
    assert vals[5, 5] == 10.0 and vals[5, 10] == 5.0 and vals[17, 3] == 12.0
    traj = np.array([[[0.35, 0.55, 0.0], [0.45, 0.55, 0.0], [0.55, 0.55, 0.0]]])
    sc, ok = score_map_grid(traj, vals, (0.0, 0.0), RES, "last", True)
    assert ok[0] and sc[0] == 10.0
    sc, _ = score_map_grid(traj, vals, (0.0, 0.0), RES, "sum", True)
    assert sc[0] == 12.0 + 11.0 + 10.0
    sc, _ = score_map_grid(traj, vals, (0.0, 0.0), RES, "product", True)
    assert sc[0] == 12.0 * 11.0 * 10.0
    # The Align critics score the pose forward_point_distance ahead: 0.3 m east = 3 cells.
    sc, _ = score_map_grid(traj, vals, (0.0, 0.0), RES, "last", False, 0.3)
    assert sc[0] == 7.0


def test_plan_seeds_skip_unknown_and_stop_leaving_the_costmap() -> None:
    grid = np.zeros((20, 20), dtype=np.uint8)
    grid[:, 0:3] = 255  # unknown: no seeds there
    # Starts off the map (x < 0), crosses unknown, runs east along y = 0.55, leaves the map
    # at x = 2.0 and comes back at y = 1.55: the return is not seeded.
    xs = np.arange(-0.25, 2.5, RES)
    back = np.arange(2.45, 0.3, -RES)
    plan = np.concatenate([np.stack([xs, np.full(xs.size, 0.55)], 1),
                           np.stack([back, np.full(back.size, 1.55)], 1)])
    vals = path_dist_values(plan, grid, (0.0, 0.0), RES)
    assert vals is not None
    assert vals[5, 3] == 0.0 and vals[5, 19] == 0.0
    assert vals[5, 2] == 1.0  # unknown cells are scored, not seeded
    assert vals[15, 10] == 10.0  # the plan's return leg is not a seed
    goal = goal_dist_values(plan, grid, (0.0, 0.0), RES)
    assert goal is not None and goal[5, 19] == 0.0 and goal[5, 3] == 16.0
    assert path_dist_values(np.array([[5.0, 5.0, 0.0]]), grid, (0.0, 0.0), RES) is None


def test_map_grid_off_grid_pose_is_illegal() -> None:
    vals = map_grid_wavefront(10, 10, np.array([[5, 5]]))
    traj = np.array([[[0.55, 0.55, 0.0], [1.05, 0.55, 0.0], [0.95, 0.55, 0.0]]])
    for stop in (True, False):
        _, ok = score_map_grid(traj, vals, (0.0, 0.0), RES, "sum", stop)
        assert not ok[0]
    # "last" without stop_on_failure only looks at the final pose.
    sc, ok = score_map_grid(traj, vals, (0.0, 0.0), RES, "last", False)
    assert ok[0] and sc[0] == 4.0


def test_adjust_plan_resolution_fills_gaps_as_nav_2d_utils() -> None:
    out = adjust_plan_resolution(np.array([[0.0, 0.0, 0.0], [2.0, 0.0, 0.0]]), 0.25)
    np.testing.assert_allclose(out[:, 0], [0.0, 0.4, 0.8, 1.2, 1.6, 2.0])
    same = adjust_plan_resolution(np.array([[0.0, 0.0], [0.4, 0.0]]), 0.25)
    assert same.shape == (2, 2)


def test_base_obstacle_scores_last_pose_or_sum() -> None:
    grid = np.zeros((10, 10), dtype=np.uint8)
    grid[5, 3] = 40
    grid[5, 4] = 100
    traj = np.array([[[0.35, 0.55, 0.0], [0.45, 0.55, 0.0], [0.55, 0.55, 0.0]],
                     [[0.35, 0.55, 0.0], [0.45, 0.55, 0.0], [0.45, 0.65, 0.0]]])
    sc, ok = score_base_obstacle(traj, grid, 0.0, 0.0, RES, False)
    assert ok.all() and sc.tolist() == [0.0, 0.0]
    sc, _ = score_base_obstacle(traj, grid, 0.0, 0.0, RES, True)
    assert sc.tolist() == [140.0, 140.0]
    for c in (253, 254, 255):
        grid[6, 4] = c
        _, ok = score_base_obstacle(traj, grid, 0.0, 0.0, RES, False)
        assert ok.tolist() == [True, False]


def test_obstacle_footprint_outline() -> None:
    grid = np.zeros((20, 20), dtype=np.uint8)
    grid[10, 13] = 180  # under the square's east edge, not under its centre
    fp = np.array([[0.2, 0.2], [-0.2, 0.2], [-0.2, -0.2], [0.2, -0.2]])
    traj = np.array([[[1.15, 1.05, 0.0]], [[0.85, 1.05, 0.0]]])
    sc, ok = score_obstacle_footprint(traj, fp, grid, 0.0, 0.0, RES, False)
    assert ok.tolist() == [True, True] and sc.tolist() == [180.0, 0.0]
    _, base_ok = score_base_obstacle(traj, grid, 0.0, 0.0, RES, False)
    assert base_ok.all()
    grid[10, 13] = 253  # inscribed is legal for the outline, lethal and unknown are not
    sc, ok = score_obstacle_footprint(traj, fp, grid, 0.0, 0.0, RES, False)
    assert ok.all() and sc[0] == 253.0
    for c in (254, 255):
        grid[10, 13] = c
        _, ok = score_obstacle_footprint(traj, fp, grid, 0.0, 0.0, RES, False)
        assert ok.tolist() == [False, True]
    # A vertex off the grid is illegal even though the centre is on it.
    _, ok = score_obstacle_footprint(np.array([[[0.1, 1.0, 0.0]]]), fp, grid, 0.0, 0.0, RES,
                                     False)
    assert not ok[0]


def test_prefer_forward_and_twirling() -> None:
    vx = np.array([-0.1, 0.05, 0.05, 0.2, 0.2])
    wz = np.array([0.0, 0.1, 0.5, 0.3, -0.3])
    sc, ok = score_prefer_forward(vx, wz, 1.0, 0.1, 0.2, 10.0)
    np.testing.assert_allclose(sc, [1.0, 1.0, 5.0, 3.0, 3.0])
    assert ok.all()
    np.testing.assert_allclose(score_twirling(wz)[0], [0.0, 0.1, 0.5, 0.3, 0.3])


def test_critic_parameters_from_nav2_yaml() -> None:
    cfg = dwb_config_from_params({
        "critics": ["ObstacleFootprint", "PreferForward", "Twirling", "PathDist"],
        "PreferForward": {"penalty": 2.0, "strafe_x": 0.05, "theta_scale": 4.0},
        "Twirling.scale": 0.5, "PathDist.aggregation_type": "sum",
        "ObstacleFootprint": {"sum_scores": True},
    })
    assert (cfg.PreferForward_penalty, cfg.PreferForward_strafe_x,
            cfg.PreferForward_strafe_theta, cfg.PreferForward_theta_scale) == (2.0, 0.05, 0.2, 4.0)
    assert cfg.Twirling_scale == 0.5 and cfg.PathDist_aggregation_type == "sum"
    assert cfg.ObstacleFootprint_sum_scores and cfg.GoalDist_aggregation_type == "last"
    with pytest.raises(ParameterError, match=r"PathAlign\.aggregation_type"):
        build_controller_server({"FollowPath": {"plugin": "dwb_core::DWBLocalPlanner",
                                                "critics": ["PathAlign"],
                                                "PathAlign.aggregation_type": "max"}})


def test_controller_path_align_scale() -> None:
    """PathAlign weighs resolution/2 · scale and drops out near the goal."""
    cm = make_costmap(np.zeros((60, 60), dtype=np.int8))
    plan = np.stack([np.linspace(0.5, 2.5, 41), np.full(41, 1.5), np.zeros(41)], axis=1)
    cfg = dwb_config_from_params({
        "max_vel_x": 0.3, "max_speed_xy": 0.3, "max_vel_theta": 1.0, "acc_lim_x": 2.5,
        "acc_lim_theta": 3.2, "decel_lim_x": -2.5, "decel_lim_theta": -3.2, "vy_samples": 1,
        "critics": ["PathAlign", "Twirling"], "PathAlign.scale": 32.0,
        "PathAlign.forward_point_distance": 0.325})
    ctrl = DWBController(cfg)
    cmd = ctrl.compute_velocity_commands((0.5, 1.55, 0.0), Twist2D(0.2, 0.0, 0.0), plan, cm)
    vals = ctrl.grid_values["PathAlign"]
    assert vals[30, 20] == 0.0 and vals[31, 20] == 1.0 and vals[40, 20] == 10.0
    assert abs(cmd.wz) <= 1.0
    traj = np.array([[[1.0, 1.55, 0.0]]])
    pose = np.array([0.5, 1.55, 0.0])
    sc, ok, scale = ctrl._map_grid("PathAlign", traj, pose, plan[-1], plan, cm, 32.0)
    # 0.325 m ahead of (1.0, 1.55) is cell (26, 31): one cell off the plan's row 30.
    assert ok[0] and sc[0] == 1.0 and scale == pytest.approx(0.05 * 0.5 * 32.0)
    near = np.array([2.3, 1.5, 0.0])  # within forward_point_distance of the goal: scale 0
    assert ctrl._map_grid("PathAlign", traj, near, plan[-1], plan, cm, 32.0)[2] == 0.0


@pytest.mark.parametrize("critic", ["PathDist", "GoalDist", "GoalAlign", "PathAlign"])
def test_every_map_grid_critic_weighs_resolution_half_scale(critic: str) -> None:
    """MapGridCritic::getScale: cell distances count resolution / 2 · scale, so 24 on a 0.05 m
    grid is 0.6 per cell (12 per metre), comparable to BaseObstacle's 0.02 · cost."""
    cm = make_costmap(np.zeros((60, 60), dtype=np.int8))
    plan = np.stack([np.linspace(0.5, 2.5, 41), np.full(41, 1.5), np.zeros(41)], axis=1)
    ctrl = DWBController(dwb_config_from_params({
        "max_vel_x": 0.3, "max_speed_xy": 0.3, "max_vel_theta": 1.0, "acc_lim_x": 2.5,
        "acc_lim_theta": 3.2, "decel_lim_x": -2.5, "decel_lim_theta": -3.2, "vy_samples": 1,
        "critics": [critic]}))
    traj = np.array([[[1.0, 1.75, 0.0]]])
    pose = np.array([0.5, 1.55, 0.0])
    sc, ok, scale = ctrl._map_grid(critic, traj, pose, plan[-1], plan, cm, 24.0)
    assert ok[0] and scale == pytest.approx(0.05 * 0.5 * 24.0)
    if critic == "PathDist":
        assert sc[0] == 5.0  # (1.0, 1.75) is 5 cells above the plan's row


def test_rotate_to_goal_window_latches_until_a_new_plan() -> None:
    """RotateToGoalCritic::prepare: once the robot was within xy_goal_tolerance (0.25 m), a
    pose that localization puts just outside it still only turns in place, until the plan is
    set again (upstream's in_window_ / rotating_)."""
    cm = make_costmap(np.zeros((60, 60), dtype=np.int8))
    plan = np.stack([np.linspace(0.5, 1.5, 21), np.full(21, 1.5), np.full(21, 1.2)], axis=1)
    cfg = dwb_config_from_params({
        "max_vel_x": 0.3, "max_speed_xy": 0.3, "max_vel_theta": 1.0, "acc_lim_x": 2.5,
        "acc_lim_theta": 3.2, "decel_lim_x": -2.5, "decel_lim_theta": -3.2, "vy_samples": 1,
        "critics": ["RotateToGoal", "GoalDist"], "RotateToGoal.scale": 32.0,
        "GoalDist.scale": 24.0})
    ctrl = DWBController(cfg)
    inside = (1.3, 1.5, 0.0)  # 0.20 m short of the goal, 1.2 rad off its heading
    cmd = ctrl.compute_velocity_commands(inside, Twist2D(), plan, cm)
    assert cmd.vx == 0.0 and cmd.wz > 0.0
    outside = (1.22, 1.5, 0.1)  # 0.28 m short: outside the window, the same plan
    cmd = ctrl.compute_velocity_commands(outside, Twist2D(0.0, 0.0, cmd.wz), plan, cm)
    assert cmd.vx == 0.0 and cmd.wz > 0.0
    ctrl.set_plan(plan.copy())  # a new plan resets the window: GoalDist drives again
    cmd = ctrl.compute_velocity_commands(outside, Twist2D(), None, cm)
    assert cmd.vx > 0.0
