"""The range node: raw ADC and PING → sensor_msgs/Range with REP-117's ±inf."""

from __future__ import annotations

import math

import numpy as np
import pytest

from eddiebot.base.range_node import RangeNode
from eddiebot.core import Context, Node, SingleThreadedExecutor
from eddiebot.msgs.eddiebot_msgs import ADC, Ping
from eddiebot.msgs.sensor_msgs import Range
from eddiebot.robot.constants import (
    ADC_COUNTS_PER_VOLT,
    PING_METRES_PER_UNIT,
    sharp_distance_to_voltage,
)


@pytest.fixture
def graph():
    ctx = Context(use_sim_time=True)
    node = RangeNode(context=ctx)
    probe = Node("probe", context=ctx)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    ex.add_node(probe)
    got: dict[str, list[float]] = {}
    for topic in ("/eddie/ir/left", "/eddie/ir/center", "/eddie/ir/right",
                  "/eddie/ping/left", "/eddie/ping/right"):
        got[topic] = []
        probe.create_subscription(Range, topic, lambda m, t=topic: got[t].append(float(m.range)), 10)
    yield ex, probe, got
    ctx.shutdown()


def _counts(volts: float) -> int:
    return round(volts * ADC_COUNTS_PER_VOLT)


def test_ir_too_close_is_minus_inf_and_nothing_is_plus_inf(graph):
    ex, probe, got = graph
    adc = probe.create_publisher(ADC, "/eddie/adc_data", 10)
    # left: 3.0 V, above the 10 cm end (2.30 V); centre: 0.30 m; right: 0.2 V, below 80 cm
    counts = [_counts(3.0), _counts(sharp_distance_to_voltage(0.30)), _counts(0.2), 0, 0, 0, 0,
              _counts(12.0 / 3.21)]
    adc.publish(ADC(status="SUCCESS", value=np.asarray(counts, dtype=np.uint16)))
    ex.spin_until_idle()
    assert got["/eddie/ir/left"] == [-math.inf]
    assert got["/eddie/ir/center"][0] == pytest.approx(0.30, abs=0.005)
    assert got["/eddie/ir/right"] == [math.inf]


def test_ping_zero_is_plus_inf(graph):
    ex, probe, got = graph
    ping = probe.create_publisher(Ping, "/eddie/ping_data", 10)
    ping.publish(Ping(status="SUCCESS", value=np.asarray([0, 500], dtype=np.uint16)))
    ex.spin_until_idle()
    assert got["/eddie/ping/left"] == [math.inf]
    assert got["/eddie/ping/right"] == [pytest.approx(500 * PING_METRES_PER_UNIT)]
