"""The exploration core on synthetic grids: frontiers, path lengths, gain, cost, choice."""

from __future__ import annotations

import math

import numpy as np
import pytest

from eddiebot.explore import (
    Blacklist,
    ExploreConfig,
    ExploreConfigError,
    FrontierTracker,
    ProgressMonitor,
    choose_frontier,
    distance_field,
    frontier_cells,
    frontier_cost,
    information_gain,
    looked_mask,
    reachable_mask,
    search_frontiers,
)
from eddiebot.explore.config import EDDIE_EXPLORE_PARAMS
from eddiebot.explore.frontiers import mark_swept
from eddiebot.explore.gain import UNKNOWN_BLOCKING
from eddiebot.maps import OccupancyMap

RES = 0.05


def room(width_cells: int = 90, height_cells: int = 60, open_east: bool = True) -> OccupancyMap:
    """A known room (walls on three sides, or four) in an unknown 200 x 100 grid; room
    interior columns 11..99, rows 21..78; with ``open_east`` the east side (column 100)
    is unknown: one straight frontier 58 cells (2.9 m) long."""
    d = np.full((100, 200), -1, np.int8)
    d[20:20 + height_cells, 10:10 + width_cells] = 0
    d[20, 10:10 + width_cells] = 100
    d[19 + height_cells, 10:10 + width_cells] = 100
    d[20:20 + height_cells, 10] = 100
    if not open_east:
        d[20:20 + height_cells, 9 + width_cells] = 100
    return OccupancyMap(d, RES, (0.0, 0.0, 0.0))


def faded_cone(config: ExploreConfig, unknown_from: float) -> float:
    """The gain of a cone whose unknown part starts ``unknown_from`` m ahead (m²): each
    point weighted by the chance that no wall stands before it in the unknown and that one
    stands behind it within range (else the beam is NaN and clears nothing)."""
    r = np.linspace(max(config.sensor_min_range, unknown_from), config.sensor_max_range, 2000)
    fade = np.exp(-UNKNOWN_BLOCKING * (r - unknown_from))
    back = 1.0 - np.exp(-UNKNOWN_BLOCKING * (config.sensor_max_range - r))
    return float(config.sensor_fov * np.trapezoid(r * fade * back, r))


def test_frontier_cells_are_unknown_cells_beside_free_ones() -> None:
    cells = frontier_cells(room(), ExploreConfig())
    rows, cols = np.nonzero(cells)
    assert set(cols) == {100}
    assert (rows.min(), rows.max()) == (21, 78)  # not beside the wall cells of rows 20, 79
    assert frontier_cells(room(open_east=False), ExploreConfig()).sum() == 0


def test_one_frontier_with_its_size_centroid_viewpoint_and_gain() -> None:
    config = ExploreConfig()
    search = search_frontiers(room(), (1.0, 2.5, 0.0), config)
    assert len(search.frontiers) == 1
    f = search.frontiers[0]
    assert f.size == pytest.approx(58 * RES)
    assert f.centroid == pytest.approx((5.025, 2.5), abs=1e-6)
    # the viewpoint stands back between the standoff (0.9 m) and half the range (2.25 m),
    # in the room's middle, and faces the frontier
    back = 5.025 - f.viewpoint[0]
    assert config.standoff - RES <= back <= 0.5 * config.sensor_max_range + RES
    assert abs(f.viewpoint[1] - 2.5) < 0.5 and abs(f.viewpoint[2]) < 0.05
    # path length from x = 1.0 to the viewpoint
    assert f.distance == pytest.approx(math.dist(f.viewpoint[:2], (1.0, 2.5)), abs=0.15)
    # the cone beyond the frontier to 4.5 m, each point weighted by how far into the
    # unknown it lies and by the chance its beam comes back
    assert f.gain == pytest.approx(faded_cone(config, back), rel=0.1)
    assert f.cost == pytest.approx(frontier_cost(f.distance, f.turn, f.gain, config))


def test_small_and_unreachable_frontiers_are_dropped() -> None:
    g = room()
    d = g.data.copy()
    d[40:45, 30] = -1  # a 5-cell hole (0.25 m) inside the room: too small by default 0.5 m
    search = search_frontiers(OccupancyMap(d, RES), (1.0, 2.5, 0.0), ExploreConfig())
    assert search.too_small == 1 and len(search.frontiers) == 1
    # a wall across the room cuts the robot off from the east frontier
    d = g.data.copy()
    d[20:80, 60] = 100
    search = search_frontiers(OccupancyMap(d, RES), (1.0, 2.5, 0.0), ExploreConfig())
    assert search.unreachable == 1 and not search.frontiers


def test_holes_too_small_to_visit_do_not_take_a_frontiers_viewpoints() -> None:
    # one- and two-cell gaps in the scan's coverage between the robot and the frontier (a
    # corridor seen by a Kinect): dropped as too small, they must not claim the spots that
    # look at the real frontier (each cell looks at the frontier nearest to it)
    config = ExploreConfig()
    clean = search_frontiers(room(), (1.0, 2.5, 0.0), config).frontiers[0]
    d = room().data.copy()
    for row in range(24, 78, 6):
        d[row:row + 2, 75] = -1
    search = search_frontiers(OccupancyMap(d, RES), (1.0, 2.5, 0.0), config)
    assert search.too_small == 9 and len(search.frontiers) == 1
    f = search.frontiers[0]
    back = 5.025 - f.viewpoint[0]
    assert config.standoff - RES <= back <= 0.5 * config.sensor_max_range + RES, f.viewpoint
    assert f.gain == pytest.approx(clean.gain, rel=0.15)
    # after a full turn at that viewpoint, another spot still looks at the frontier
    turn = [(f.viewpoint[0], f.viewpoint[1], a) for a in np.linspace(-math.pi, math.pi, 36)]
    again = search_frontiers(OccupancyMap(d, RES), f.viewpoint, config, looked=turn)
    g = again.frontiers[0]
    assert math.dist(g.viewpoint[:2], f.viewpoint[:2]) >= 0.3
    assert g.gain >= 0.5 * clean.gain, (g.viewpoint, g.gain, clean.gain)


def test_wavefront_measures_path_length_around_walls_not_straight_lines() -> None:
    passable = np.ones((60, 60), bool)
    passable[0:50, 30] = False  # a wall with a gap at rows 50..59
    dist = distance_field(passable, (10, 10), 0.1)
    assert dist[10, 10] == 0.0
    assert dist[10, 20] == pytest.approx(1.0)
    # (10, 10) → (50, 10) is 4 m as the crow flies; the path goes round the wall through the
    # gap at row 50: 20 diagonal + 20 straight steps there and as many back
    assert dist[10, 50] == pytest.approx(2 * (20 * math.sqrt(2) + 20) * 0.1)
    assert math.isinf(distance_field(np.zeros((5, 5), bool), (2, 2), 0.1)[0, 0])


def test_reachable_space_keeps_the_robot_radius_from_walls() -> None:
    config = ExploreConfig(robot_radius=0.23)
    mask = reachable_mask(room(), config)
    # row 20 is the wall: rows 21..24 are within 0.23 m (centres 0.05..0.20 m), row 25 is not
    assert not mask[24, 50] and mask[25, 50]


def test_gain_counts_only_what_the_camera_can_see() -> None:
    config = ExploreConfig()
    d = np.full((200, 200), -1, np.int8)
    g = OccupancyMap(d, RES, (-5.0, -5.0, 0.0))
    full = information_gain(g, (0.0, 0.0, 0.0), config)
    assert full == pytest.approx(faded_cone(config, 0.0), rel=0.1)
    d2 = d.copy()
    d2[:, 120] = 100  # a wall 1 m ahead stops every ray
    walled = information_gain(OccupancyMap(d2, RES, (-5.0, -5.0, 0.0)), (0.0, 0.0, 0.0), config)
    assert walled < 0.25 * full  # only the 0.5-1 m before the wall
    # looking at known free space gains nothing
    assert information_gain(OccupancyMap(np.zeros((200, 200), np.int8), RES, (-5.0, -5.0, 0.0)),
                            (0.0, 0.0, 0.0), config) == 0.0


def test_cost_trades_path_turning_and_gain() -> None:
    config = ExploreConfig(potential_scale=1.0, orientation_scale=0.5, gain_scale=0.3)
    assert frontier_cost(4.0, math.pi, 10.0, config) == pytest.approx(4.0 + 0.5 * math.pi - 3.0)
    # the frontier ahead wins over an equal one behind the robot when turning counts
    d = np.full((100, 300), -1, np.int8)
    d[20:80, 100:200] = 0
    d[20, 100:200] = d[79, 100:200] = 100
    g = OccupancyMap(d, RES)
    facing_east = search_frontiers(g, (7.5, 2.5, 0.0), config).frontiers
    assert len(facing_east) == 2
    assert facing_east[0].centroid[0] > 7.5 and facing_east[0].turn < facing_east[1].turn
    facing_west = search_frontiers(g, (7.5, 2.5, math.pi), config).frontiers
    assert facing_west[0].centroid[0] < 7.5


def test_swept_cells_are_free() -> None:
    g = OccupancyMap(np.full((40, 40), -1, np.int8), RES)
    swept = mark_swept(g, [(1.0, 1.0)], 0.23)
    # cells whose centres lie within 0.23 m of (1, 1): 4 cells either side, not 5
    assert swept.data[20, 20] == 0 and swept.data[20, 24] == 0 and swept.data[20, 25] == -1
    assert (swept.data == 0).sum() == np.sum(np.hypot(*np.mgrid[-4:5, -4:5]) <= 4.5)


def test_tracker_keeps_identity_of_a_flickering_frontier() -> None:
    t = FrontierTracker(tolerance=0.75, memory=2)
    a = t.update([(1.0, 1.0), (5.0, 5.0)])
    b = t.update([(5.3, 5.1), (1.2, 0.9)])  # moved a little, other order
    assert b == [a[1], a[0]]
    t.update([(5.3, 5.1)])  # (1, 1) flickers out for one search ...
    c = t.update([(1.1, 1.0), (5.3, 5.1)])  # ... and comes back: the same frontier
    assert c == [a[0], a[1]]
    d = t.update([(3.0, 3.0)])  # too far from both: new
    assert d[0] not in a


def test_blacklist_and_choice() -> None:
    config = ExploreConfig()
    frontiers = search_frontiers(room(), (1.0, 2.5, 0.0), config).frontiers
    ids = [7]
    bl = Blacklist(radius=0.6)
    assert choose_frontier(frontiers, ids, bl, None, config) == (frontiers[0], 7)
    bl.add((5.2, 2.6), "navigation failed")
    assert bl.contains(frontiers[0].centroid)
    assert choose_frontier(frontiers, ids, bl, None, config) is None
    assert len(bl) == 1


def test_blacklist_forgives_only_places_the_robot_could_not_get_to() -> None:
    bl = Blacklist(radius=0.6)
    bl.add((1.0, 1.0), "unproductive")
    bl.add((3.0, 1.0), "no progress", retryable=True)
    assert bl.forgive() == 1
    assert bl.contains((1.0, 1.0)) and not bl.contains((3.0, 1.0))
    assert bl.forgive() == 0


def test_goals_keep_away_from_avoided_spots() -> None:
    config = ExploreConfig()
    grid = room()
    before = search_frontiers(grid, (1.0, 2.5, 0.0), config).frontiers[0]
    spot = before.viewpoint[:2]
    after = search_frontiers(grid, (1.0, 2.5, 0.0), config, avoid=[spot]).frontiers[0]
    assert math.dist(after.viewpoint[:2], spot) > config.avoid_radius
    assert math.dist(after.entry, spot) > config.avoid_radius


def door_wall(grid: OccupancyMap) -> OccupancyMap:
    """``grid`` (a `room`) with a wall across it at x = 2.5 m and two 0.7 m gaps in it,
    y 1.3-1.95 m (south) and 3.0-3.65 m (north)."""
    d = grid.data.copy()
    d[20:80, 50] = 100
    d[26:40, 50] = 0
    d[60:74, 50] = 0
    return OccupancyMap(d, RES, grid.origin)


def test_after_no_progress_viewpoints_are_reached_without_passing_the_blocked_spot() -> None:
    config = ExploreConfig()
    grid = door_wall(room())
    robot = (1.0, 1.6, 0.0)
    before = search_frontiers(grid, robot, config).frontiers[0]
    assert before.viewpoint[1] < 2.6  # nearest by path: through the south gap
    # the robot stood blocked in the south gap (a chair below the scan): the viewpoint is
    # now one whose shortest path runs through the north gap
    after = search_frontiers(grid, robot, config, blocked=[(2.5, 1.625)]).frontiers[0]
    assert after.viewpoint[1] > 2.9
    passable = reachable_mask(grid, config)
    rows, cols = np.mgrid[0:passable.shape[0], 0:passable.shape[1]]
    closed = passable & (np.hypot(rows - 32, cols - 50) * RES > 0.3)  # the blocked disc
    start = (20, 32)
    col, row = int(after.viewpoint[0] / RES), int(after.viewpoint[1] / RES)
    assert distance_field(closed, start, RES)[row, col] == pytest.approx(
        distance_field(passable, start, RES)[row, col], abs=0.05)
    # with nothing else to choose (a blocked spot every way round) the viewpoint stays
    both = search_frontiers(grid, robot, config, blocked=[(2.5, 1.625), (2.5, 3.325)])
    assert both.frontiers[0].viewpoint == before.viewpoint


def test_viewpoints_keep_the_preferred_clearance_when_the_frontier_has_room() -> None:
    from scipy import ndimage

    grid = room()
    occupied = grid.data >= 65
    clearance = ndimage.distance_transform_edt(~occupied) * RES
    robot = (1.0, 1.35, 0.0)  # beside the south wall
    for preferred in (0.5, 1.2):
        f = search_frontiers(grid, robot, ExploreConfig(preferred_clearance=preferred)).frontiers[0]
        col, row = int(f.viewpoint[0] / RES), int(f.viewpoint[1] / RES)
        assert clearance[row, col] >= preferred - 1e-9
    # a narrow room has no such spot: the viewpoint keeps goal_clearance only
    narrow = room(height_cells=18)  # 0.8 m between the walls
    occupied = narrow.data >= 65
    clearance = ndimage.distance_transform_edt(~occupied) * RES
    f = search_frontiers(narrow, (1.0, 1.4, 0.0), ExploreConfig()).frontiers[0]
    col, row = int(f.viewpoint[0] / RES), int(f.viewpoint[1] / RES)
    assert ExploreConfig().goal_clearance <= clearance[row, col] < 0.5


def test_progress_monitor_times_out_without_getting_closer() -> None:
    m = ProgressMonitor(timeout=30.0)
    m.reset(0.0)
    assert not m.update(5.0, 0.0)
    assert not m.update(4.0, 20.0)  # closer: progress
    assert not m.update(4.0, 49.0)
    assert m.update(3.99, 50.5)  # 1 cm is not progress; 30.5 s since the last


def test_config_validates() -> None:
    assert ExploreConfig().potential_scale == 1e-3  # explore_lite's default
    with pytest.raises(ExploreConfigError):
        ExploreConfig(planner_frequency=0.0)
    with pytest.raises(ExploreConfigError):
        ExploreConfig.from_mapping({"potential_scal": 1.0})
    assert ExploreConfig.from_mapping({"min_frontier_size": 1}).min_frontier_size == 1.0


def test_free_space_on_the_map_border_is_a_frontier() -> None:
    # a corridor seen down its length: the map ends where the scan end points did
    d = np.zeros((40, 100), np.int8)
    d[0, :] = d[39, :] = 100
    search = search_frontiers(OccupancyMap(d, RES, (0.0, 0.0, 0.0)), (0.5, 1.0, 0.0), ExploreConfig())
    east = [f for f in search.frontiers if f.centroid[0] > 4.9]
    assert len(east) == 1 and east[0].size == pytest.approx(38 * RES)
    assert east[0].points[:, 0].min() == pytest.approx(5.025)  # just beyond the last column


def test_ragged_frontier_pieces_are_one_frontier() -> None:
    from eddiebot.explore import group_frontier_cells

    cells = np.zeros((10, 30), bool)
    cells[5, 0:8] = True
    cells[5, 10:18] = True  # two cells apart from the first piece: the same frontier
    cells[5, 25:29] = True  # seven cells apart: another
    labels, count = group_frontier_cells(cells, gap=1)
    assert count == 2
    assert labels[5, 0] == labels[5, 17] != labels[5, 25]
    assert (labels > 0).sum() == cells.sum()  # the joining cells are not frontier cells
    assert group_frontier_cells(cells, gap=0)[1] == 3


def test_a_direction_already_looked_along_from_a_spot_gains_nothing_more() -> None:
    config = ExploreConfig()
    g = OccupancyMap(np.full((200, 200), -1, np.int8), RES, (-5.0, -5.0, 0.0))
    fresh = information_gain(g, (0.0, 0.0, 0.0), config)
    assert fresh > 1.0
    looked = looked_mask(g, [(0.1, 0.0, 0.0)], config)
    # from (nearly) the same spot, the same way: every ray was looked along already
    assert information_gain(g, (0.0, 0.0, 0.0), config, looked) < 0.2 * fresh
    # the other way, or 1 m aside, the camera has not looked yet
    assert information_gain(g, (0.0, 0.0, math.pi), config, looked) == pytest.approx(fresh, rel=0.05)
    assert information_gain(g, (0.0, 1.0, 0.0), config, looked) == pytest.approx(fresh, rel=0.05)


def test_a_beam_ending_on_a_known_wall_clears_what_it_crosses() -> None:
    config = ExploreConfig()
    d = np.full((200, 200), -1, np.int8)
    d[:, 150] = 100  # a known wall 2.5 m ahead
    walled = information_gain(OccupancyMap(d, RES, (-5.0, -5.0, 0.0)), (0.0, 0.0, 0.0), config)
    open_ = information_gain(OccupancyMap(np.full((200, 200), -1, np.int8), RES, (-5.0, -5.0, 0.0)),
                             (0.0, 0.0, 0.0), config)
    # the rays to the wall come back for sure: the 0.5-2.5 m before it is worth more than
    # the same stretch of the open cone, where a beam may meet nothing within 4.5 m
    r = np.linspace(config.sensor_min_range, 2.5, 1000)
    expected = float(config.sensor_fov * np.trapezoid(r * np.exp(-UNKNOWN_BLOCKING * r), r))
    assert walled == pytest.approx(expected, rel=0.1)
    assert walled > 0.5 * open_


def test_a_viewpoint_looks_across_a_corridor_middle_it_looked_down_before() -> None:
    config = ExploreConfig(potential_scale=1.0, orientation_scale=0.5, gain_scale=0.3)
    # a 2 m corridor, known but for its middle strip 1-4 m ahead of the robot, which looked
    # down it from x = 0.5 (the middle beams met nothing within 4.5 m: NaN, nothing cleared)
    d = np.zeros((60, 200), np.int8)
    d[10, :] = d[50, :] = 100
    d[27:34, 30:80] = -1
    d[:, 0] = d[:, 199] = 100
    g = OccupancyMap(d, RES)
    robot = (0.5, 1.5, 0.0)
    looks = [(0.5, 1.5, 0.0), (0.6, 1.5, 0.0)]
    f = search_frontiers(g, robot, config, looked=looks).frontiers
    assert len(f) == 1
    x, y, yaw = f[0].viewpoint
    # not from the corridor's middle line looking down it again: from aside, looking across
    assert abs(y - 1.5) > 0.2 or abs(math.remainder(yaw, 2 * math.pi)) > 0.6
    assert f[0].gain > 0.2


def test_a_visit_is_unproductive_only_when_it_promised_area_and_showed_none() -> None:
    from eddiebot.explore.tracking import Track

    t = Track(0, (0.0, 0.0), known_at_goal=10.0, expected=3.0, arrived=True)
    t.judge_visit(10.2)  # promised 3 m², showed 0.2 m²
    assert t.visits == 1 and not t.arrived
    t.judge_visit(10.2)  # no new arrival: nothing judged
    assert t.visits == 1
    t.arrived, t.known_at_goal = True, 10.2
    t.judge_visit(12.0)  # showed 1.8 m²: productive again
    assert t.visits == 0
    # promised little, showed little: no verdict on the frontier
    low = Track(1, (0.0, 0.0), known_at_goal=10.0, expected=0.3, arrived=True)
    low.judge_visit(10.1)
    assert low.visits == 0 and low.idle == 1


def test_a_frontier_round_a_corner_is_looked_at_from_where_the_camera_sees_past_it() -> None:
    # an L of known floor (a maze's first corner): the robot in the upper-left room, the
    # unknown beyond the corner north of the lower room's east half, behind the wall the
    # robot faces; a spot near the robot looking along that wall sees a sliver past its end
    config = ExploreConfig.from_mapping(dict(EDDIE_EXPLORE_PARAMS))
    d = np.full((100, 200), -1, np.int8)
    d[20:50, 10:91] = 0  # lower room: x 0.5-4.55, y 1.0-2.5
    d[50:81, 10:55] = 0  # upper-left room: x 0.5-2.75, y 2.5-4.05
    d[19, 9:92] = d[81, 9:56] = 100
    d[19:82, 9] = d[19:50, 91] = 100
    d[50:82, 55] = 100  # the wall between that room and the unknown beyond the corner
    g = OccupancyMap(d, RES, (0.0, 0.0, 0.0))
    (f,) = search_frontiers(g, (1.5, 3.5, 0.0), config).frontiers
    x, y, yaw = f.viewpoint
    # from the lower room, east of the corner, looking north-east into the unknown
    assert x > 2.5 and y < 2.2 and 0.3 < yaw < 1.8
    assert f.gain > 1.5
    assert information_gain(g, f.viewpoint, config) > 1.5


def test_a_corridor_middle_looked_down_from_its_end_is_looked_at_across_from_beside_it() -> None:
    config = ExploreConfig(**{k: v for k, v in EDDIE_EXPLORE_PARAMS.items()
                              if k in ExploreConfig.__dataclass_fields__})
    # a 1.9 m corridor 12 m long, known but for its middle from x = 3 m on (the beams down
    # it met nothing within range: NaN, nothing cleared), which the robot looked down from
    # every spot short of it, all round. Every spot 0.9 m (the standoff) from that middle
    # lies short of it, and shows nothing more; beside it the corridor is 0.8 m wide.
    d = np.zeros((59, 240), np.int8)
    d[10, :] = d[48, :] = 100
    d[:, 0] = d[:, 239] = 100
    d[26:33, 60:239] = -1
    g = OccupancyMap(d, RES)
    robot = (1.0, 1.45, 0.0)
    looks = [(x, y, a) for x in np.arange(0.6, 2.9, 0.2) for y in (1.0, 1.45, 1.9)
             for a in np.arange(0.0, 2 * math.pi, 0.15)]
    # from the standoff band: nothing to see, as a search that would end exploring
    before = search_frontiers(g, robot, config, looked=looks).frontiers
    assert len(before) == 1 and before[0].gain < config.min_gain
    search = search_frontiers(g, robot, config, looked=looks, near_views=True)
    assert len(search.frontiers) == 1
    f = search.frontiers[0]
    assert f.gain > 0.2
    x, y, _ = f.viewpoint
    assert x > 3.0 and abs(y - 1.5) > 0.3  # beside the unknown middle, not short of it
