"""Global planners: shortest paths, typed failures, tolerance; the smoother stays out of collision."""

from __future__ import annotations

import math

import numpy as np
import pytest
from navtest_helpers import make_costmap

from eddiebot.nav.errors import (
    GoalOccupied,
    GoalOutsideMapBounds,
    InvalidPlanner,
    NoValidPath,
    ParameterError,
    StartOccupied,
    StartOutsideMapBounds,
)
from eddiebot.nav.planners import (
    NavfnConfig,
    NavfnPlanner,
    ThetaStarPlanner,
    build_planners,
    get_planner,
)
from eddiebot.nav.smoother import SimpleSmoother
from eddiebot.nav.types import path_length

RES = 0.05


@pytest.fixture(scope="module")
def wall_map():
    # 5 m x 5 m; a thin wall at x = 2.5 m from y = 1.0 to y = 4.0 m, no inflation.
    occ = np.zeros((100, 100), dtype=np.int8)
    occ[20:80, 50] = 100
    return make_costmap(occ, robot_radius=0.05, inflation_radius=0.0)


def _true_shortest() -> float:
    # Around the wall end at (2.5, 4.0) [cell edge at y = 4.0 m]: two straight legs.
    start, goal, corner = np.array([1.0, 2.5]), np.array([4.0, 2.5]), np.array([2.5, 4.0])
    return float(np.hypot(*(corner - start)) + np.hypot(*(goal - corner)))


def _check_clear(path: np.ndarray, cm) -> None:
    for x, y, _ in path:
        cell = cm.master.world_to_map(x, y)
        assert cell is not None and cm.master.get_cost(*cell) < 253


@pytest.mark.parametrize("use_astar", [False, True])
def test_navfn_shortest_path_around_wall(wall_map, use_astar: bool) -> None:
    planner = NavfnPlanner(NavfnConfig(use_astar=use_astar))
    path = planner.create_plan((1.0, 2.5, 0.0), (4.0, 2.5, 1.0), wall_map.master)
    assert np.allclose(path[0, :2], [1.0, 2.5], atol=RES)
    assert np.allclose(path[-1], [4.0, 2.5, 1.0])
    length = path_length(path)
    assert _true_shortest() <= length <= 1.04 * _true_shortest()
    _check_clear(path, wall_map)


def test_theta_star_shortest_path_around_wall(wall_map) -> None:
    path = ThetaStarPlanner().create_plan((1.0, 2.5, 0.0), (4.0, 2.5, 0.0), wall_map.master)
    assert _true_shortest() * 0.99 <= path_length(path) <= 1.03 * _true_shortest()
    _check_clear(path, wall_map)
    # Interpolated at the resolution.
    steps = np.hypot(*np.diff(path[:, :2], axis=0).T)
    assert steps.max() <= RES + 1e-9


@pytest.mark.parametrize("planner", [NavfnPlanner(NavfnConfig(tolerance=0.0)), ThetaStarPlanner()])
def test_typed_failures(wall_map, planner) -> None:
    cm = wall_map.master
    with pytest.raises(StartOutsideMapBounds) as e1:
        planner.create_plan((-1.0, 2.5, 0.0), (4.0, 2.5, 0.0), cm)
    assert e1.value.result_code == 203
    with pytest.raises(GoalOutsideMapBounds) as e2:
        planner.create_plan((1.0, 2.5, 0.0), (9.0, 2.5, 0.0), cm)
    assert e2.value.result_code == 204
    with pytest.raises(StartOccupied) as e3:
        planner.create_plan((2.52, 2.5, 0.0), (4.0, 2.5, 0.0), cm)
    assert e3.value.result_code == 205
    with pytest.raises(GoalOccupied) as e4:
        planner.create_plan((1.0, 2.5, 0.0), (2.52, 2.5, 0.0), cm)
    assert e4.value.result_code == 206


def test_no_valid_path_when_goal_enclosed() -> None:
    occ = np.zeros((60, 60), dtype=np.int8)
    occ[30:41, 30] = occ[30:41, 40] = 100
    occ[30, 30:41] = occ[40, 30:41] = 100
    cm = make_costmap(occ, robot_radius=0.05, inflation_radius=0.0)
    with pytest.raises(NoValidPath) as exc:
        NavfnPlanner(NavfnConfig(tolerance=0.0)).create_plan((0.5, 0.5, 0), (1.75, 1.75, 0), cm.master)
    assert exc.value.result_code == 208
    with pytest.raises(NoValidPath):
        ThetaStarPlanner().create_plan((0.5, 0.5, 0), (1.75, 1.75, 0), cm.master)


def test_navfn_tolerance_reaches_nearest_free_point() -> None:
    occ = np.zeros((60, 60), dtype=np.int8)
    occ[25:35, 25:35] = 100  # a 0.5 m block; goal at its centre
    cm = make_costmap(occ, robot_radius=0.05, inflation_radius=0.0)
    goal = (1.5, 1.5, 0.0)
    with pytest.raises(GoalOccupied):
        NavfnPlanner(NavfnConfig(tolerance=0.2)).create_plan((0.3, 0.3, 0), goal, cm.master)
    path = NavfnPlanner(NavfnConfig(tolerance=0.5)).create_plan((0.3, 0.3, 0), goal, cm.master)
    end = path[-1, :2]
    # The block spans 1.25..1.75 m: the nearest free sample of the tolerance square lies just
    # outside it, about 0.25-0.3 m from the goal.
    d = math.hypot(end[0] - goal[0], end[1] - goal[1])
    assert 0.24 <= d <= 0.36
    assert cm.master.get_cost(*cm.master.world_to_map(*end)) < 253


def test_registry_from_yaml_params() -> None:
    planners = build_planners({
        "planner_plugins": ["GridBased", "Theta"],
        "GridBased": {"plugin": "nav2_navfn_planner/NavfnPlanner", "tolerance": 0.3, "use_astar": True},
        "Theta": {"plugin": "nav2_theta_star_planner::ThetaStarPlanner", "w_traversal_cost": 1.5},
    })
    assert isinstance(planners["GridBased"], NavfnPlanner)
    assert planners["GridBased"].config.use_astar and planners["GridBased"].config.tolerance == 0.3
    assert planners["Theta"].config.w_traversal_cost == 1.5
    with pytest.raises(InvalidPlanner):
        get_planner(planners, "Nope")
    with pytest.raises(ParameterError) as exc:
        build_planners({"planner_plugins": ["X"], "X": {"plugin": "nav2_smac_planner::Nope"}})
    assert exc.value.key == "X.plugin"
    with pytest.raises(ParameterError) as exc:
        build_planners({"GridBased": {"tolerance": -1.0}})
    assert exc.value.key == "tolerance"


def test_smoother_reduces_jaggedness_and_avoids_lethal() -> None:
    occ = np.zeros((80, 80), dtype=np.int8)
    occ[30:50, 38:42] = 100
    cm = make_costmap(occ, robot_radius=0.15, inflation_radius=0.4)
    path = NavfnPlanner().create_plan((0.5, 2.0, 0.0), (3.5, 2.0, 0.0), cm.master)
    res = SimpleSmoother().smooth(path, cm.master)
    out = res.path
    assert out.shape == path.shape
    assert np.allclose(out[0, :2], path[0, :2]) and np.allclose(out[-1, :2], path[-1, :2])
    for x, y, _ in out:
        assert cm.master.get_cost(*cm.master.world_to_map(x, y)) <= 252

    def roughness(p: np.ndarray) -> float:
        return float(np.sum(np.linalg.norm(p[2:, :2] - 2 * p[1:-1, :2] + p[:-2, :2], axis=1)))

    assert roughness(out) < roughness(path)


def test_smoother_returns_last_admissible_path_near_obstacle() -> None:
    occ = np.zeros((40, 40), dtype=np.int8)
    occ[18:22, 18:22] = 100
    cm = make_costmap(occ, robot_radius=0.05, inflation_radius=0.0)
    # A path hugging the block's corner: smoothing would cut through it.
    pts = [(0.5, 1.15), (0.85, 1.15), (0.88, 1.12), (0.88, 0.5)]
    res = SimpleSmoother().smooth(np.array([[x, y, 0.0] for x, y in pts]), cm.master)
    for x, y, _ in res.path:
        assert cm.master.get_cost(*cm.master.world_to_map(x, y)) <= 252


def test_navfn_allow_unknown() -> None:
    occ = np.zeros((60, 60), dtype=np.int8)
    occ[:, 28:32] = -1  # an unknown band splitting the map
    cm = make_costmap(occ, robot_radius=0.05, inflation_radius=0.0, track_unknown_space=True)
    start, goal = (0.5, 1.5, 0.0), (2.5, 1.5, 0.0)
    path = NavfnPlanner(NavfnConfig(allow_unknown=True)).create_plan(start, goal, cm.master)
    assert np.allclose(path[-1, :2], goal[:2])
    with pytest.raises(NoValidPath):
        NavfnPlanner(NavfnConfig(allow_unknown=False, tolerance=0.0)).create_plan(
            start, goal, cm.master)


def test_navfn_goal_in_unknown_is_no_valid_path_as_upstream() -> None:
    # Upstream NavFn raises GoalOccupied (206) only for a lethal goal; a goal in unknown space
    # that the potential cannot reach is NoValidPathCouldBeFound (208), which the default BT's
    # WouldAPlannerRecoveryHelp retries after clearing the costmap.
    occ = np.zeros((60, 60), dtype=np.int8)
    occ[20:40, 40:55] = -1  # an unknown room
    occ[45:50, 10:15] = 100  # an obstacle
    cm = make_costmap(occ, robot_radius=0.05, inflation_radius=0.0, track_unknown_space=True)
    planner = NavfnPlanner(NavfnConfig(allow_unknown=False, tolerance=0.0))
    with pytest.raises(NoValidPath) as unknown:
        planner.create_plan((0.5, 0.5, 0.0), (2.4, 1.5, 0.0), cm.master)
    assert unknown.value.result_code == 208
    with pytest.raises(GoalOccupied) as lethal:
        planner.create_plan((0.5, 0.5, 0.0), (0.6, 2.35, 0.0), cm.master)
    assert lethal.value.result_code == 206
