"""Through a doorway with Eddie's tuning (config/nav2.yaml): NavFn on the inflated map, RPP
following it, and the progress checker that counts turning in place."""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml
from navtest_helpers import EDDIE_NAV2, eddie_collision_monitor, make_costmap, simulate
from scipy import ndimage

from eddiebot.nav.controllers import (
    PoseProgressChecker,
    PoseProgressCheckerConfig,
    RegulatedPurePursuitConfig,
    RegulatedPurePursuitController,
    SimpleGoalChecker,
    SimpleProgressChecker,
    build_controller_server,
)
from eddiebot.nav.errors import NoValidControl
from eddiebot.nav.params import from_params
from eddiebot.nav.planners import NavfnPlanner

NAV2 = EDDIE_NAV2
RES = 0.05
EDDIE_RADIUS = 0.2245
START = (1.0, 1.0, 0.0)


@pytest.fixture(scope="module")
def params() -> dict:
    return yaml.safe_load(NAV2.read_text())


def _door_map() -> np.ndarray:
    """6 x 5 m: a 2 m corridor (y < 2), a 0.12 m wall at y = 2.0 with a door of 0.875 m
    (x 3.0-3.875, an open leaf takes 2.5 cm of a 0.9 m doorway), a room above; cells
    occupied within half a cell of an outline, as the simulator's ground-truth maps."""
    occ = np.zeros((100, 120), dtype=np.int8)
    occ[[0, -1], :] = 100
    occ[:, [0, -1]] = 100
    ys = (np.arange(100) + 0.5) * RES
    xs = (np.arange(120) + 0.5) * RES
    wall_rows = (ys >= 2.0 - RES / 2) & (ys <= 2.12 + RES / 2)
    wall_cols = (xs <= 3.0 + RES / 2) | (xs >= 3.875 - RES / 2)
    occ[np.ix_(wall_rows, wall_cols)] = 100
    return occ


def _inflation(params: dict, which: str) -> tuple[float, float]:
    p = params[which][which]["ros__parameters"]
    infl = p["inflation_layer"]
    return float(infl["inflation_radius"]), float(infl["cost_scaling_factor"])


def _through_door(params: dict, rpp_overrides: dict | None = None,
                  inflation: tuple[float, float] | None = None) -> tuple[bool, float, str]:
    occ = _door_map()
    radius = float(params["global_costmap"]["global_costmap"]["ros__parameters"]["robot_radius"])
    g_infl = inflation or _inflation(params, "global_costmap")
    l_infl = inflation or _inflation(params, "local_costmap")
    global_cm = make_costmap(occ, RES, radius, *g_infl)
    local_cm = make_costmap(occ, RES, radius, *l_infl)
    start, goal = START, (3.44, 3.5, math.pi / 2)
    path = NavfnPlanner().create_plan(start, goal, global_cm.master)
    rpp_params = dict(params["controller_server"]["ros__parameters"]["FollowPath"])
    rpp_params.pop("plugin")
    rpp_params.update(rpp_overrides or {})
    rpp = RegulatedPurePursuitController(from_params(RegulatedPurePursuitConfig, rpp_params))
    dist = ndimage.distance_transform_edt(occ == 0) * RES - RES / 2  # to occupied outlines
    try:
        pose, reached, log = simulate(rpp, path, local_cm, start, SimpleGoalChecker(), steps=1200)
    except NoValidControl as exc:
        return False, math.nan, str(exc)
    cells = np.clip((log[:, :2] / RES).astype(int), 0, None)
    clearance = float(dist[cells[:, 1], cells[:, 0]].min())
    return bool(reached), clearance, ""


def test_doorway_with_eddies_tuning(params: dict) -> None:
    reached, clearance, err = _through_door(params)
    assert err == "" and reached
    assert clearance > EDDIE_RADIUS + 0.05  # passed with room to spare


def test_pose_progress_checker_counts_turning() -> None:
    s = 1_000_000_000
    simple, pose = SimpleProgressChecker(), PoseProgressChecker()
    for pc in (simple, pose):
        assert pc.check((0, 0, 0), 0)
    # turning in place by 0.3 rad per 4 s, for 12 s: only the pose checker sees progress
    for k in range(1, 4):
        th = 0.3 * k
        ok_simple = simple.check((0.0, 0.0, th), 4 * k * s + 1)
        ok_pose = pose.check((0.0, 0.0, th), 4 * k * s + 1)
    assert not ok_simple and ok_pose
    # standing still without turning fails both after the allowance
    assert not pose.check((0.0, 0.0, 0.9), 30 * s)
    pc = PoseProgressChecker(PoseProgressCheckerConfig(required_movement_angle=0.2,
                                                       movement_time_allowance=1.0))
    assert pc.check((0, 0, 3.1), 0)
    assert pc.check((0, 0, -3.0), s // 2)  # 0.18 rad across the wrap: not enough ...
    assert not pc.check((0, 0, -3.0), 2 * s)  # ... and the allowance ran out
    assert pc.check((0, 0, -2.9), 3 * s)


def test_config_uses_the_pose_progress_checker_and_ir_cones_only(params: dict) -> None:
    srv = build_controller_server(params["controller_server"]["ros__parameters"])
    assert isinstance(srv.progress_checkers["progress_checker"], PoseProgressChecker)
    topics = params["local_costmap"]["local_costmap"]["ros__parameters"]["range_layer"]["topics"]
    assert topics and all("/ir/" in t for t in topics)


def _gap_map(narrow: float) -> np.ndarray:
    """6 x 5 m: a wall across y = 2.5 (0.8 m deep, as a pallet row) with a ``narrow`` gap
    centred at x = 3.0 and a 1.0 m gap at x = 5.0."""
    occ = np.zeros((100, 120), dtype=np.int8)
    occ[[0, -1], :] = 100
    occ[:, [0, -1]] = 100
    ys = (np.arange(100) + 0.5) * RES
    xs = (np.arange(120) + 0.5) * RES
    rows = (ys >= 2.1) & (ys <= 2.9)
    gap = (np.abs(xs - 3.0) < narrow / 2) | (np.abs(xs - 5.0) < 0.5)
    occ[np.ix_(rows, ~gap)] = 100
    return occ


def _stop_reach_beside() -> float:
    """How far beside the centre a return stops Eddie driving forward (m), asked of the
    collision monitor that the shipped nav2.yaml builds."""
    from eddiebot.nav.collision_monitor import ActionType
    from eddiebot.nav.types import Twist2D

    monitor, quiet = eddie_collision_monitor()
    ys = np.arange(0.2, 0.6, 0.005)
    stops = [monitor.process(Twist2D(0.2, 0.0, 0.0), {**quiet, "scan": np.array([[0.0, y]])},
                             0).action == ActionType.STOP for y in ys]
    return float(ys[np.flatnonzero(stops)].max())


def test_plans_keep_the_collision_monitors_stop_zone_clear(params: dict) -> None:
    """Between two pallets 0.56 m apart (the warehouse's, 5.6 cm beside Eddie each side)
    a plan would put obstacles inside the collision monitor's stop zone ahead, which then
    stops the robot driving on for as long as it stands there. The global costmap's
    inscribed radius (robot_radius + footprint_padding) is at least the stop zone's reach
    beside the robot, so NavFn takes the 1 m gap instead."""
    from eddiebot.maps import OccupancyMap
    from eddiebot.nav.costmap import build_costmap

    cm_params = dict(params["global_costmap"]["global_costmap"]["ros__parameters"])
    cm_params["plugins"] = ["static_layer", "inflation_layer"]
    costmap = build_costmap(cm_params, "global_costmap")
    stop_radius = _stop_reach_beside()
    assert stop_radius == pytest.approx(0.3, abs=0.01)
    assert costmap.inscribed_radius >= stop_radius

    occ = _gap_map(0.56)
    costmap.set_static_map(OccupancyMap(data=occ, resolution=RES))
    costmap.update_map(np.array([1.0, 1.0, 0.0]))
    path = NavfnPlanner().create_plan((3.0, 1.0, math.pi / 2), (3.0, 4.0, math.pi / 2),
                                      costmap.master)
    dist = ndimage.distance_transform_edt(occ == 0) * RES - RES / 2
    cells = np.clip((np.asarray(path)[:, :2] / RES).astype(int), 0, None)
    assert float(dist[cells[:, 1], cells[:, 0]].min()) >= stop_radius - RES / 2
    crossing = np.asarray(path)[np.argmin(np.abs(np.asarray(path)[:, 1] - 2.5))]
    assert abs(crossing[0] - 5.0) < 0.3  # through the 1 m gap
