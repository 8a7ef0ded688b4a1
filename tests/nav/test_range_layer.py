"""Range layer: Nav2's probabilistic RangeSensorLayer model (and the deterministic option)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from eddiebot.nav.costmap import RangeReading, build_costmap
from eddiebot.nav.costmap.layers.range import RangeLayer, RangeLayerConfig, sensor_model
from eddiebot.nav.errors import ParameterError


def _local(**layer: object) -> tuple[object, RangeLayer]:
    cm = build_costmap({"rolling_window": True, "width": 4, "height": 4, "resolution": 0.05,
                        "track_unknown_space": True, "plugins": ["range_layer"],
                        "range_layer": {"plugin": "nav2_costmap_2d::RangeSensorLayer", **layer}},
                       "local")
    rl = cm.layer("range_layer")
    assert isinstance(rl, RangeLayer)
    cm.update_map((0.0, 0.0, 0.0))
    return cm, rl


def _delta(phi: float, phi_v: float = 1.2) -> float:
    return 1.0 - (1.0 + math.tanh(2.0 * (phi - phi_v))) / 2.0


def test_sensor_model_zones() -> None:
    r, half, res = 1.0, 0.25, 0.05
    # clearing zone (phi < r - 2 res r = 0.9): (1 - lambda) / 2, lambda = delta(phi) gamma(theta)
    near = sensor_model(r, [0.5], [0.0], half, 1.2, res)[0]
    assert near == pytest.approx((1.0 - _delta(0.5)) * 0.5)
    assert near == pytest.approx(0.0285, abs=5e-4)
    # half way to the cone's edge gamma = 1 - 0.25
    lam = _delta(0.5) * 0.75
    assert sensor_model(r, [0.5], [0.125], half, 1.2, res)[0] == pytest.approx((1.0 - lam) * 0.5)
    # at the reading: lambda/2 + 1/2 (0.845 at 1 m)
    at = sensor_model(r, [1.0], [0.0], half, 1.2, res)[0]
    assert at == pytest.approx(_delta(1.0) * 0.5 + 0.5)
    assert at == pytest.approx(0.845, abs=1e-3)
    # rising edge r - 2 dr <= phi < r - dr: continuous with the clearing zone at its start
    lo = sensor_model(r, [0.9], [0.0], half, 1.2, res)[0]
    assert lo == pytest.approx((1.0 - _delta(0.9)) * 0.5)
    mid = sensor_model(r, [0.925], [0.0], half, 1.2, res)[0]
    lam = _delta(0.925)
    assert mid == pytest.approx(lam * 0.5 * 0.25 + (1.0 - lam) * 0.5)
    # beyond r + dr and outside the cone: no information (0.5)
    assert sensor_model(r, [1.06, 2.0], [0.0, 0.0], half, 1.2, res) == pytest.approx([0.5, 0.5])
    assert sensor_model(r, [0.5], [0.3], half, 1.2, res)[0] == pytest.approx(0.5)
    # far readings are trusted less: the clearing probability rises towards 0.5
    assert sensor_model(3.0, [2.5], [0.0], half, 1.2, res)[0] > 0.49


def test_reading_marks_the_hit_and_clears_the_cone() -> None:
    cm, rl = _local()
    m = cm.master
    assert rl.costmap.get_cost(*m.world_to_map(1.0, 0.0)) == 127  # prior 0.5
    rl.add_reading(RangeReading((0.0, 0.0, 0.0), 0.5, 0.02, 3.0, 1.0))
    cm.update_map((0.0, 0.0, 0.0))
    hit = m.world_to_map(1.0, 0.0)
    # the hit cell: 233 then Bayes with the band's probability -> above mark_threshold (203)
    assert rl.costmap.get_cost(*hit) > 203
    assert m.get_cost(*hit) == 254
    # inside the cone, in the clearing zone: posterior = sensor = 0.0285 -> cost 7 -> FREE
    near = m.world_to_map(0.5, 0.0)
    assert rl.costmap.get_cost(*near) == int(sensor_model(1.0, [math.hypot(
        *m.map_to_world(*near))], [0.0], 0.25)[0] * 254) or rl.costmap.get_cost(*near) < 10
    assert m.get_cost(*near) == 0
    # outside the cone (but inside the updated box): unchanged prior, unknown in the master
    side = m.world_to_map(0.5, 0.45)
    assert rl.costmap.get_cost(*side) == 127
    assert m.get_cost(*side) == 255
    # beyond the reading: nothing learnt
    assert m.get_cost(*m.world_to_map(1.5, 0.0)) == 255


def test_repeated_readings_accumulate_and_a_far_echo_alone_does_not_mark() -> None:
    cm, rl = _local()
    m = cm.master
    far = m.world_to_map(1.9, 0.0)
    rl.add_reading(RangeReading((0.0, 0.0, 0.0), 0.5, 0.02, 3.0, 1.9))
    cm.update_map((0.0, 0.0, 0.0))
    first = rl.costmap.get_cost(*far)
    # at 1.9 m delta = 0.06: one echo moves the hit cell only from 233 a little
    assert 203 < first < 240
    # a cell in the far band (not the hit cell) stays between the thresholds after one echo
    band = m.world_to_map(1.9, 0.1)
    once = rl.costmap.get_cost(*band)
    assert 127 < once <= 203
    assert m.get_cost(*band) == 255
    for _ in range(20):
        rl.add_reading(RangeReading((0.0, 0.0, 0.0), 0.5, 0.02, 3.0, 1.9))
    cm.update_map((0.0, 0.0, 0.0))
    # ... and is marked once the evidence accumulates (Bayes: odds multiply per echo)
    assert rl.costmap.get_cost(*band) > 203
    assert m.get_cost(*band) == 254
    # the hit cell is set to 233 before every update, as upstream: it does not accumulate
    assert rl.costmap.get_cost(*far) == first


def test_max_reading_clears_the_box_only_with_clear_on_max_reading() -> None:
    for clear in (False, True):
        cm, rl = _local(clear_on_max_reading=clear)
        m = cm.master
        rl.add_reading(RangeReading((0.0, 0.0, 0.0), 0.5, 0.02, 3.0, 1.0))
        cm.update_map((0.0, 0.0, 0.0))
        hit = m.world_to_map(1.0, 0.0)
        assert m.get_cost(*hit) == 254
        rl.add_reading(RangeReading((0.0, 0.0, 0.0), 0.5, 0.02, 1.2, 1.2))  # max range
        cm.update_map((0.0, 0.0, 0.0))
        if clear:  # sensor probability 0 everywhere in the box
            assert rl.costmap.get_cost(*hit) == 0
            assert m.get_cost(*hit) == 0
        else:  # an ordinary reading at 1.2 m: the old hit is in its clearing zone
            assert rl.costmap.get_cost(*hit) < 254
            assert m.get_cost(*m.world_to_map(1.2, 0.0)) == 254


def test_out_of_range_and_fixed_rangers() -> None:
    cm, rl = _local(clear_on_max_reading=True)
    before = rl.costmap.data.copy()
    rl.add_reading(RangeReading((0.0, 0.0, 0.0), 0.5, 0.2, 3.0, 0.1))  # below min_range
    rl.add_reading(RangeReading((0.0, 0.0, 0.0), 0.5, 0.2, 3.0, 3.5))  # above max_range
    rl.add_reading(RangeReading((0.0, 0.0, 0.0), 0.5, 0.2, 3.0, math.nan))
    rl.add_reading(RangeReading((0.0, 0.0, 0.0), 0.1, 0.3, 0.3, 0.25))  # fixed: finite invalid
    cm.update_map((0.0, 0.0, 0.0))
    assert np.array_equal(rl.costmap.data, before)
    m = cm.master
    rl.add_reading(RangeReading((0.0, 0.0, 0.0), 0.1, 0.3, 0.3, -math.inf))  # fixed: object
    cm.update_map((0.0, 0.0, 0.0))
    assert m.get_cost(*m.world_to_map(0.3, 0.0)) == 254
    rl.add_reading(RangeReading((0.0, 0.0, 0.0), 0.1, 0.3, 0.3, math.inf))  # fixed: nothing
    cm.update_map((0.0, 0.0, 0.0))
    assert rl.costmap.get_cost(*m.world_to_map(0.3, 0.0)) == 0


def test_inflate_cone_limits_the_update_to_the_triangle() -> None:
    # a clearing (max-range) reading sets every updated cell to 0, in or out of the cone
    reading = RangeReading((0.0, 0.0, 0.0), 0.5, 0.02, 1.0, 1.0)
    changed = {}
    for inflate in (0.0, 1.0):
        cm, rl = _local(inflate_cone=inflate, clear_on_max_reading=True)
        rl.add_reading(reading)
        cm.update_map((0.0, 0.0, 0.0))
        changed[inflate] = int(np.count_nonzero(rl.costmap.data == 0))
        side = cm.master.world_to_map(0.3, 0.25)  # in the box, outside the triangle
        assert rl.costmap.get_cost(*side) == (0 if inflate == 1.0 else 127)
    # the box of the triangle (1.2 m deep, 0.59 m wide) is 25 x 13 cells, the triangle half
    assert changed[1.0] == pytest.approx(25 * 13, abs=30)
    assert 0.35 * changed[1.0] < changed[0.0] < 0.75 * changed[1.0]


def test_no_readings_timeout_and_reset() -> None:
    cm, rl = _local(no_readings_timeout=1.0)
    rl.set_time(0)
    rl.add_reading(RangeReading((0.0, 0.0, 0.0), 0.5, 0.02, 3.0, 1.0))
    cm.update_map((0.0, 0.0, 0.0))
    assert rl.current
    rl.set_time(900_000_000)
    cm.update_map((0.0, 0.0, 0.0))
    assert rl.current
    rl.set_time(1_100_000_000)  # 1.1 s without a reading
    cm.update_map((0.0, 0.0, 0.0))
    assert not rl.current
    # as upstream, readings alone do not make it current again; a reset does
    rl.add_reading(RangeReading((0.0, 0.0, 0.0), 0.5, 0.02, 3.0, 1.0))
    cm.update_map((0.0, 0.0, 0.0))
    assert not rl.current
    rl.reset()
    assert np.all(rl.costmap.data == 127)
    rl.add_reading(RangeReading((0.0, 0.0, 0.0), 0.5, 0.02, 3.0, 1.0))
    cm.update_map((0.0, 0.0, 0.0))
    assert rl.current


def test_deterministic_option_and_validation() -> None:
    cm, rl = _local(sensor_model="deterministic")
    m = cm.master
    rl.add_reading(RangeReading((0.0, 0.0, 0.0), 0.5, 0.02, 3.0, 1.0))
    cm.update_map((0.0, 0.0, 0.0))
    arc = m.world_to_map(math.cos(0.2), math.sin(0.2))  # on the arc, inside the cone
    assert m.get_cost(*arc) == 254
    with pytest.raises(ParameterError):
        RangeLayer("r", RangeLayerConfig(sensor_model="bayes"))
    with pytest.raises(ParameterError):
        RangeLayer("r", RangeLayerConfig(mark_threshold=1.5))
