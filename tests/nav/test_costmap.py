"""Costmaps: cost values, inflation profile, static/obstacle/range layers, filters, clearing."""

from __future__ import annotations

import math

import numpy as np
import pytest
from navtest_helpers import make_costmap

from eddiebot.maps import OccupancyMap
from eddiebot.nav import cost_values as cv
from eddiebot.nav.costmap import (
    CostmapFilterInfo,
    RangeReading,
    build_costmap,
    cloud_observation,
    inflation_cost,
    interpret_static_value,
    scan_observation,
    to_occupancy_grid,
)
from eddiebot.nav.costmap.filters import SPEED_FILTER_PERCENT
from eddiebot.nav.errors import ParameterError


def test_cost_values_and_translation() -> None:
    assert (cv.FREE_SPACE, cv.MAX_NON_OBSTACLE, cv.INSCRIBED_INFLATED_OBSTACLE,
            cv.LETHAL_OBSTACLE, cv.NO_INFORMATION) == (0, 252, 253, 254, 255)
    t = cv.COST_TO_OCCUPANCY
    assert (t[0], t[1], t[252], t[253], t[254], t[255]) == (0, 1, 98, 99, 100, -1)
    assert t[128] == 1 + (97 * 127) // 251


def test_inflation_cost_formula() -> None:
    assert inflation_cost(0, 0.05, 0.2, 3.0) == 254
    assert inflation_cost(4, 0.05, 0.2, 3.0) == 253  # 0.20 m <= inscribed
    # 0.3 m from the obstacle: floor(252 * exp(-3 * 0.1)) = floor(186.68) = 186
    assert inflation_cost(6, 0.05, 0.2, 3.0) == 186
    assert inflation_cost(6, 0.05, 0.2, 3.0) == int(252 * math.exp(-3.0 * (0.3 - 0.2)))


def test_inflation_profile_matches_nav2_formula() -> None:
    occ = np.zeros((80, 80), dtype=np.int8)
    occ[40, 40] = 100
    cm = make_costmap(occ, robot_radius=0.2, inflation_radius=0.55, cost_scaling_factor=3.0)
    insc = cm.inscribed_radius
    r_cells = math.ceil(0.55 / 0.05)
    jj, ii = np.mgrid[0:80, 0:80]
    d = np.hypot(ii - 40, jj - 40)
    expected = np.zeros((80, 80), dtype=np.int64)
    for j in range(80):
        for i in range(80):
            if d[j, i] <= r_cells:
                expected[j, i] = inflation_cost(d[j, i], 0.05, insc, 3.0)
    assert np.array_equal(cm.master.data.astype(np.int64), expected)
    # Monotonic decay along a ray, truncated integer costs.
    row = cm.master.data[40, 40:40 + r_cells + 2].astype(int)
    assert row[0] == 254 and all(a >= b for a, b in zip(row, row[1:]))
    assert row[-1] == 0


def test_inflation_never_lowers_and_nearest_obstacle_wins() -> None:
    occ = np.zeros((60, 60), dtype=np.int8)
    occ[30, 20] = 100
    occ[30, 26] = 100
    cm = make_costmap(occ, robot_radius=0.1, inflation_radius=0.5)
    # Cell midway (3 cells from each): cost of distance 3.
    assert cm.master.data[30, 23] == inflation_cost(3, 0.05, cm.inscribed_radius, 3.0)


def test_static_layer_interpretation() -> None:
    data = np.array([[-1, 0, 50, 99, 100]], dtype=np.int8)
    tri = interpret_static_value(data, track_unknown_space=True, lethal_cost_threshold=100,
                                 unknown_cost_value=255, trinary_costmap=True)
    assert tri.tolist() == [[255, 0, 0, 0, 254]]
    no_unknown = interpret_static_value(data, track_unknown_space=False, lethal_cost_threshold=100,
                                        unknown_cost_value=255, trinary_costmap=True)
    assert no_unknown.tolist() == [[0, 0, 0, 0, 254]]
    scaled = interpret_static_value(data, track_unknown_space=True, lethal_cost_threshold=50,
                                    unknown_cost_value=255, trinary_costmap=False)
    assert scaled.tolist() == [[255, 0, 254, 254, 254]]


def test_global_costmap_resizes_to_map_and_tracks_unknown() -> None:
    occ = np.zeros((40, 60), dtype=np.int8)
    occ[:, :10] = -1
    cm = make_costmap(occ, track_unknown_space=True, inflation_radius=0.0)
    assert (cm.master.size_x, cm.master.size_y) == (60, 40)
    assert cm.master.data[5, 5] == 255 and cm.master.data[5, 30] == 0


def _local(**over):
    params = {
        "rolling_window": True, "width": 5, "height": 5, "resolution": 0.05,
        "robot_radius": 0.2, "footprint_padding": 0.0,
        "plugins": ["obstacle_layer", "inflation_layer"],
        "obstacle_layer": {
            "plugin": "nav2_costmap_2d::ObstacleLayer", "observation_sources": "scan points",
            "scan": {"clearing": True, "marking": True, "obstacle_max_range": 4.0,
                     "raytrace_max_range": 5.0, "max_obstacle_height": 1.0},
            "points": {"data_type": "PointCloud2", "clearing": False, "marking": True,
                       "min_obstacle_height": 0.05, "max_obstacle_height": 0.7},
        },
        "inflation_layer": {"inflation_radius": 0.3, "cost_scaling_factor": 3.0},
    }
    params.update(over)
    return build_costmap(params, "local_costmap")


def test_obstacle_marking_and_raytrace_clearing() -> None:
    cm = _local()
    ol = cm.layer("obstacle_layer")
    n = 640  # a Kinect-wide scan: rays dense enough to sweep every cell they pass
    fov = math.radians(57.0)
    ol.add_observation("scan", scan_observation(np.full(n, 2.0), -fov / 2, fov / (n - 1), 0.45,
                                                10.0, (0.0, 0.0, 0.6, 0.0)))
    cm.update_map((0.0, 0.0, 0.0))
    m = cm.master
    hit = m.world_to_map(2.0, 0.0)
    assert hit is not None and m.get_cost(*hit) == 254
    mid = m.world_to_map(1.0, 0.0)
    assert mid is not None and m.get_cost(*mid) == 0
    # The obstacle leaves: a longer reading clears the old cell by ray tracing.
    ol.add_observation("scan", scan_observation(np.full(n, 2.4), -fov / 2, fov / (n - 1), 0.45,
                                                10.0, (0.0, 0.0, 0.6, 0.0)))
    cm.update_map((0.0, 0.0, 0.0))
    assert m.get_cost(*hit) == 0
    far = m.world_to_map(2.4, 0.0)
    assert far is not None and m.get_cost(*far) == 254


def test_obstacle_ranges_gate_marking() -> None:
    cm = _local()
    ol = cm.layer("obstacle_layer")
    ol.add_observation("scan", scan_observation(np.array([2.4]), 0.0, 0.1, 0.1, 10.0,
                                                (0.0, 0.0, 0.0, math.pi / 2)))
    cm.update_map((0.0, 0.0, 0.0))
    assert cm.master.get_cost(*cm.master.world_to_map(0.0, 2.4)) == 254
    cm2 = _local(obstacle_layer={
        "plugin": "nav2_costmap_2d::ObstacleLayer", "observation_sources": "scan",
        "scan": {"clearing": True, "marking": True, "obstacle_max_range": 2.0}})
    ol2 = cm2.layer("obstacle_layer")
    ol2.add_observation("scan", scan_observation(np.array([2.4]), 0.0, 0.1, 0.1, 10.0,
                                                 (0.0, 0.0, 0.0, math.pi / 2)))
    cm2.update_map((0.0, 0.0, 0.0))
    assert cm2.master.get_cost(*cm2.master.world_to_map(0.0, 2.4)) == 0


def test_cloud_heights_mark_tables_the_scan_misses() -> None:
    cm = _local()
    ol = cm.layer("obstacle_layer")
    pts = np.array([[1.0, 0.5, 0.4],    # table top: marked
                    [1.0, -0.5, 1.5],   # above the robot: ignored
                    [1.0, -1.0, 0.01]])  # floor: ignored
    ol.add_observation("points", cloud_observation(pts, (0.0, 0.0, 0.6)))
    cm.update_map((0.0, 0.0, 0.0))
    m = cm.master
    assert m.get_cost(*m.world_to_map(1.0, 0.5)) == 254
    assert m.get_cost(*m.world_to_map(1.0, -0.5)) < 253
    assert m.get_cost(*m.world_to_map(1.0, -1.0)) < 253


def test_rolling_window_follows_robot() -> None:
    cm = _local()
    ol = cm.layer("obstacle_layer")
    ol.add_observation("scan", scan_observation(np.array([1.0]), 0.0, 0.1, 0.1, 10.0,
                                                (0.0, 0.0, 0.0, 0.0)))
    cm.update_map((0.0, 0.0, 0.0))
    o1 = (cm.master.origin_x, cm.master.origin_y)
    assert o1[0] == pytest.approx(-cm.master.size_in_meters_x / 2)
    cm.update_map((1.0, 0.5, 0.0))
    assert cm.master.origin_x == pytest.approx(o1[0] + 1.0, abs=0.051)
    assert cm.master.origin_y == pytest.approx(o1[1] + 0.5, abs=0.051)
    # The obstacle stays where it is in the world.
    assert cm.master.get_cost(*cm.master.world_to_map(1.0, 0.0)) == 254


def test_range_layer_marks_at_range_and_clears_inside() -> None:
    cm = build_costmap({"rolling_window": True, "width": 4, "height": 4, "resolution": 0.05,
                        "plugins": ["range_layer"],
                        "range_layer": {"plugin": "nav2_costmap_2d::RangeSensorLayer",
                                        "clear_on_max_reading": True,
                                        "sensor_model": "deterministic"}}, "local")
    rl = cm.layer("range_layer")
    cm.update_map((0.0, 0.0, 0.0))
    rl.costmap.data[:] = 254  # pretend stale marks everywhere
    rl.add_reading(RangeReading((0.0, 0.0, 0.0), 0.5, 0.02, 3.0, 1.0))
    cm.update_map((0.0, 0.0, 0.0))
    m = cm.master
    assert m.get_cost(*m.world_to_map(1.0, 0.0)) == 254
    assert m.get_cost(*m.world_to_map(0.5, 0.0)) == 0
    assert m.get_cost(*m.world_to_map(0.5, 0.1)) == 0  # inside the 0.5 rad cone
    assert rl.costmap.get_cost(*m.world_to_map(0.5, 0.6)) == 254  # outside the cone: untouched
    rl.add_reading(RangeReading((0.0, 0.0, 0.0), 0.5, 0.02, 3.0, 3.0))  # max reading clears
    cm.update_map((0.0, 0.0, 0.0))
    assert m.get_cost(*m.world_to_map(1.0, 0.0)) == 0


def test_keepout_and_speed_filters() -> None:
    occ = np.zeros((40, 40), dtype=np.int8)
    cm = build_costmap({"resolution": 0.05, "robot_radius": 0.1,
                        "plugins": ["static_layer"], "filters": ["keepout", "speed"],
                        "keepout": {"plugin": "nav2_costmap_2d::KeepoutFilter"},
                        "speed": {"plugin": "nav2_costmap_2d::SpeedFilter"}}, "global")
    cm.set_static_map(OccupancyMap(occ, 0.05))
    mask = np.full((40, 40), -1, dtype=np.int8)
    mask[10:20, 10:20] = 100
    mask[0:5, 0:5] = 0
    cm.layer("keepout").set_mask(OccupancyMap(mask, 0.05))
    speed = np.zeros((40, 40), dtype=np.int8)
    speed[30:, 30:] = 40
    cm.layer("speed").set_mask(OccupancyMap(speed, 0.05), CostmapFilterInfo(SPEED_FILTER_PERCENT, 0.0, 1.0))
    cm.update_map((0.1, 0.1, 0.0))
    assert cm.master.data[15, 15] == 254 and cm.master.data[25, 25] == 0
    assert cm.speed_limit_changes() == []
    cm.update_map((1.8, 1.8, 0.0))
    (limit,) = cm.speed_limit_changes()
    assert limit.percentage and limit.speed_limit == pytest.approx(40.0)
    cm.update_map((0.1, 0.1, 0.0))
    (limit,) = cm.speed_limit_changes()
    assert limit.speed_limit == 0.0  # NO_SPEED_LIMIT


def test_clear_operations() -> None:
    cm = _local()
    ol = cm.layer("obstacle_layer")
    ol.add_observation("scan", scan_observation(np.array([1.0, 2.0]), 0.0, math.pi / 2, 0.1,
                                                10.0, (0.0, 0.0, 0.0, 0.0)))
    cm.update_map((0.0, 0.0, 0.0))
    near, far = cm.master.world_to_map(1.0, 0.0), cm.master.world_to_map(0.0, 2.0)
    assert cm.master.get_cost(*near) == 254 and cm.master.get_cost(*far) == 254
    ol._buffers.clear()  # no new data: only clearing changes the map
    cm.clear_around_robot((0.0, 0.0, 0.0), 3.0)
    cm.update_map((0.0, 0.0, 0.0))
    assert cm.master.get_cost(*near) == 0 and cm.master.get_cost(*far) == 254
    cm.clear_except_region((0.0, 0.0, 0.0), 3.0)
    cm.update_map((0.0, 0.0, 0.0))
    assert cm.master.get_cost(*far) == 0
    cm.clear_entirely()
    cm.update_map((0.0, 0.0, 0.0))
    assert int(cm.master.data.max()) == 0


def test_occupancy_grid_message() -> None:
    occ = np.zeros((20, 30), dtype=np.int8)
    occ[10, 10] = 100
    cm = make_costmap(occ, inflation_radius=0.0)
    msg = to_occupancy_grid(cm.master, "map", 1_500_000_000)
    assert (msg.info.width, msg.info.height) == (30, 20)
    assert msg.header.stamp.sec == 1 and msg.header.stamp.nanosec == 500_000_000
    assert msg.data.dtype == np.int8 and msg.data[10 * 30 + 10] == 100
    assert msg.info.origin.orientation.w == 1.0


def test_bad_parameters_are_named() -> None:
    with pytest.raises(ParameterError) as exc:
        build_costmap({"resolution": -1.0}, "global_costmap")
    assert exc.value.server == "global_costmap" and exc.value.key == "resolution"
    with pytest.raises(ParameterError) as exc:
        build_costmap({"plugins": ["x"], "x": {"plugin": "nav2_costmap_2d::Nope"}}, "local")
    assert exc.value.key == "x.plugin"
    with pytest.raises(ParameterError) as exc:
        build_costmap({"plugins": ["inflation_layer"],
                       "inflation_layer": {"inflation_radius": "far"}}, "local")
    assert exc.value.key == "inflation_radius" and exc.value.value == "far"


def test_inflation_unknown_rules() -> None:
    occ = np.full((40, 40), -1, dtype=np.int8)
    occ[:, :20] = 0
    occ[20, 10] = 100
    base = {"resolution": 0.05, "robot_radius": 0.1, "footprint_padding": 0.0,
            "track_unknown_space": True, "plugins": ["static_layer", "inflation_layer"]}
    cm = build_costmap({**base, "inflation_layer": {"inflation_radius": 0.6}}, "g")
    cm.set_static_map(OccupancyMap(occ, 0.05))
    cm.update_map((0.0, 0.0, 0.0))
    # Unknown cells keep 255 unless the inflated cost is inscribed or lethal.
    assert cm.master.data[20, 21] == 255
    assert cm.master.data[20, 11] == 253
    cm2 = build_costmap({**base, "inflation_layer": {"inflation_radius": 0.6,
                                                     "inflate_unknown": True}}, "g")
    cm2.set_static_map(OccupancyMap(occ, 0.05))
    cm2.update_map((0.0, 0.0, 0.0))
    assert cm2.master.data[20, 21] == inflation_cost(11, 0.05, cm2.inscribed_radius, 10.0)
    cm3 = build_costmap({**base, "inflation_layer": {"inflation_radius": 0.2,
                                                     "inflate_around_unknown": True}}, "g")
    cm3.set_static_map(OccupancyMap(occ, 0.05))
    cm3.update_map((0.0, 0.0, 0.0))
    assert cm3.master.data[5, 19] == 253  # next to the unknown half


def test_static_layer_in_rolling_window() -> None:
    occ = np.zeros((100, 100), dtype=np.int8)
    occ[50, 60] = 100  # world (3.025, 2.525)
    cm = build_costmap({"rolling_window": True, "width": 2, "height": 2, "resolution": 0.05,
                        "plugins": ["static_layer"]}, "local")
    cm.set_static_map(OccupancyMap(occ, 0.05))
    cm.update_map((2.5, 2.5, 0.0))
    m = cm.master
    assert m.get_cost(*m.world_to_map(3.025, 2.525)) == 254
    assert int(m.data.sum()) == 254
