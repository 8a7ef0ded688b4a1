"""The MPPI optimiser and controller: its pieces with numbers, convergence on a straight
path and around a corner, and a goal in the same kinematic harness RPP and DWB run in."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from navtest_helpers import make_costmap, simulate

from eddiebot.nav.controllers import SimpleGoalChecker, build_controller_server
from eddiebot.nav.controllers.mppi import MPPIConfig, MPPIController, mppi_params
from eddiebot.nav.controllers.mppi._kernels import predict_velocities
from eddiebot.nav.controllers.mppi.optimizer import integrate, savitzky_golay
from eddiebot.nav.controllers.mppi.path_handler import (
    MPPIPathHandler,
    first_after_integrated_distance,
    first_path_inversion,
)
from eddiebot.nav.cost_values import INSCRIBED_INFLATED_OBSTACLE
from eddiebot.nav.errors import InvalidPath, NoValidControl, ParameterError, UnsupportedPlugin
from eddiebot.nav.planners import NavfnPlanner
from eddiebot.nav.types import Twist2D

JAZZY = Path(__file__).resolve().parents[1] / "data" / "nav2" / "nav2_params_jazzy.yaml"
LINE = np.stack([np.linspace(0.5, 5.0, 100), np.full(100, 3.0), np.zeros(100)], axis=1)
_TH = np.linspace(-np.pi / 2, np.pi / 2, 200)
ARC = np.stack([2.0 + 1.5 * np.cos(_TH), 3.0 + 1.5 * np.sin(_TH), _TH + np.pi / 2], axis=1)


def jazzy_follow_path() -> dict[str, Any]:
    doc = yaml.safe_load(JAZZY.read_text())
    return dict(doc["controller_server"]["ros__parameters"]["FollowPath"])


def jazzy_mppi(seed: int = 3, **overrides: Any) -> MPPIController:
    params = jazzy_follow_path()
    params.update(overrides)
    return MPPIController.from_params(params, seed=seed)


def test_predict_clamps_controls_to_the_accelerations() -> None:
    cvx = np.full((2, 5), 1.0)
    cwz = np.full((2, 5), -2.0)
    vx = np.zeros((2, 5))
    wz = np.zeros((2, 5))
    vx[1, 0] = -0.2  # reversing: the deceleration bound applies the other way round
    predict_velocities(cvx, cwz, vx, wz, 0.15, -0.15, 0.175)
    assert vx[0] == pytest.approx([0.0, 0.15, 0.30, 0.45, 0.60])
    assert vx[1] == pytest.approx([-0.2, -0.05, 0.10, 0.25, 0.40])
    assert wz[0] == pytest.approx([0.0, -0.175, -0.35, -0.525, -0.70])
    assert cvx[0, :4] == pytest.approx(vx[0, 1:])  # the controls are clamped in place
    assert cvx[0, 4] == 1.0


def test_integrate_moves_along_the_previous_heading() -> None:
    x, y, yaw = integrate(np.array([1.0, 2.0, math.pi / 2]), np.array([1.0, 1.0, 1.0]),
                          np.array([0.0, math.pi / 2 / 0.1, 0.0]), 0.1)
    # step 0 along +y; step 1 turns to pi (still moving along +y); step 2 along -x
    assert x == pytest.approx([1.0, 1.0, 0.9])
    assert y == pytest.approx([2.1, 2.2, 2.2])
    assert yaw == pytest.approx([math.pi / 2, math.pi, math.pi])


def test_savitzky_golay_keeps_quadratics_and_the_last_entry() -> None:
    k = np.arange(-4.0, 26.0)
    seq = 0.01 * k[4:] ** 2 - 0.3 * k[4:]
    out = savitzky_golay(seq, 0.01 * k[:4] ** 2 - 0.3 * k[:4])
    # a 9-point quadratic fit reproduces a quadratic where the window lies inside it
    assert out[:-5] == pytest.approx(seq[:-5])
    assert out[-1] == seq[-1]
    impulse = np.zeros(30)
    impulse[10] = 231.0
    assert savitzky_golay(impulse, np.zeros(4))[6:15] == pytest.approx(
        [-21, 14, 39, 54, 59, 54, 39, 14, -21])


def test_path_handler_prunes_and_crops_at_inversions() -> None:
    cm = make_costmap(np.zeros((120, 120), dtype=np.int8))
    assert first_after_integrated_distance(LINE, 1.0) == 23  # 0.04545 m spacing
    h = MPPIPathHandler(prune_distance=1.0)
    h.set_path(LINE)
    seg = h.transform_path(np.array([1.52, 3.1, 0.0]), cm)
    assert seg[0, 0] == pytest.approx(LINE[22, 0])  # closest pose to x = 1.52
    assert seg.shape[0] == 23 and seg[-1, 0] < 2.55
    assert h.goal() == pytest.approx(LINE[-1])
    back = np.concatenate([LINE[:50], LINE[48::-1]])  # out and back
    assert first_path_inversion(back) == 50  # the first pose of the way back
    h = MPPIPathHandler(enforce_path_inversion=True)
    h.set_path(back)
    assert h.plan_up_to_inversion.shape[0] == 50 and h.inversion_locale == 50
    seg = h.transform_path(np.array([0.5, 3.0, 0.0]), cm)
    assert seg[:, 0].max() <= LINE[49, 0] + 1e-9  # the optimiser sees only the way out
    h.transform_path(np.array([*LINE[49, :2].tolist(), 0.0]), cm)  # at the cusp: the rest
    assert h.inversion_locale == 0 and h.plan_up_to_inversion[-1, 0] == pytest.approx(0.5)
    with pytest.raises(InvalidPath):
        MPPIPathHandler().set_path(np.zeros((0, 3)))


def test_jazzy_sample_section_loads() -> None:
    p = mppi_params(jazzy_follow_path())
    c = p.config
    assert (c.batch_size, c.time_steps, c.model_dt, c.prune_distance) == (2000, 56, 0.05, 1.7)
    assert (c.vx_max, c.vx_min, c.wz_max, c.temperature, c.gamma) == (0.5, -0.35, 1.9, 0.3, 0.015)
    assert c.regenerate_noises and c.visualize and c.motion_model == "DiffDrive"
    assert [n for n, _ in p.critic_configs] == [
        "ConstraintCritic", "CostCritic", "GoalCritic", "GoalAngleCritic", "PathAlignCritic",
        "PathFollowCritic", "PathAngleCritic", "PreferForwardCritic"]
    cfg = dict(p.critic_configs)
    assert cfg["CostCritic"].cost_weight == 3.81 and cfg["CostCritic"].near_goal_distance == 1.0
    assert cfg["PathAlignCritic"].max_path_occupancy_ratio == 0.05
    assert cfg["PathAngleCritic"].max_angle_to_furthest == 1.0
    assert p.visualizer.trajectory_step == 5 and p.ackermann.min_turning_r == 0.2
    # defaults are Jazzy's code defaults
    d = MPPIConfig()
    assert (d.batch_size, d.iteration_count, d.vx_std, d.wz_std, d.prune_distance) == (
        1000, 1, 0.2, 0.4, 1.5)


def test_controller_server_loads_mppi_by_its_plugin_name() -> None:
    srv = build_controller_server({"controller_plugins": ["FollowPath"],
                                   "FollowPath": jazzy_follow_path()})
    ctrl = srv.controller("FollowPath")
    assert isinstance(ctrl, MPPIController)
    assert ctrl.optimizer.settings.batch_size == 2000
    assert ctrl.optimizer.shift_control_sequence  # 20 Hz = 1 / model_dt


@pytest.mark.parametrize(("key", "value", "match"), [
    ("motion_model", "Omni", "Omni"),
    ("motion_model", "Ackermann", "Ackermann"),
    ("motion_model", "Tank", "valid options"),
    ("temperature", 0.0, "temperature"),
    ("batch_size", "many", "batch_size"),
])
def test_bad_values_are_named(key: str, value: Any, match: str) -> None:
    params = jazzy_follow_path()
    params[key] = value
    with pytest.raises(ParameterError, match=match) as exc:
        build_controller_server({"FollowPath": params})
    assert exc.value.key == key and "FollowPath" in str(exc.value)


def test_unknown_critic_and_slow_controller_are_refused() -> None:
    params = jazzy_follow_path()
    params["critics"] = [*params["critics"], "WiggleCritic"]
    with pytest.raises(UnsupportedPlugin) as exc:
        build_controller_server({"FollowPath": params})
    assert (exc.value.key, exc.value.plugin) == ("FollowPath.critics", "WiggleCritic")
    params = jazzy_follow_path()
    params["CostCritic"] = {**params["CostCritic"], "trajectory_point_step": 0}
    with pytest.raises(ParameterError, match="CostCritic"):
        build_controller_server({"FollowPath": params})
    # a controller period longer than model_dt cannot shift the sequence: refused upstream
    with pytest.raises(ParameterError, match="model_dt"):
        build_controller_server({"controller_frequency": 10.0, "FollowPath": jazzy_follow_path()})


@pytest.mark.parametrize(("path", "start"), [(LINE, (0.5, 3.05, 0.0)), (ARC, (2.0, 1.5, 0.0))],
                         ids=["straight", "curved"])
def test_tracks_path_to_goal(empty_costmap, path, start) -> None:
    ctrl = jazzy_mppi()
    checker = SimpleGoalChecker()
    pose, reached, log = simulate(ctrl, path, empty_costmap, start, checker, steps=1500)
    assert reached
    assert math.hypot(pose[0] - path[-1, 0], pose[1] - path[-1, 1]) <= 0.25
    assert abs((pose[2] - path[-1, 2] + math.pi) % (2 * math.pi) - math.pi) < 0.25
    d = np.min(np.hypot(log[:, None, 0] - path[None, :, 0], log[:, None, 1] - path[None, :, 1]),
               axis=1)
    assert d.max() < 0.15
    # the limits hold up to the Savitzky-Golay smoothing, which upstream applies after them
    assert np.abs(log[:, 3]).max() <= 0.5 * 1.01 and np.abs(log[:, 4]).max() <= 1.9 * 1.01


def test_converges_to_cruise_on_a_straight_path(empty_costmap) -> None:
    ctrl = jazzy_mppi()
    _, _, log = simulate(ctrl, LINE, empty_costmap, (0.5, 3.0, 0.0), SimpleGoalChecker(),
                         steps=60)
    # from rest to near vx_max within 3 s, heading held
    assert log[-20:, 3].mean() > 0.4
    assert np.abs(log[-20:, 4]).max() < 0.3
    assert np.abs(log[:, 1] - 3.0).max() < 0.05


def _corner_map() -> np.ndarray:
    """4 × 4 m at 0.05: an L corridor 1.1 m wide, along y = 0.45..1.55 to x = 3.55, then
    up along x = 2.45..3.55 to y = 3.55; everything else occupied."""
    occ = np.full((80, 80), 100, dtype=np.int8)
    occ[9:31, 10:71] = 0
    occ[9:71, 49:71] = 0
    return occ


def test_turns_a_corner_clear_of_the_walls() -> None:
    cm = make_costmap(_corner_map(), robot_radius=0.2, inflation_radius=0.5,
                      cost_scaling_factor=3.0)
    start, goal = (0.8, 1.0, 0.0), (3.0, 3.2, math.pi / 2)
    path = NavfnPlanner().create_plan(start, goal, cm.master)
    ctrl = jazzy_mppi()
    pose, reached, log = simulate(ctrl, path, cm, start, SimpleGoalChecker(), steps=600)
    assert reached
    assert math.hypot(pose[0] - goal[0], pose[1] - goal[1]) <= 0.25
    costs = [cm.master.cost_at_world(x, y) for x, y in log[:, :2]]
    assert max(costs) < INSCRIBED_INFLATED_OBSTACLE  # the footprint never touches a wall
    assert log.shape[0] * 0.05 < 15.0  # 4.4 m of corridor at up to 0.5 m/s


def test_boxed_in_robot_fails_after_the_retry() -> None:
    occ = np.zeros((60, 60), dtype=np.int8)
    occ[25:35, 25:35] = 100
    cm = make_costmap(occ)
    ctrl = jazzy_mppi()
    with pytest.raises(NoValidControl, match="fail to compute path"):
        ctrl.compute_velocity_commands((1.5, 1.5, 0.0), Twist2D(), LINE * [0.5, 0.5, 1], cm)


def test_speed_limit_scales_the_velocity_limits(empty_costmap) -> None:
    ctrl = jazzy_mppi()
    ctrl.set_speed_limit(40.0, True)
    _, _, log = simulate(ctrl, LINE, empty_costmap, (0.5, 3.0, 0.0), SimpleGoalChecker(),
                         steps=80)
    assert log[:, 3].max() <= 0.2 * 1.03 and log[-20:, 3].mean() > 0.15  # smoothing overshoot
    ctrl.set_speed_limit(0.25, False)
    assert ctrl.optimizer.constraints.vx_max == pytest.approx(0.25)
    assert ctrl.optimizer.constraints.wz == pytest.approx(1.9 * 0.5)
    ctrl.set_speed_limit(0.0, False)
    assert ctrl.optimizer.constraints.vx_max == 0.5


def test_visualize_keeps_candidates_and_the_optimal_trajectory(empty_costmap) -> None:
    ctrl = jazzy_mppi()
    ctrl.compute_velocity_commands((0.5, 3.0, 0.0), Twist2D(), LINE, empty_costmap)
    assert ctrl.candidates.shape == (400, 19, 3)  # every 5th of 2000, every 3rd of 56 steps
    assert ctrl.optimal.shape == (56, 3)
    assert ctrl.transformed_plan[-1, 0] - ctrl.transformed_plan[0, 0] <= 1.7 + 0.05
