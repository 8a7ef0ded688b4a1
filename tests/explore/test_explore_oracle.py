"""The oracle tour (benchmarks/explore_oracle.py) on constructed worlds: a square room and an
L-shaped corridor, with the speed model and the ordering checked by hand."""

from __future__ import annotations

import dataclasses
import math
import sys
from pathlib import Path

import numpy as np
import pytest

from eddiebot.maps import OccupancyMap

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))

import explore_oracle as oracle

RES = 0.05


def _grid(free_rects: list[tuple[float, float, float, float]], size: tuple[float, float]) -> OccupancyMap:
    """Everything occupied but the free rectangles (x0, y0, x1, y1, m); origin (-0.5, -0.5)."""
    w, h = round(size[0] / RES), round(size[1] / RES)
    data = np.full((h, w), 100, np.int8)
    for x0, y0, x1, y1 in free_rects:
        c0, c1 = round((x0 + 0.5) / RES), round((x1 + 0.5) / RES)
        r0, r1 = round((y0 + 0.5) / RES), round((y1 + 0.5) / RES)
        data[r0:r1, c0:c1] = 0
    return OccupancyMap(data=data, resolution=RES, origin=(-0.5, -0.5, 0.0))


LIMITS = oracle.SpeedLimits(linear=0.4, accel=0.8, decel=1.0, angular=1.2, angular_accel=2.0)
PARAMS = oracle.OracleParams(spacing=0.3, rays=360)


def test_speed_model_by_hand() -> None:
    # 2 m at 0.4 m/s: ramps 0.4²/2·(1/0.8 + 1/1.0) = 0.18 m, so 2/0.4 + 0.4/2·2.25 = 5.45 s
    assert oracle.leg_time(2.0, LIMITS) == pytest.approx(5.45)
    # 0.1 m never reaches 0.4 m/s: peak √(2·0.1/2.25) = 0.298 m/s, 0.298/0.8 + 0.298/1.0
    peak = math.sqrt(0.2 / 2.25)
    assert oracle.leg_time(0.1, LIMITS) == pytest.approx(peak / 0.8 + peak)
    # a half turn at 1.2 rad/s and 2 rad/s²: π/1.2 + 1.2/2·(1/2 + 1/2)
    assert oracle.turn_time(math.pi, LIMITS) == pytest.approx(math.pi / 1.2 + 0.6)
    assert oracle.leg_time(0.0, LIMITS) == 0.0


def test_speed_limits_read_from_the_nav_config(tmp_path: Path) -> None:
    limits = oracle.speed_limits()
    # the controller's 0.4 m/s and 1.2 rad/s turn, under the smoother's 0.5 m/s and 1.5 rad/s
    assert (limits.linear, limits.angular) == (0.4, 1.2)
    assert (limits.accel, limits.decel, limits.angular_accel) == (0.8, 1.0, 2.0)
    cfg = tmp_path / "nav2.yaml"
    cfg.write_text("controller_server:\n  ros__parameters:\n    controller_plugins: [FollowPath]\n"
                   "    FollowPath: {desired_linear_vel: 0.7, rotate_to_heading_angular_vel: 0.9}\n"
                   "velocity_smoother:\n  ros__parameters:\n    max_velocity: [0.5, 0.0, 1.5]\n"
                   "    max_accel: [0.6, 0.0, 1.0]\n    max_decel: [-0.9, 0.0, -1.0]\n")
    mine = oracle.speed_limits(cfg)
    assert (mine.linear, mine.angular, mine.accel, mine.decel) == (0.5, 0.9, 0.6, 0.9)


def test_the_robots_own_slowdowns_read_from_the_nav_config() -> None:
    limits = oracle.speed_limits()
    # the collision monitor's NearWallLimit, RPP's approach slowdown, the goal tolerance
    assert (limits.near_wall_radius, limits.near_wall_linear) == (0.5, 0.2)
    assert (limits.approach_dist, limits.approach_min, limits.goal_tolerance) == (0.6, 0.05, 0.15)
    assert limits.cap(0.3) == 0.2 and limits.cap(0.6) == 0.4


def test_path_drive_time_by_hand() -> None:
    steps = np.full(40, 0.05)  # 2 m
    # one cap, no approach slowdown: the trapezoid
    assert oracle.path_drive_time(steps, np.full(40, 0.4), LIMITS) == pytest.approx(5.45)
    # near a wall all the way: 2/0.2 + 0.2/2·(1/0.8 + 1/1.0)
    assert oracle.path_drive_time(steps, np.full(40, 0.2), LIMITS) == pytest.approx(10.225)
    # RPP's approach: 1.4 m at 0.4 m/s, then 0.4·left/0.6 down to the 0.15 m tolerance,
    # 0.6/0.4·ln(0.6/0.15) s; the ramp up, and down from 0.4·0.175/0.6 m/s
    rpp = dataclasses.replace(LIMITS, approach_dist=0.6, approach_min=0.05, goal_tolerance=0.15)
    by_hand = 1.4 / 0.4 + 1.5 * math.log(4.0) + 0.4 / 1.6 + 0.4 * 0.175 / 0.6 / 2.0
    assert oracle.path_drive_time(steps, np.full(40, 0.4), rpp) == pytest.approx(by_hand, rel=0.01)
    assert oracle.path_drive_time(steps[:2], np.full(2, 0.4), rpp) == 0.0  # within tolerance


def test_a_narrow_corridor_is_driven_at_the_near_wall_limit() -> None:
    corridor = _grid([(0.0, 0.0, 8.0, 1.0), (7.0, 0.0, 8.0, 7.0)], (9.0, 8.0))
    free = oracle.oracle_tour(corridor, corridor, (0.5, 0.5, 0.0), PARAMS, LIMITS).tour(1.0)
    walled = dataclasses.replace(LIMITS, near_wall_radius=0.6, near_wall_linear=0.2)
    slow = oracle.oracle_tour(corridor, corridor, (0.5, 0.5, 0.0), PARAMS, walled).tour(1.0)
    # 1 m wide: every centre is within 0.6 m of a wall, so every leg at 0.2 m/s
    assert slow.path_m == pytest.approx(free.path_m, rel=0.05)
    assert slow.drive_s > 1.8 * free.drive_s
    assert slow.turn_s == pytest.approx(free.turn_s, rel=0.05)


def test_order_is_the_shortest_open_path_on_a_line() -> None:
    xs = [0.0, 3.0, 1.0, 2.0, -1.0]  # node 0 is the start
    dist = np.abs(np.subtract.outer(xs, xs))
    order = oracle.order_tour(dist)
    assert sorted(order) == [1, 2, 3, 4]
    length = sum(dist[a, b] for a, b in zip([0, *order], order, strict=False))
    assert length == pytest.approx(5.0)  # -1 first, then 1, 2, 3 (not 1, 2, 3, -1: 7 m)
    closed = oracle.order_tour(dist, closed=True)
    loop = [0, *closed, 0]
    assert sum(dist[a, b] for a, b in zip(loop, loop[1:], strict=False)) == pytest.approx(8.0)


def test_rays_stop_at_walls_and_skip_the_near_range() -> None:
    # a 6 x 1 m corridor with a wall across it at x = 3 m
    grid = _grid([(0.0, 0.0, 3.0, 1.0), (3.05, 0.0, 6.0, 1.0)], (7.0, 2.0))
    blocked = grid.data >= 65
    cell = (round(1.0 / RES), round(1.5 / RES))  # (row, col) of (1.0, 0.5)
    flat, _ = oracle.visibility(blocked, RES, cell, oracle.OracleParams(rays=720))
    rows, cols = np.unravel_index(np.unique(flat), blocked.shape)
    x = cols * RES - 0.5 + RES / 2
    y = rows * RES - 0.5 + RES / 2
    d = np.hypot(x - 1.025, y - 0.525)
    assert d.min() >= 0.5 - RES  # nothing nearer than the Kinect's 0.5 m
    assert x.max() < 3.05  # the wall stops every ray
    assert x.min() < 0.05  # ... but the corridor's near end is seen (1 m away)
    assert not blocked[rows, cols].any()


def test_a_ray_that_meets_nothing_within_the_cameras_range_sees_nothing() -> None:
    # a 1 m wide corridor 20 m long, looked down from x = 1 m: its middle line 3-4 m ahead
    # lies only on rays that end on the far wall, 19 m off (no return: NaN, SLAM clears
    # nothing along them); 0.4 m off the middle, rays that end on the side walls cross it
    grid = _grid([(0.0, 0.0, 20.0, 1.0)], (21.0, 2.0))
    blocked = grid.data >= 65
    cell = (round(1.0 / RES), round(1.5 / RES))  # (row, col) of (1.0, 0.5)

    def seen(params: oracle.OracleParams) -> set[tuple[float, float]]:
        flat, _ = oracle.visibility(blocked, RES, cell, params)
        rows, cols = np.unravel_index(np.unique(flat), blocked.shape)
        return set(zip(np.round(cols * RES - 0.5 + RES / 2, 3).tolist(),
                       np.round(rows * RES - 0.5 + RES / 2, 3).tolist(), strict=True))

    returning = seen(oracle.OracleParams(rays=720))
    every = seen(oracle.OracleParams(rays=720, return_range=None))
    middle = {(x, 0.525) for x in np.round(np.arange(4.025, 5.0, RES), 3).tolist()}
    assert middle <= every and not middle & returning
    aside = {(x, 0.125) for x in np.round(np.arange(2.025, 3.0, RES), 3).tolist()}
    assert aside <= returning
    assert returning < every


def test_square_room_is_seen_from_one_ring_of_views() -> None:
    # a 3 x 3 m room, start in its middle facing +x; from one spot the 4.5 m range reaches every
    # corner: one sweep of views there sees all but the floor within 0.5 m of it, which a
    # second, short stop shows. Greedy cover by single views would drive to three corners.
    room = _grid([(0.0, 0.0, 3.0, 3.0)], (4.0, 4.0))
    result = oracle.oracle_tour(room, room, (1.5, 1.5, 0.0), PARAMS, LIMITS)
    assert result.unseeable == 0.0
    # the whole room but 3 cells in each corner, where a round body never reaches
    assert result.reachable_cells == 60 * 60 - 4 * 3
    full = result.tour(1.0)
    assert full.seen == 1.0
    assert result.tour(0.95).seen >= 0.95
    positions = {(round(p[0], 2), round(p[1], 2)) for p in (leg.pose for leg in full.legs)}
    assert len(positions) == 2
    assert full.method == "places"
    assert len(full.legs) >= 3  # 57° views: no single one sees a room that surrounds it
    for leg in full.legs:
        assert 0.2 < leg.pose[0] < 2.8 and 0.2 < leg.pose[1] < 2.8
    assert full.path_m < 3.5
    assert full.time_s == pytest.approx(full.drive_s + full.turn_s)
    assert full.drive_s == pytest.approx(sum(oracle.leg_time(leg.path_m, LIMITS) for leg in full.legs))
    assert 5.0 < full.time_s < 25.0
    assert full.round_trip_s > full.time_s


def test_l_corridor_tour_goes_round_the_corner() -> None:
    # a 1 m wide L: 8 m along x, then 6 m up y from its far end; start at the x leg's end
    corridor = _grid([(0.0, 0.0, 8.0, 1.0), (7.0, 0.0, 8.0, 7.0)], (9.0, 8.0))
    result = oracle.oracle_tour(corridor, corridor, (0.5, 0.5, 0.0), PARAMS, LIMITS)
    full = result.tour(1.0)
    assert result.unseeable == 0.0 and full.seen == 1.0
    poses = [leg.pose for leg in full.legs]
    # the top of the y leg (6.5-7 m) is 4.5 m from no point of the x leg: a view from up the
    # y leg, looking up it
    up = [p for p in poses if p[0] > 7.0 and p[1] > 1.9 and abs(math.remainder(p[2] - math.pi / 2, 2 * math.pi)) < 0.6]
    assert up
    # the floor behind the start (under 0.5 m from it) needs a view looking back down the x leg
    back = [p for p in poses if p[1] < 1.0 and abs(math.remainder(p[2] - math.pi, 2 * math.pi)) < 0.6]
    assert back
    # the shortest way from the start to y = 1.9 m in the other leg is about 7 + 1.4 m
    assert 8.0 < full.path_m < 20.0
    assert full.home_path_m > 7.0
    time_95 = result.tour(0.95).time_s
    assert time_95 <= full.time_s
    assert full.time_s > full.path_m / LIMITS.linear  # driving at most at 0.4 m/s, and turning


def test_grids_must_match() -> None:
    a = _grid([(0.0, 0.0, 3.0, 3.0)], (4.0, 4.0))
    b = _grid([(0.0, 0.0, 3.0, 3.0)], (5.0, 4.0))
    with pytest.raises(ValueError, match="share one grid"):
        oracle.oracle_tour(a, b, (1.5, 1.5, 0.0), PARAMS, LIMITS)
    with pytest.raises(ValueError, match="no reachable floor"):
        oracle.oracle_tour(a, a, (-0.3, -0.3, 0.0), PARAMS, LIMITS)


def test_bench_explore_oracle_row_on_a_world_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import bench_explore

    monkeypatch.setenv("EDDIE_CACHE_DIR", str(tmp_path / "cache"))
    world = tmp_path / "room.yaml"
    world.write_text("name: room\nstart: {x: 1.5, y: 1.5}\nwalls:\n"
                     "  - {points: [[0, 0], [3, 0], [3, 3], [0, 3], [0, 0]], thickness: 0.1}\n")
    row = bench_explore.oracle_row(str(world))
    # the room inside its 0.1 m walls: 2.9 x 2.9 m, less the corners a round body misses
    assert row["reachable_m2"] == pytest.approx(2.9 * 2.9, rel=0.05)
    assert row["unseeable"] == 0.0
    assert 0.0 < row["oracle_95_s"] <= row["oracle_100_s"] < row["oracle_s"] < 40.0
    assert row["method"] == "places"
    assert row["oracle_100_views"] >= 3
