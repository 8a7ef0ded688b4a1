"""The twist mux tells, once, which source holds it while another's commands are dropped."""

from __future__ import annotations

import logging

import pytest

from eddiebot.base.twist_mux import TwistMuxNode
from eddiebot.core import Context, Node, SingleThreadedExecutor
from eddiebot.msgs.geometry_msgs import Twist


@pytest.fixture
def mux():
    ctx = Context(use_sim_time=True)
    node = TwistMuxNode(context=ctx)
    probe = Node("probe", context=ctx)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    ex.add_node(probe)
    out: list[Twist] = []
    probe.create_subscription(Twist, "/cmd_vel", out.append, 100)
    yield ex, probe, node, out
    ctx.shutdown()


def _send(ex, pub, seconds, vx, rate=20.0):
    for _ in range(round(seconds * rate)):
        msg = Twist()
        msg.linear.x = vx
        pub.publish(msg)
        ex.spin_for(1.0 / rate)


def _override_lines(caplog):
    return [r.getMessage() for r in caplog.records if "overridden by" in r.getMessage()]


def test_override_is_logged_once_and_again_after_navigation_drove(mux, caplog):
    ex, probe, node, out = mux
    caplog.set_level(logging.INFO)
    nav = probe.create_publisher(Twist, "/cmd_vel_safe", 10)
    teleop = probe.create_publisher(Twist, "/cmd_vel_teleop", 10)
    _send(ex, teleop, 0.1, 0.0)  # teleop holds the mux (its zero, as an idle teleop sends)
    _send(ex, nav, 0.3, 0.2)  # navigation keeps sending within teleop's timeout
    lines = _override_lines(caplog)
    assert len(lines) == 1, lines
    assert lines[0].startswith("navigation (cmd_vel_safe) overridden by teleop (cmd_vel_teleop")
    assert all(m.linear.x == 0.0 for m in out)  # nothing of navigation's got through
    _send(ex, nav, 1.0, 0.2)  # teleop quiet for longer than its timeout: navigation drives
    assert out[-1].linear.x == pytest.approx(0.2)
    assert len(_override_lines(caplog)) == 1
    _send(ex, teleop, 0.05, 0.0)
    _send(ex, nav, 0.2, 0.2)
    assert len(_override_lines(caplog)) == 2  # a new episode is told again


def test_navigation_alone_logs_no_override(mux, caplog):
    ex, probe, _node, out = mux
    caplog.set_level(logging.INFO)
    nav = probe.create_publisher(Twist, "/cmd_vel_safe", 10)
    _send(ex, nav, 0.5, 0.2)
    assert out and out[-1].linear.x == pytest.approx(0.2)
    assert _override_lines(caplog) == []
