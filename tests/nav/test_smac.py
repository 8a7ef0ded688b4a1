"""Smac planners (SmacPlanner2D, SmacPlannerHybrid): Nav2's unit-test data, paths around
obstacles, footprints, Dubins / Reeds-Shepp motion, unknown space and typed failures."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from navtest_helpers import make_costmap

from eddiebot.maps import OccupancyMap
from eddiebot.nav.costmap import build_costmap
from eddiebot.nav.costmap.costmap2d import Costmap2D
from eddiebot.nav.errors import (
    GoalOccupied,
    NoValidPath,
    ParameterError,
    PlannerTimedOut,
    StartOccupied,
)
from eddiebot.nav.params import from_params
from eddiebot.nav.planners.smac import (
    SmacPlanner2D,
    SmacPlanner2DConfig,
    SmacPlannerHybrid,
    SmacPlannerHybridConfig,
)
from eddiebot.nav.planners.smac import search as S
from eddiebot.nav.planners.smac.curves import curve_path, curve_sample
from eddiebot.nav.types import path_length

RES = 0.05


# a loaded test machine must not turn a plan into a time-out: the time limit is only tested
# where a test sets it
NO_TIME_LIMIT = 600.0


def hybrid(**kw: object) -> SmacPlannerHybrid:
    kw.setdefault("max_planning_time", NO_TIME_LIMIT)
    return SmacPlannerHybrid(from_params(SmacPlannerHybridConfig, kw))


def planner_2d(**kw: object) -> SmacPlanner2D:
    kw.setdefault("max_planning_time", NO_TIME_LIMIT)
    return SmacPlanner2D(from_params(SmacPlanner2DConfig, kw))


def assert_clear(path: np.ndarray, cm) -> None:
    for x, y, _ in path:
        cell = cm.master.world_to_map(x, y)
        assert cell is not None and cm.master.get_cost(*cell) < 253, (x, y)


@pytest.fixture(scope="module")
def wall_map():
    # 5 m x 5 m; a wall at x = 2.5 m from y = 1.0 to 4.0 m, inflated for a 0.1 m robot
    occ = np.zeros((100, 100), dtype=np.int8)
    occ[20:80, 50] = 100
    return make_costmap(occ, robot_radius=0.1, inflation_radius=0.3, cost_scaling_factor=10.0)


# --- Nav2's unit-test data ----------------------------------------------------------------

# test_nodehybrid.cpp: motion primitives (dx, dy cells; heading change in bins)
@pytest.mark.parametrize(("model", "radius_cells", "expected"), [
    ("DUBIN", 4, [(1.731517, 0.0, 0), (1.69047, 0.3747, 5), (1.69047, -0.3747, -5)]),
    ("REEDS_SHEPP", 8, [(2.088, 0.0, 0), (2.070, 0.272, 3), (2.070, -0.272, -3),
                        (-2.088, 0.0, 0), (-2.07, 0.272, -3), (-2.07, -0.272, 3)]),
])
def test_motion_primitives_match_upstream(model: str, radius_cells: float,
                                          expected: list[tuple[float, float, int]]) -> None:
    pl = hybrid(motion_model_for_search=model)
    dx, dy, dth, _turn, _travel = pl._motion_table(radius_cells)
    assert len(dth) == len(expected)
    for i, (ex, ey, et) in enumerate(expected):
        assert dx[i, 0] == pytest.approx(ex, abs=0.01)
        assert dy[i, 0] == pytest.approx(ey, abs=0.01)
        assert dth[i] == et


def test_primitive_interpolation_count_matches_upstream() -> None:
    # test_nodehybrid.cpp test_interpolation_prims2: 72 bins, radius 8 cells -> 7 primitives
    pl = hybrid(allow_primitive_interpolation=True)
    assert len(pl._motion_table(8.0)[2]) == 7
    assert len(hybrid()._motion_table(8.0)[2]) == 3


@pytest.mark.parametrize(("parent", "turn", "prim", "expected", "tol"), [
    (-1, S.LEFT, 1, 2.088, 0.1),              # first expansion: neutral travel cost
    (S.LEFT, S.FORWARD, 0, 2.088 * 0.9, 0.1),  # retrospective reward 10 %
    (S.LEFT, S.LEFT, 1, 2.294 * 0.9, 0.01),   # same turn as parent: non_straight_penalty
    (S.LEFT, S.RIGHT, 2, 2.506 * 0.9, 0.01),  # opposite turn: + change_penalty
    (S.LEFT, S.REV_RIGHT, 1, 2.513 * 0.9 * 2.0, 0.01),  # reversing: reverse_penalty
    (S.RIGHT, S.REV_LEFT, 2, 2.513 * 0.9 * 2.0, 0.01),
])
def test_traversal_cost_matches_upstream(parent: int, turn: int, prim: int, expected: float,
                                         tol: float) -> None:
    # test_nodehybrid.cpp test_node_hybrid: radius 8 cells, cost 0, change 0.1,
    # non-straight 1.1, reverse 2.0, cost_penalty 1.7, retrospective 0.1
    travel = hybrid(motion_model_for_search="REEDS_SHEPP")._motion_table(8.0)[4]
    c = S.traversal_cost(parent, turn, travel[prim], travel[0], 0.0, 1.7, False, 0.9, 1.1, 0.1,
                         2.0)
    assert c == pytest.approx(expected, abs=tol)


def test_obstacle_heuristic_matches_upstream() -> None:
    # test_nodehybrid.cpp test_obstacle_heuristic: 100x100, a lethal island with a narrow
    # high-cost passage above it; the wave goes round the wide side either way: 91.1 cells
    grid = np.zeros((100, 100), dtype=np.uint8)
    grid[40:61, 20:81] = 254
    grid[61:71, 20:81] = 250
    grid[71:100, 20:81] = 254
    grid[61:71, 50] = 254
    blocked = S.obstacle_heuristic(grid, 90.0, 51.0, 1.7, True, False)[25, 5]
    grid[61:71, 50] = 250
    open_ = S.obstacle_heuristic(grid, 90.0, 51.0, 1.7, True, False)[25, 5]
    assert blocked == pytest.approx(91.1, abs=0.1)
    assert open_ == blocked


@pytest.mark.parametrize(("cost", "straight"), [(0, True), (200, True), (210, False)])
def test_node2d_travel_cost(cost: int, straight: bool) -> None:
    # Node2D::getTraversalCost: (1 or √2)·(1 + cost_travel_multiplier·cost/252). Across a
    # cell of ``cost`` costs 2 + cost/252; round it diagonally 2√2: straight below cost 208.7
    grid = np.zeros((3, 3), dtype=np.uint8)
    grid[1, 1] = cost
    status, cells, _ = S.astar_2d(grid, 0, 1, 2.0, 1.0, 1.0, False, 0.0, 100, 100, 100, 10.0)
    assert status == S.FOUND
    assert (cells.tolist() == [[0, 1], [1, 1], [2, 1]]) == straight
    assert len(cells) == 3


def _island() -> np.ndarray:
    grid = np.zeros((100, 100), dtype=np.uint8)
    grid[40:61, 40:61] = 254
    return grid


def test_a_star_2d_matches_upstream() -> None:
    # test_a_star.cpp test_a_star_2d: 100x100 with a lethal island, (20, 20) -> (80, 80),
    # no tolerance: 82 cells, all free; 2414 expansions upstream (ties in the queue break
    # differently here, hence the 2 % band)
    grid = _island()
    status, cells, its = S.astar_2d(grid, 20, 20, 80.0, 80.0, 2.0, False, 0.0, 10000, 10, 5000,
                                    120.0)
    assert status == S.FOUND and len(cells) == 82
    assert abs(its - 2414) <= 0.02 * 2414
    assert all(grid[y, x] == 0 for x, y in cells)
    # an occupied goal with a liberal tolerance (20 cells): 21 cells, all free
    status, cells, _ = S.astar_2d(grid, 20, 20, 50.0, 50.0, 2.0, False, 20.0, 10000, 10, 5000,
                                  120.0)
    assert status == S.FOUND and len(cells) == 21
    assert all(grid[y, x] == 0 for x, y in cells)


def _upstream_hybrid(**kw: object) -> SmacPlannerHybrid:
    # test_a_star.cpp's SearchInfo in Nav2 parameters: 0.1 m cells, turning radius 8 cells,
    # lookup table 401 cells, tolerance 10 cells, 10000 iterations, 10 on approach
    params = {"change_penalty": 0.1, "non_straight_penalty": 1.1,
              "minimum_turning_radius": 0.8, "retrospective_penalty": 0.015,
              "analytic_expansion_ratio": 3.5, "cost_penalty": 1.7, "max_iterations": 10000,
              "tolerance": 1.0, "max_on_approach_iterations": 10, "allow_unknown": False,
              "lookup_table_size": 40.1, "smooth_path": False}
    params.update(kw)
    return hybrid(**params)


def test_a_star_hybrid_matches_upstream() -> None:
    # test_a_star.cpp test_a_star_se2: (10, 10, bin 0) -> (80, 80, bin 40) round the island,
    # analytic expansion within 20 cells: more than 2000 expansions, 63 ± 2 poses, each step
    # under 2.1 cells, all on free cells
    cm = Costmap2D(100, 100, 0.1, 0.0, 0.0, 0)
    cm.data[:] = _island()
    pl = _upstream_hybrid(analytic_expansion_max_length=2.0)
    pl.create_plan((1.0, 1.0, 0.0), (8.0, 8.0, 40 * 2 * math.pi / 72), cm)
    raw = pl.last_raw_path
    assert pl.last_iterations > 2000
    assert abs(len(raw) - 63) <= 2
    assert (np.hypot(*np.diff(raw[:, :2], axis=0).T) < 2.1 * 0.1).all()
    assert all(cm.get_cost(*cm.world_to_map(x, y)) == 0 for x, y, _ in raw)


def test_a_star_reeds_shepp_straight_back_matches_upstream() -> None:
    # test_a_star.cpp test_a_star_analytic_expansion (Reeds-Shepp, reverse_penalty 0): from
    # (80, 0) to (20, 0) facing +x is one straight reverse, heading 0 all along
    pl = _upstream_hybrid(motion_model_for_search="REEDS_SHEPP", change_penalty=0.0,
                          analytic_expansion_max_length=200.0)
    pl.config = dataclasses.replace(pl.config, reverse_penalty=0.0)  # below Nav2's documented 1
    pl.create_plan((8.0, 0.0, 0.0), (2.0, 0.0, 0.0), Costmap2D(100, 100, 0.1, 0.0, 0.0, 0))
    assert np.abs(pl.last_raw_path[:, 2]).max() < 1e-3
    assert pl.last_reversing[1:].all()


_SQUARE = np.array([[[-10.0, 10.0], [10.0, 10.0], [10.0, -10.0], [-10.0, -10.0]]])  # cells


@pytest.mark.parametrize(("default", "block", "lethal", "x", "y", "hit", "cost"), [
    # test_collision_checker.cpp test_footprint_at_pose_with_movement: a 2 x 2 m footprint
    # (0.1 m cells) inside a 21 x 21 cell patch of cost 128 in a lethal map
    (254, True, (), 50, 50, False, 128), (254, True, (), 50, 49, True, 128),
    (254, True, (), 50, 52, True, 128), (254, True, (), 11, 11, True, 254),
    # test_point_and_line_cost: cost 128 everywhere, two lethal cells
    (128, False, ((62, 50), (39, 60)), 50, 50, False, 128),
    (128, False, ((62, 50), (39, 60)), 49, 50, True, 128),
    (128, False, ((62, 50), (39, 60)), 52, 50, True, 128),
    (128, False, ((62, 50), (39, 60)), 39, 60, True, 254),
])
def test_footprint_collision_matches_upstream(default: int, block: bool, lethal: tuple, x: int,
                                              y: int, hit: bool, cost: int) -> None:
    grid = np.full((100, 100), default, dtype=np.uint8)
    if block:
        grid[40:61, 40:61] = 128
    for cx, cy in lethal:
        grid[cy, cx] = 254
    assert S._in_collision(grid, float(x), float(y), 0, False, False, 0.0, _SQUARE) == (hit, cost)


def test_point_collision_matches_upstream() -> None:
    # test_collision_checker.cpp test_world_to_map: a point robot reports its cell's cost
    grid = np.zeros((100, 100), dtype=np.uint8)
    assert S._in_collision(grid, 50.0, 50.0, 0, False, True, 0.0, _SQUARE) == (False, 0)
    grid[50, 50] = 200
    assert S._in_collision(grid, 50.0, 50.0, 0, False, True, 0.0, _SQUARE) == (False, 200)
    grid[50, 50] = 253
    assert S._in_collision(grid, 50.0, 50.0, 0, False, True, 0.0, _SQUARE)[0]


# --- curves -------------------------------------------------------------------------------

@pytest.mark.parametrize("reeds_shepp", [False, True])
def test_curves_end_on_the_goal(reeds_shepp: bool) -> None:
    rng = np.random.default_rng(3)
    for _ in range(300):
        a = rng.uniform(-4, 4, 3)
        b = rng.uniform(-4, 4, 3)
        rho = rng.uniform(0.3, 2.0)
        kinds, lengths, total = curve_path(*a, *b, rho, reeds_shepp)
        x, y, th, _ = curve_sample(*a, kinds, lengths, rho, 1.0)
        assert math.hypot(x - b[0], y - b[1]) < 1e-6
        assert abs(math.remainder(th - b[2], 2 * math.pi)) < 1e-6
        assert total >= math.hypot(*(b[:2] - a[:2])) - 1e-9
        if not reeds_shepp:
            assert (lengths >= 0).all()


def test_reeds_shepp_backs_up_straight() -> None:
    kinds, lengths, total = curve_path(0.0, 0.0, 0.0, -3.0, 0.0, 0.0, 1.0, True)
    assert total == pytest.approx(3.0)
    assert lengths.sum() == pytest.approx(-3.0)
    assert curve_path(0.0, 0.0, 0.0, -3.0, 0.0, 0.0, 1.0, False)[2] > 3.0 + 2 * math.pi - 0.1


# --- SmacPlanner2D ------------------------------------------------------------------------

def test_2d_straight_line(empty_costmap) -> None:
    path = planner_2d().create_plan((1.0, 1.0, 0.0), (5.0, 1.0, 0.5), empty_costmap.master)
    assert path[-1, 2] == 0.5
    assert np.abs(path[:, 1] - 1.025).max() < 1e-6
    assert path_length(path) == pytest.approx(4.0, abs=0.06)


def test_2d_around_wall(wall_map) -> None:
    path = planner_2d().create_plan((1.0, 2.5, 0.0), (4.0, 2.5, 0.0), wall_map.master)
    assert_clear(path, wall_map)
    shortest = 2 * math.hypot(1.5, 1.5)  # round the end of the wall
    assert shortest <= path_length(path) <= 1.12 * shortest
    assert path[:, 1].max() > 4.0  # goes round the top end


def test_2d_cost_travel_multiplier_keeps_off_inflation() -> None:
    # a corridor 1.2 m wide; with a high multiplier the path keeps to the centre line
    occ = np.zeros((60, 120), dtype=np.int8)
    occ[:6, :] = 100
    occ[30:, :] = 100
    cm = make_costmap(occ, robot_radius=0.1, inflation_radius=0.6, cost_scaling_factor=2.0)
    start, goal = (0.5, 0.6, 0.0), (5.5, 0.9, 0.0)
    cheap = planner_2d(cost_travel_multiplier=0.0).create_plan(start, goal, cm.master)
    dear = planner_2d(cost_travel_multiplier=50.0).create_plan(start, goal, cm.master)
    mid = 0.5 * (0.3 + 1.5)

    def mean_offset(p: np.ndarray) -> float:
        return float(np.mean(np.abs(p[5:-5, 1] - mid)))

    assert mean_offset(dear) < mean_offset(cheap) - 0.05


def test_2d_unknown_space() -> None:
    occ = np.zeros((100, 100), dtype=np.int8)
    occ[10:90, 40:60] = -1
    cm = make_costmap(occ, robot_radius=0.1, inflation_radius=0.2, track_unknown_space=True)
    start, goal = (1.0, 2.5, 0.0), (4.0, 2.5, 0.0)
    through = planner_2d(allow_unknown=True).create_plan(start, goal, cm.master)
    pl = planner_2d(allow_unknown=False)
    around = pl.create_plan(start, goal, cm.master)
    assert path_length(through) == pytest.approx(3.0, abs=0.1)
    assert path_length(around) > 5.0
    for x, y, _ in pl.last_raw_path:
        assert cm.master.get_cost(*cm.master.world_to_map(x, y)) != 255


def test_2d_failures(wall_map) -> None:
    occ = np.zeros((100, 100), dtype=np.int8)
    occ[:, 50] = 100
    cm = make_costmap(occ, robot_radius=0.1, inflation_radius=0.3)
    with pytest.raises(NoValidPath):
        planner_2d().create_plan((1.0, 2.5, 0.0), (4.0, 2.5, 0.0), cm.master)
    with pytest.raises(StartOccupied):
        planner_2d().create_plan((2.5, 2.5, 0.0), (4.0, 2.5, 0.0), wall_map.master)
    with pytest.raises(GoalOccupied):
        planner_2d(tolerance=0.0).create_plan((1.0, 2.5, 0.0), (2.5, 2.5, 0.0), wall_map.master)
    with pytest.raises(PlannerTimedOut):
        planner_2d(max_iterations=10).create_plan((1.0, 2.5, 0.0), (4.0, 2.5, 0.0),
                                                  wall_map.master)


def test_2d_tolerance_reaches_near_occupied_goal(wall_map) -> None:
    # goal in the wall's inflation; a 0.3 m tolerance ends on the nearest reachable cell
    path = planner_2d(tolerance=0.3).create_plan((1.0, 2.5, 0.0), (2.5, 2.5, 0.0),
                                                 wall_map.master)
    assert_clear(path, wall_map)
    assert math.hypot(path[-1, 0] - 2.5, path[-1, 1] - 2.5) <= 0.3 + RES


def test_2d_downsampling(wall_map) -> None:
    path = planner_2d(downsample_costmap=True, downsampling_factor=2).create_plan(
        (1.0, 2.5, 0.0), (4.0, 2.5, 0.0), wall_map.master)
    assert_clear(path, wall_map)
    assert path_length(path) < 5.2


# --- SmacPlannerHybrid --------------------------------------------------------------------

def _curvatures(path: np.ndarray) -> np.ndarray:
    d = np.hypot(*np.diff(path[:, :2], axis=0).T)
    dth = np.abs(np.remainder(np.diff(path[:, 2]) + math.pi, 2 * math.pi) - math.pi)
    keep = d > 1e-6
    return dth[keep] / d[keep]


@pytest.mark.parametrize("model", ["DUBIN", "REEDS_SHEPP"])
def test_hybrid_around_wall(wall_map, model: str) -> None:
    pl = hybrid(motion_model_for_search=model)
    path = pl.create_plan((1.0, 2.5, 0.0), (4.0, 2.5, 0.0), wall_map.master)
    assert_clear(path, wall_map)
    assert_clear(pl.last_raw_path, wall_map)
    assert path[:, 1].max() > 4.0 or path[:, 1].min() < 1.0
    assert np.allclose(path[0, :2], [1.0, 2.5]) and np.allclose(path[-1], [4.0, 2.5, 0.0])
    assert path_length(path) < 7.0
    if model == "DUBIN":
        assert not pl.last_reversing.any()


@pytest.mark.parametrize("radius", [0.4, 1.0])
def test_hybrid_curvature_within_turning_radius(wall_map, radius: float) -> None:
    pl = hybrid(minimum_turning_radius=radius, smooth_path=False)
    pl.create_plan((1.0, 2.5, math.pi / 2), (4.0, 2.5, -math.pi / 2), wall_map.master)
    raw = pl.last_raw_path[:-1]  # the goal pose's yaw is exact, its node's bin is rounded
    assert raw.shape[0] > 10
    assert _curvatures(raw).max() <= 1.01 / radius


def test_reeds_shepp_reverses_when_cheaper(empty_costmap) -> None:
    start, goal = (3.0, 3.0, 0.0), (2.0, 3.0, 0.0)  # 1 m straight behind
    rs = hybrid(motion_model_for_search="REEDS_SHEPP")
    path = rs.create_plan(start, goal, empty_costmap.master)
    assert rs.last_reversing.any()
    assert path_length(path) == pytest.approx(1.0, abs=0.1)
    dub = hybrid(motion_model_for_search="DUBIN", smooth_path=False)
    dpath = dub.create_plan(start, goal, empty_costmap.master)
    assert not dub.last_reversing.any()
    assert path_length(dpath) > 1.0 + 2 * math.pi * 0.4 - 0.2
    # Dubins never drives backwards: every step moves along the pose's heading
    raw = dub.last_raw_path
    step = np.diff(raw[:, :2], axis=0)
    heading = np.stack([np.cos(raw[:-1, 2]), np.sin(raw[:-1, 2])], axis=1)
    assert (np.sum(step * heading, axis=1) > -1e-9).all()


def _slot_map(width: float) -> tuple:
    """6 x 4 m; a wall across x = 3 m with a 1 m long, ``width`` wide slot along x."""
    occ = np.zeros((80, 120), dtype=np.int8)
    occ[:, 50:70] = 100
    half = round(width / RES / 2)
    occ[40 - half:40 + half, 50:70] = 0
    cm = build_costmap({
        "resolution": RES, "footprint": "[[0.4, 0.1], [0.4, -0.1], [-0.4, -0.1], [-0.4, 0.1]]",
        "footprint_padding": 0.0, "plugins": ["static_layer", "inflation_layer"],
        "inflation_layer": {"inflation_radius": 0.5, "cost_scaling_factor": 5.0},
    }, "slot")
    cm.set_static_map(OccupancyMap(occ, RES))
    cm.update_map((0.0, 0.0, 0.0))
    return cm


def test_rectangular_footprint_through_slot_only_lengthwise() -> None:
    cm = _slot_map(0.4)  # a 0.8 x 0.2 m robot fits lengthwise only
    pl = hybrid(motion_model_for_search="REEDS_SHEPP",
                analytic_expansion_max_length=1.0)
    pl.configure_from_costmap(cm)
    assert not pl.use_radius and pl.possible_collision_cost > 0
    path = pl.create_plan((1.0, 2.0, 0.0), (5.0, 2.0, 0.0), cm.master)
    raw = pl.last_raw_path
    inside = raw[(raw[:, 0] > 2.6) & (raw[:, 0] < 3.4)]
    assert inside.shape[0] > 3
    assert np.abs(inside[:, 1] - 2.0).max() < 0.1
    assert np.abs(np.sin(inside[:, 2])).max() < math.sin(math.radians(10))
    for x, y, th in raw:
        assert 0 <= cm.master.footprint_cost(cm.footprint_at((x, y, th))) < 254
    assert path[-1, 0] == 5.0
    # the same robot turned across (0.2 long, 0.8 wide) cannot drive through the slot
    pl.set_footprint(np.array([[0.1, 0.4], [0.1, -0.4], [-0.1, -0.4], [-0.1, 0.4]]), False,
                     pl.possible_collision_cost)
    pl2 = hybrid(motion_model_for_search="REEDS_SHEPP", analytic_expansion_max_length=1.0)
    pl2.set_footprint(pl.footprint, False, pl.possible_collision_cost)
    with pytest.raises(NoValidPath):
        pl2.create_plan((1.0, 2.0, math.pi / 2), (5.0, 2.0, math.pi / 2), cm.master)


def test_hybrid_failures(wall_map) -> None:
    occ = np.zeros((100, 100), dtype=np.int8)
    occ[:, 50] = 100
    cm = make_costmap(occ, robot_radius=0.1, inflation_radius=0.3)
    with pytest.raises(NoValidPath):
        hybrid().create_plan((1.0, 2.5, 0.0), (4.0, 2.5, 0.0), cm.master)
    with pytest.raises(StartOccupied):
        hybrid().create_plan((2.5, 2.5, 0.0), (4.0, 2.5, 0.0), wall_map.master)
    with pytest.raises(GoalOccupied):
        hybrid(tolerance=0.0).create_plan((1.0, 2.5, 0.0), (2.5, 2.5, 0.0), wall_map.master)
    with pytest.raises(PlannerTimedOut):
        hybrid(max_iterations=5, analytic_expansion_max_length=0.5).create_plan(
            (1.0, 2.5, 0.0), (4.0, 2.5, 0.0), wall_map.master)


def test_hybrid_unknown_space() -> None:
    occ = np.zeros((100, 100), dtype=np.int8)
    occ[10:90, 40:60] = -1
    cm = make_costmap(occ, robot_radius=0.1, inflation_radius=0.2, track_unknown_space=True)
    start, goal = (1.0, 2.5, 0.0), (4.0, 2.5, 0.0)
    # the obstacle heuristic's wave does not enter unknown space (as upstream), so the path
    # through it is found but not the straightest
    through = hybrid(allow_unknown=True).create_plan(start, goal, cm.master)
    pl = hybrid(allow_unknown=False)
    around = pl.create_plan(start, goal, cm.master)
    assert path_length(through) < 3.6
    assert any(cm.master.get_cost(*cm.master.world_to_map(x, y)) == 255 for x, y, _ in through)
    assert path_length(around) > 5.0
    for x, y, _ in pl.last_raw_path:
        assert cm.master.get_cost(*cm.master.world_to_map(x, y)) != 255


# --- parameters ---------------------------------------------------------------------------

@pytest.mark.parametrize(("cls", "params", "key"), [
    (SmacPlannerHybridConfig, {"motion_model_for_search": "DUBINS"}, "motion_model_for_search"),
    (SmacPlannerHybridConfig, {"motion_model_for_search": "MOORE"}, "motion_model_for_search"),
    (SmacPlannerHybridConfig, {"angle_quantization_bins": "72"}, "angle_quantization_bins"),
    (SmacPlannerHybridConfig, {"minimum_turning_radius": 0.0}, "minimum_turning_radius"),
    (SmacPlannerHybridConfig, {"reverse_penalty": 0.5}, "reverse_penalty"),
    (SmacPlannerHybridConfig, {"smoother": {"w_smoth": 0.3}}, "smoother.w_smoth"),
    (SmacPlannerHybridConfig, {"smoother": {"max_iterations": -1}}, "smoother.max_iterations"),
    (SmacPlanner2DConfig, {"tolerance": -1.0}, "tolerance"),
    (SmacPlanner2DConfig, {"smoother": 3}, "smoother"),
    (SmacPlanner2DConfig, {"downsampling_factor": 0}, "downsampling_factor"),
])
def test_bad_parameters_are_named(cls: type, params: dict, key: str) -> None:
    with pytest.raises(ParameterError) as err:
        from_params(cls, params, server="planner_server.GridBased")
    assert err.value.key == key
    assert "planner_server.GridBased" in str(err.value)


def test_smoother_block_is_read() -> None:
    cfg = from_params(SmacPlannerHybridConfig, {"smoother": {"max_iterations": 5, "w_data": 0.4}})
    assert cfg.smoother.max_iterations == 5 and cfg.smoother.w_data == 0.4
    assert cfg.smoother.w_smooth == 0.3


def test_smoother_shortens_2d_path(wall_map) -> None:
    raw = planner_2d(smoother={"max_iterations": 0}).create_plan(
        (1.0, 2.5, 0.0), (4.0, 2.5, 0.0), wall_map.master)
    # a generous time budget: the smoother gets what the search leaves of it
    smooth = planner_2d().create_plan((1.0, 2.5, 0.0), (4.0, 2.5, 0.0),
                                                            wall_map.master)
    assert path_length(smooth) < path_length(raw) - 0.01
    assert_clear(smooth, wall_map)


def test_built_from_nav2_parameters() -> None:
    from eddiebot.nav.planners import build_planners

    planners = build_planners({
        "planner_plugins": ["GridBased", "Hybrid"],
        "GridBased": {"plugin": "nav2_smac_planner/SmacPlanner2D", "tolerance": 0.2,
                      "smoother": {"max_iterations": 500}},
        "Hybrid": {"plugin": "nav2_smac_planner::SmacPlannerHybrid",
                   "motion_model_for_search": "REEDS_SHEPP", "minimum_turning_radius": 0.3,
                   "smoother": {"w_smooth": 0.4, "do_refinement": False}},
    })
    two_d, hyb = planners["GridBased"], planners["Hybrid"]
    assert isinstance(two_d, SmacPlanner2D) and isinstance(hyb, SmacPlannerHybrid)
    assert two_d.config.tolerance == 0.2 and two_d.config.smoother.max_iterations == 500
    assert hyb.config.motion_model_for_search == "REEDS_SHEPP"
    assert hyb.config.smoother.w_smooth == 0.4 and not hyb.config.smoother.do_refinement
    with pytest.raises(ParameterError) as err:
        build_planners({"planner_plugins": ["GridBased"],
                        "GridBased": {"plugin": "nav2_smac_planner::SmacPlannerHybrid",
                                      "motion_model_for_search": "STATE_LATICE"}})
    assert err.value.key == "motion_model_for_search"
    assert "planner_server.GridBased" in str(err.value)


def test_configure_from_layered_costmap() -> None:
    cm = _slot_map(0.4)
    pl = hybrid()
    pl.configure_from_costmap(cm)
    # inflation at the circumscribed radius (hypot(0.4, 0.1) = 0.412 m), inscribed 0.1 m
    expected = int(252 * math.exp(-5.0 * (math.hypot(0.4, 0.1) - 0.1)))
    assert pl.possible_collision_cost == pytest.approx(expected, abs=1)
    circ = make_costmap(np.zeros((40, 40), dtype=np.int8), robot_radius=0.2)
    pl.configure_from_costmap(circ)
    assert pl.use_radius


def test_params_audit_keeps_the_smoother_block() -> None:
    from eddiebot.nav.nodes.params_audit import audit_nav2_params

    doc = {"planner_server": {"ros__parameters": {
        "planner_plugins": ["GridBased"],
        "GridBased": {"plugin": "nav2_smac_planner::SmacPlannerHybrid",
                      "minimum_turning_radius": 0.3, "foo": 1,
                      "smoother": {"max_iterations": 500, "w_smoth": 0.3}},
    }}}
    audit = audit_nav2_params(doc)
    kept = audit.supported["planner_server"]["ros__parameters"]["GridBased"]
    assert kept["smoother"] == {"max_iterations": 500}
    assert kept["minimum_turning_radius"] == 0.3
    assert "ignored: planner_server.GridBased.foo" in audit.warnings
    assert "ignored: planner_server.GridBased.smoother.w_smoth" in audit.warnings


def test_hybrid_smoothing_keeps_end_poses_and_turning_radius(wall_map) -> None:
    pl = hybrid()
    start, goal = (1.0, 2.5, math.pi / 2), (4.0, 2.5, -math.pi / 2)
    path = pl.create_plan(start, goal, wall_map.master)
    assert path_length(path) < path_length(pl.last_raw_path)
    assert_clear(path, wall_map)
    # the boundary curves restore the start heading (the search's is its bin's) and end on
    # the goal's
    assert path[0, 2] == pytest.approx(math.pi / 2, abs=1e-6)
    assert path[-2, 2] == pytest.approx(-math.pi / 2, abs=0.2)
    assert _curvatures(path).max() <= 1.02 / 0.4


def test_hybrid_tolerance_ends_near_an_occupied_goal(wall_map) -> None:
    pl = hybrid(tolerance=0.5)
    path = pl.create_plan((1.0, 2.5, 0.0), (2.5, 2.5, 0.0), wall_map.master)
    assert_clear(path, wall_map)
    end = path[-1]
    assert 0.0 < math.hypot(end[0] - 2.5, end[1] - 2.5) <= 0.5
