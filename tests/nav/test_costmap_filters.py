"""Costmap filters' cores: keepout costs (also through a frame transform and with the lethal
override), speed limits in percent and m/s, the binary state, the parameter names, and
switching filters on and off (``toggle_filter``)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from eddiebot.maps import OccupancyMap
from eddiebot.nav.cost_values import LETHAL_OBSTACLE, NO_INFORMATION
from eddiebot.nav.costmap import build_costmap
from eddiebot.nav.costmap.filters import (
    BINARY_FILTER,
    KEEPOUT_FILTER,
    NO_SPEED_LIMIT,
    SPEED_FILTER_ABSOLUTE,
    SPEED_FILTER_PERCENT,
    BinaryFilter,
    CostmapFilterInfo,
    KeepoutFilter,
    SpeedFilter,
    SpeedLimit,
)
from eddiebot.nav.errors import ParameterError

RES = 0.05


def _costmap(filters: dict[str, dict], **extra):
    params = {"resolution": RES, "width": 4, "height": 4, "robot_radius": 0.1,
              "plugins": [], "filters": list(filters), **filters, **extra}
    return build_costmap(params, "global_costmap")


def _mask(value: int, box: tuple[int, int, int, int], shape=(80, 80), fill=0,
          origin=(0.0, 0.0, 0.0)) -> OccupancyMap:
    data = np.full(shape, fill, dtype=np.int8)
    x0, y0, x1, y1 = box
    data[y0:y1, x0:x1] = value
    return OccupancyMap(data, RES, origin, "map")


def test_keepout_cells_are_lethal_and_never_lower_costs() -> None:
    cm = _costmap({"keepout": {"plugin": "nav2_costmap_2d::KeepoutFilter"}},
                  plugins=["static_layer"])
    static = np.zeros((80, 80), dtype=np.int8)
    static[52, 12] = static[62, 62] = 100  # obstacles under a half-cost and an unknown cell
    cm.set_static_map(OccupancyMap(static, RES))
    f = cm.layer("keepout")
    assert isinstance(f, KeepoutFilter)
    mask = np.zeros((80, 80), dtype=np.int8)
    mask[20:30, 40:50] = 100   # x 2.0..2.5, y 1.0..1.5
    mask[50:55, 10:15] = 50    # half-cost zone: round(50 * 254 / 100) = 127
    mask[60:65, 60:65] = -1    # unknown in the mask: writes nothing
    f.set_mask(OccupancyMap(mask, RES))
    cm.update_map((0.5, 0.5, 0.0))
    d = cm.master.data
    assert (d[20:30, 40:50] == LETHAL_OBSTACLE).all()
    assert d[51, 11] == 127 and d[52, 12] == LETHAL_OBSTACLE  # never lowered
    assert d[62, 62] == LETHAL_OBSTACLE and d[61, 61] == 0
    assert int((d == LETHAL_OBSTACLE).sum()) == 102
    assert int((d == 127).sum()) == 24


def test_keepout_mask_in_another_frame() -> None:
    # a rolling odom-frame costmap; the mask (square x 2.0..2.5, y 1.0..1.5) is in the map
    # frame, odom sits at (1, 0) turned 90 degrees in it: every lethal cell, taken back to
    # the map frame, lies in the square
    cm = _costmap({"keepout": {"plugin": "nav2_costmap_2d::KeepoutFilter"}},
                  global_frame="odom", rolling_window=True)
    f = cm.layer("keepout")
    f.set_mask(_mask(100, (40, 20, 50, 30)))
    mo = (1.0, 0.0, math.pi / 2)  # odom's pose in map
    c, s = math.cos(mo[2]), math.sin(mo[2])
    # global (odom) -> mask (map): p_map = R p_odom + t
    f.set_mask_transform(mo)
    cm.update_map((1.0, -1.0, 0.0))
    m = cm.master
    jj, ii = np.nonzero(m.data == LETHAL_OBSTACLE)
    ox = m.origin_x + (ii + 0.5) * RES
    oy = m.origin_y + (jj + 0.5) * RES
    mx, my = mo[0] + c * ox - s * oy, mo[1] + s * ox + c * oy
    assert len(ii) == 100
    assert (mx > 2.0 - 1e-6).all() and (mx < 2.5 + 1e-6).all()
    assert (my > 1.0 - 1e-6).all() and (my < 1.5 + 1e-6).all()
    # an unknown transform: the filter sits the update out
    f.set_mask_transform(None, ok=False)
    cm.clear_entirely()
    cm.update_map((1.0, -1.0, 0.0))
    assert not (cm.master.data == LETHAL_OBSTACLE).any()


def test_keepout_override_lets_a_robot_inside_the_zone_out() -> None:
    cm = _costmap({"keepout": {"plugin": "nav2_costmap_2d::KeepoutFilter",
                               "override_lethal_cost": True, "lethal_override_cost": 200}})
    cm.layer("keepout").set_mask(_mask(100, (20, 20, 40, 40)))
    cm.update_map((0.2, 0.2, 0.0))
    assert cm.master.data[30, 30] == LETHAL_OBSTACLE
    cm.update_map((1.5, 1.5, 0.0))  # inside the zone
    assert cm.master.data[30, 30] == 200
    cm.update_map((0.2, 0.2, 0.0))  # out again: lethal once more
    assert cm.master.data[30, 30] == LETHAL_OBSTACLE


def test_keepout_override_cost_is_clamped_below_lethal() -> None:
    cm = _costmap({"keepout": {"plugin": "nav2_costmap_2d::KeepoutFilter",
                               "override_lethal_cost": True, "lethal_override_cost": 300}})
    assert cm.layer("keepout").lethal_override_cost == 252


@pytest.mark.parametrize(("kind", "base", "multiplier", "value", "expected"), [
    (SPEED_FILTER_PERCENT, 100.0, -1.0, 40, SpeedLimit(True, 60.0)),
    (SPEED_FILTER_PERCENT, 0.0, 1.0, 30, SpeedLimit(True, 30.0)),
    (SPEED_FILTER_ABSOLUTE, 0.0, 0.005, 40, SpeedLimit(False, 0.2)),
    (SPEED_FILTER_ABSOLUTE, 0.1, 0.001, 50, SpeedLimit(False, 0.15)),
])
def test_speed_limit_from_the_mask(kind: int, base: float, multiplier: float, value: int,
                                   expected: SpeedLimit) -> None:
    f = SpeedFilter()
    f.set_mask(_mask(value, (40, 40, 80, 80)), CostmapFilterInfo(kind, base, multiplier))
    assert f.update(1.0, 1.0) is None  # mask 0 under the robot: no limit, which is current
    got = f.update(3.0, 3.0)
    assert got is not None and got.percentage == expected.percentage
    assert got.speed_limit == pytest.approx(expected.speed_limit)
    assert f.update(3.5, 3.5) is None  # unchanged: nothing new to publish
    assert f.update(1.0, 1.0) == SpeedLimit(expected.percentage, NO_SPEED_LIMIT)


def test_speed_limit_out_of_range_unknown_and_outside() -> None:
    f = SpeedFilter()
    mask = _mask(50, (0, 0, 40, 80))
    data = mask.data.copy()
    data[:, 60:] = -1
    f.set_mask(OccupancyMap(data, RES), CostmapFilterInfo(SPEED_FILTER_PERCENT, 80.0, 1.0))
    assert f.update(1.0, 1.0) is None  # 130 % is out of bounds: no limit (already none)
    f.set_filter_info(CostmapFilterInfo(SPEED_FILTER_PERCENT, 10.0, 1.0))
    assert f.update(1.0, 1.0) == SpeedLimit(True, 60.0)
    assert f.update(3.5, 1.0) is None  # unknown cell: the limit stays
    assert f.update(9.0, 1.0) is None  # outside the mask: the limit stays
    assert f.speed_limit == pytest.approx(60.0)


def test_speed_filter_refuses_other_info_types() -> None:
    f = SpeedFilter()
    problem = f.set_filter_info(CostmapFilterInfo(KEEPOUT_FILTER))
    assert "type 0 is not supported" in problem and "1 or 2" in problem
    assert f.info.type == SPEED_FILTER_PERCENT


def test_binary_state_flips_in_and_out() -> None:
    cm = _costmap({"binary": {"plugin": "nav2_costmap_2d::BinaryFilter",
                              "flip_threshold": 40.0, "default_state": False}})
    f = cm.layer("binary")
    assert isinstance(f, BinaryFilter) and f.pending == [False]
    f.pending.clear()
    data = np.zeros((40, 40), dtype=np.int8)
    data[10:20, 10:20] = 100
    data[10:20, 25:30] = 30  # below the threshold
    f.set_mask(OccupancyMap(data, RES), CostmapFilterInfo(BINARY_FILTER, 0.0, 1.0))
    for x in (0.2, 0.6, 0.8, 1.3, 1.5, 3.0, 0.7):
        cm.update_map((x, 0.7, 0.0))
    # in at 0.6 -> True; 0.8 stays; 1.3 (value 30) -> False; 1.5 no change; 3.0 outside the
    # mask -> default (already); 0.7 -> True
    assert f.pending == [True, False, True]
    assert f.state is True


def test_binary_filter_base_multiplier_and_default_true() -> None:
    f = BinaryFilter(config=BinaryFilter.config_class(default_state=True, flip_threshold=50.0))
    f.pending.clear()
    # base + multiplier * v = 100 - v: low values flip it
    f.set_mask(_mask(80, (0, 0, 40, 80)), CostmapFilterInfo(BINARY_FILTER, 100.0, -1.0))
    f.update(1.0, 1.0)   # 100 - 80 = 20: not over the threshold -> default (no change)
    f.update(3.0, 1.0)   # mask 0: 100 > 50 -> flipped to False
    f.update(10.0, 1.0)  # outside: back to the default True
    assert f.pending == [False, True]
    assert "type 1 is not supported" in f.set_filter_info(CostmapFilterInfo(SPEED_FILTER_PERCENT))


def test_filter_parameters_use_nav2_names() -> None:
    cm = _costmap({"speed": {"plugin": "nav2_costmap_2d::SpeedFilter",
                             "filter_info_topic": "/speed_info", "speed_limit_topic": "/limit"},
                   "binary": {"plugin": "nav2_costmap_2d::BinaryFilter",
                              "binary_state_topic": "/camera_on", "flip_threshold": 20.0}})
    assert cm.layer("speed").config.speed_limit_topic == "/limit"
    assert cm.layer("speed").config.filter_info_topic == "/speed_info"
    assert cm.layer("binary").config.binary_state_topic == "/camera_on"
    with pytest.raises(ParameterError) as exc:
        _costmap({"keepout": {"plugin": "nav2_costmap_2d::KeepoutFilter",
                              "override_lethal_cost": "yes please"}})
    assert "override_lethal_cost" in str(exc.value)


def test_unknown_master_cells_take_the_mask() -> None:
    cm = _costmap({"keepout": {"plugin": "nav2_costmap_2d::KeepoutFilter"}},
                  track_unknown_space=True)
    cm.layer("keepout").set_mask(_mask(0, (0, 0, 1, 1), fill=0))
    cm.update_map((0.5, 0.5, 0.0))
    # Nav2's rule: a known mask value replaces NO_INFORMATION in the master
    assert int((cm.master.data == NO_INFORMATION).sum()) == 0


# --- toggle_filter -------------------------------------------------------------------------------
def test_keepout_switched_off_clears_the_zone_and_on_paints_it_again() -> None:
    cm = _costmap({"keepout": {"plugin": "nav2_costmap_2d::KeepoutFilter"}},
                  plugins=["static_layer"])
    static = np.zeros((80, 80), dtype=np.int8)
    static[25, 45] = 100  # a map obstacle inside the zone stays lethal throughout
    cm.set_static_map(OccupancyMap(static, RES))
    f = cm.layer("keepout")
    assert isinstance(f, KeepoutFilter)
    f.set_mask(_mask(100, (40, 20, 50, 30)))  # x 2.0..2.5, y 1.0..1.5
    cm.update_map((0.5, 0.5, 0.0))
    d = cm.master.data
    assert int((d[20:30, 40:50] == LETHAL_OBSTACLE).sum()) == 100
    assert f.set_enabled(False) == "Disabled" and not f.filter_enabled
    cm.update_map((0.5, 0.5, 0.0))
    d = cm.master.data
    assert int((d == LETHAL_OBSTACLE).sum()) == 1 and d[25, 45] == LETHAL_OBSTACLE
    # switched off it sits the updates out; a new mask meanwhile draws nothing
    f.set_mask(_mask(100, (0, 0, 10, 10)))
    cm.update_map((0.5, 0.5, 0.0))
    assert int((cm.master.data == LETHAL_OBSTACLE).sum()) == 1
    assert f.set_enabled(True) == "Enabled" and f.filter_enabled
    cm.update_map((0.5, 0.5, 0.0))
    d = cm.master.data
    assert int((d == LETHAL_OBSTACLE).sum()) == 101 and (d[0:10, 0:10] == LETHAL_OBSTACLE).all()
    # the same request twice changes nothing
    assert f.set_enabled(True) == "Enabled"
    cm.update_map((0.5, 0.5, 0.0))
    assert int((cm.master.data == LETHAL_OBSTACLE).sum()) == 101


def test_keepout_configured_off_draws_nothing_until_switched_on() -> None:
    cm = _costmap({"keepout": {"plugin": "nav2_costmap_2d::KeepoutFilter", "enabled": False}})
    f = cm.layer("keepout")
    assert isinstance(f, KeepoutFilter) and not f.filter_enabled
    f.set_mask(_mask(100, (40, 20, 50, 30)))
    cm.update_map((0.5, 0.5, 0.0))
    assert int((cm.master.data == LETHAL_OBSTACLE).sum()) == 0
    f.set_enabled(True)
    cm.update_map((0.5, 0.5, 0.0))
    assert int((cm.master.data == LETHAL_OBSTACLE).sum()) == 100


def test_speed_and_binary_filters_switched_off_read_nothing() -> None:
    cm = _costmap({"speed": {"plugin": "nav2_costmap_2d::SpeedFilter"},
                   "binary": {"plugin": "nav2_costmap_2d::BinaryFilter"}})
    speed, binary = cm.layer("speed"), cm.layer("binary")
    assert isinstance(speed, SpeedFilter) and isinstance(binary, BinaryFilter)
    binary.pending.clear()
    speed.set_mask(_mask(40, (0, 0, 40, 80)), CostmapFilterInfo(SPEED_FILTER_PERCENT, 0.0, 1.0))
    binary.set_mask(_mask(100, (0, 0, 40, 80)), CostmapFilterInfo(BINARY_FILTER, 0.0, 1.0))
    cm.update_map((1.0, 1.0, 0.0))  # in both zones: 40 %, state flipped
    assert cm.speed_limit_changes() == [SpeedLimit(True, 40.0)] and binary.pending == [True]
    binary.pending.clear()
    assert speed.set_enabled(False) == "Disabled" and binary.set_enabled(False) == "Disabled"
    cm.update_map((3.0, 1.0, 0.0))  # out of both zones, but switched off: nothing changes
    assert cm.speed_limit_changes() == [] and binary.pending == [] and binary.state is True
    assert speed.speed_limit == 40.0
    speed.set_enabled(True)
    binary.set_enabled(True)
    cm.update_map((3.0, 1.0, 0.0))
    assert cm.speed_limit_changes() == [SpeedLimit(True, NO_SPEED_LIMIT)]
    assert binary.pending == [False]
