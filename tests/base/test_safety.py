"""The range-sensor safety core (VetoState, limit_twist) and the emergency_status node."""

from __future__ import annotations

import math

import pytest

from eddiebot.base.safety import (
    NO_READING_YET,
    SAFETY_VETO_QOS,
    SAFETY_VETO_TOPIC,
    BoardVetoMonitor,
    SafetyConfig,
    SafetyNode,
    VetoState,
    forward_factor,
    limit_twist,
)
from eddiebot.core import Context, Node, SingleThreadedExecutor
from eddiebot.msgs.eddiebot_msgs import GetStatus
from eddiebot.msgs.std_msgs import Bool
from eddiebot.robot.constants import IR_SENSORS, PING_SENSORS

MS = 1_000_000
ALL = sorted(s.name for s in (*IR_SENSORS, *PING_SENSORS))
CLEAR = dict.fromkeys(ALL, math.inf)
#: ir_center sits 0.21 m ahead of the centre, the front edge 0.2245 m: a reading r lies
#: r - 0.0145 m ahead of the front
IR_CENTER_TO_FRONT = 0.2245 - 0.21


def eddie(config: SafetyConfig | None = None) -> VetoState:
    return VetoState.from_config(config or SafetyConfig())


def clear_state(config: SafetyConfig | None = None, samples: int = 2, t0_ns: int = 0) -> VetoState:
    state = eddie(config)
    for i in range(samples):
        state.update(CLEAR, t0_ns + i * 50 * MS)
    return state


# -- config ----------------------------------------------------------------------------------


def test_config_defaults_and_validation():
    c = SafetyConfig()
    assert (c.veto_distance, c.enabled, c.stale_after, c.slowdown_distance,
            c.max_reverse_speed, c.ir_debounce) == (0.25, True, 0.5, 0.5, 0.1, 2)
    for bad in ({"veto_distance": -0.1}, {"stale_after": 0.0}, {"slowdown_distance": -1.0},
                {"max_reverse_speed": -0.1}, {"ir_debounce": 0}, {"veto_distance": math.nan}):
        with pytest.raises(ValueError):
            SafetyConfig(**bad)


# -- unknown is unsafe --------------------------------------------------------------------------


def test_start_up_refuses_forward_motion_until_every_sensor_reported():
    state = eddie()
    assert state.too_close(0) == ALL  # expected, never seen
    assert limit_twist(0.3, 0.0, state, SafetyConfig(), 0) == (0.0, 0.0)
    state.update({"ir_left": math.inf, "ir_center": math.inf, "ir_right": math.inf}, 0)
    assert state.too_close(10 * MS) == ["ping_left", "ping_right"]
    state.update({"ping_left": math.inf, "ping_right": math.inf}, 10 * MS)
    assert state.too_close(20 * MS) == []
    assert state.vetoed_at(20 * MS) is False


def test_a_state_without_expected_sensors_waits_for_any_reading():
    state = VetoState()
    assert state.too_close(0) == [NO_READING_YET]
    assert state.vetoed_at(0)
    assert state.clearance(0) == -math.inf
    state.update({"ping_left": math.nan}, 0)  # NaN is no reading
    assert state.too_close(0) == [NO_READING_YET]
    state.update({"ping_left": 2.0}, 0)
    assert state.too_close(0) == []


def test_a_silent_sensor_goes_stale_after_stale_after():
    state = clear_state()  # last update at 50 ms
    assert state.too_close(550 * MS) == []  # 0.5 s old: still fresh
    assert state.too_close(551 * MS) == ALL
    # only the PING sensors keep reporting: the IR ones are stale
    state.update({"ping_left": 3.0, "ping_right": 3.0}, 600 * MS)
    assert state.too_close(600 * MS) == ["ir_center", "ir_left", "ir_right"]
    config = SafetyConfig(stale_after=2.0)
    state = clear_state(config)
    assert state.too_close(2050 * MS) == []
    assert state.too_close(2051 * MS) == ALL


def test_nan_is_unknown_and_unsafe_only_once_stale():
    state = clear_state()  # everything clear at 0 and 50 ms
    state.update({**CLEAR, "ir_center": math.nan}, 300 * MS)
    assert state.ranges["ir_center"] != state.ranges["ir_center"]  # NaN kept as received
    assert state.too_close(300 * MS) == []  # not at once
    state.update({**CLEAR, "ir_center": math.nan}, 540 * MS)
    assert state.too_close(550 * MS) == []  # the last valid reading is 0.5 s old
    assert state.too_close(560 * MS) == ["ir_center"]


# -- geometry and debouncing ----------------------------------------------------------------------


def test_corridor_geometry_and_clearance():
    state = clear_state()
    state.update({"ir_center": 0.5}, 100 * MS)
    state.update({"ir_center": 0.5}, 150 * MS)
    assert state.clearance(150 * MS) == pytest.approx(0.5 - IR_CENTER_TO_FRONT)
    # a door jamb 0.2 m from each side sensor is beside the robot, not in its path
    state.update({"ir_left": 0.2, "ir_right": 0.2}, 200 * MS)
    state.update({"ir_left": 0.2, "ir_right": 0.2}, 250 * MS)
    assert state.obstacles(250 * MS)["ir_left"] == math.inf
    # PING left (0.195, 0.09) at +22.5°: 0.15 m lands at x 0.334, y 0.147 — in the path
    state.update({"ping_left": 0.15}, 250 * MS)
    expected = 0.195 + 0.15 * math.cos(math.pi / 8) - 0.2245
    assert state.obstacles(250 * MS)["ping_left"] == pytest.approx(expected)
    assert state.too_close(250 * MS) == ["ping_left"]
    assert state.too_close(250 * MS, distance=0.5) == ["ir_center", "ping_left"]


def test_one_ir_spike_does_not_veto_two_in_a_row_do():
    cfg = SafetyConfig()
    state = clear_state()
    t = 100 * MS
    state.update({**CLEAR, "ir_center": 0.2}, t)  # one 1.3 V spike: 0.2 m
    assert state.too_close(t) == []
    assert limit_twist(0.3, 0.0, state, cfg, t) == (0.3, 0.0)
    state.update(CLEAR, t + 50 * MS)
    assert state.too_close(t + 50 * MS) == []
    state.update({**CLEAR, "ir_center": 0.2}, t + 100 * MS)
    assert state.too_close(t + 100 * MS) == []
    state.update({**CLEAR, "ir_center": 0.2}, t + 150 * MS)  # second in a row: real
    assert state.too_close(t + 150 * MS) == ["ir_center"]
    assert limit_twist(0.3, 0.0, state, cfg, t + 150 * MS) == (0.0, 0.0)
    # "too close to measure" is debounced the same way
    state = clear_state()
    state.update({"ir_left": -math.inf}, t)
    assert state.too_close(t) == []
    state.update({"ir_left": -math.inf}, t + 50 * MS)
    assert state.too_close(t + 50 * MS) == ["ir_left"]
    # with ir_debounce 3 two samples are not enough
    state = clear_state(SafetyConfig(ir_debounce=3), samples=3)
    state.update({"ir_center": 0.2}, t)
    state.update({"ir_center": 0.2}, t + 50 * MS)
    assert state.too_close(t + 50 * MS) == []
    state.update({"ir_center": 0.2}, t + 100 * MS)
    assert state.too_close(t + 100 * MS) == ["ir_center"]


def test_ping_is_not_debounced_and_ping_zero_is_clear():
    state = clear_state()
    state.update({"ping_right": 0.15}, 100 * MS)
    assert state.too_close(100 * MS) == ["ping_right"]
    state.update({"ping_right": math.inf}, 150 * MS)  # PING 0: nothing in range
    assert state.too_close(150 * MS) == []


def test_minus_inf_on_an_unmounted_sensor_is_too_close():
    state = VetoState(debounced=frozenset())
    state.update({"bumper": -math.inf}, 0)
    assert state.too_close(0) == ["bumper"]
    state.update({"bumper": 0.3}, 0)
    assert state.too_close(0) == []
    assert state.too_close(0, distance=0.31) == ["bumper"]


# -- limit_twist --------------------------------------------------------------------------------


def _wall(ahead_of_front: float) -> VetoState:
    """Eddie's sensors all clear but the centre IR, which sees a wall this far ahead."""
    state = clear_state()
    r = ahead_of_front + IR_CENTER_TO_FRONT
    state.update({**CLEAR, "ir_center": r}, 100 * MS)
    state.update({**CLEAR, "ir_center": r}, 150 * MS)
    return state


NOW = 150 * MS


def test_clear_path_passes_the_command_unchanged():
    cfg = SafetyConfig()
    state = _wall(math.inf)
    assert limit_twist(0.3, 0.5, state, cfg, NOW) == (0.3, 0.5)
    assert forward_factor(state, cfg, NOW) == 1.0
    assert limit_twist(0.3, 0.5, _wall(0.75), cfg, NOW) == pytest.approx((0.3, 0.5))


def test_slowdown_band_scales_arcs_along_their_curve():
    cfg = SafetyConfig()  # veto 0.25, band 0.5: full speed from 0.75 m
    for ahead, factor in ((0.70, 0.9), (0.50, 0.5), (0.30, 0.1)):
        v, w = limit_twist(0.3, 0.6, _wall(ahead), cfg, NOW)
        assert v == pytest.approx(0.3 * factor)
        assert w == pytest.approx(0.6 * factor)
        assert w / v == pytest.approx(2.0)  # curvature kept: the arc slows, it does not tighten
    band = SafetyConfig(slowdown_distance=1.0)
    assert limit_twist(0.4, 0.0, _wall(0.5), band, NOW)[0] == pytest.approx(0.4 * 0.25)
    no_band = SafetyConfig(slowdown_distance=0.0)
    assert limit_twist(0.4, 0.0, _wall(0.26), no_band, NOW) == (0.4, 0.0)


def _ping_left(r: float) -> VetoState:
    """Eddie's sensors all clear but the left PING (yaw 22.5°), which sees something r m off."""
    state = clear_state()
    state.update({**CLEAR, "ping_left": r}, 100 * MS)
    state.update({**CLEAR, "ping_left": r}, 150 * MS)
    return state


def test_an_arc_is_not_slowed_by_a_jamb_on_the_side_it_turns_away_from():
    # entering a door at an angle (the house, exploring): the left PING sees the jamb
    # 0.34 m off, its axis point 0.22 m left of the centre line, 0.28 m ahead of the front;
    # the controller turns right into the door (0.15 m/s, -0.44 rad/s). Judged on the
    # straight corridor the band held the robot at 7 % of that, for 20-45 s at a time.
    cfg = SafetyConfig()
    state = _ping_left(0.34)
    assert state.clearance(NOW) == pytest.approx(0.195 + 0.34 * math.cos(math.pi / 8) - 0.2245)
    f = forward_factor(state, cfg, NOW)
    assert f == pytest.approx(0.069, abs=0.001)
    assert limit_twist(0.15, -0.44, state, cfg, NOW) == (0.15, -0.44)
    # straight on, or turning towards it, it stays in the way
    assert limit_twist(0.15, 0.0, state, cfg, NOW)[0] == pytest.approx(0.15 * f)
    v, w = limit_twist(0.15, 0.44, state, cfg, NOW)
    assert v == pytest.approx(0.15 * f) and w / v == pytest.approx(0.44 / 0.15)
    # a gentle right arc (10 m radius) still sweeps the point: slowed as before
    assert limit_twist(0.3, -0.03, state, cfg, NOW)[0] == pytest.approx(0.3 * f)
    # too close to measure is too close, whichever way the arc turns
    assert limit_twist(0.15, -0.44, _ping_left(-math.inf), cfg, NOW) == (0.0, 0.0)
    # the published verdict is the straight one: forward motion is refused within the veto
    assert _ping_left(0.28).vetoed_at(NOW)
    assert limit_twist(0.15, -0.44, _ping_left(0.28), cfg, NOW) == (0.15, -0.44)


def test_a_wall_across_a_turn_still_slows_it():
    # a wall 0.3 m ahead of the front, square to the robot: the centre IR sees it on the
    # centre line and the right PING on the right; an arc to the right is judged on both
    cfg = SafetyConfig()
    wall_x = 0.2245 + 0.3
    ping_r = (wall_x - 0.195) / math.cos(math.pi / 8)
    state = clear_state()
    for t in (100 * MS, 150 * MS):
        state.update({**CLEAR, "ir_center": wall_x - 0.21, "ping_right": ping_r,
                      "ping_left": ping_r}, t)
    for w in (-0.44, 0.0, 0.44):
        v, _ = limit_twist(0.15, w, state, cfg, NOW)
        assert v == pytest.approx(0.15 * 0.1, abs=0.002)


def test_veto_stops_arcs_but_not_rotation_in_place():
    cfg = SafetyConfig()
    state = _wall(0.2)
    assert limit_twist(0.3, 0.0, state, cfg, NOW) == (0.0, 0.0)
    assert limit_twist(0.3, 0.8, state, cfg, NOW) == (0.0, 0.0)  # not a spin in place
    assert limit_twist(0.0, 0.8, state, cfg, NOW) == (0.0, 0.8)
    assert limit_twist(0.0, -1.5, eddie(), cfg, 0) == (0.0, -1.5)  # even before any reading
    assert limit_twist(0.3, 0.0, _wall(0.25), cfg, NOW) == (0.0, 0.0)  # on the line
    stale = NOW + 501 * MS
    assert limit_twist(0.3, 0.0, _wall(math.inf), cfg, stale) == (0.0, 0.0)


def test_reverse_is_capped_keeping_the_curvature():
    cfg = SafetyConfig()
    state = _wall(0.1)  # an obstacle ahead does not stop backing away
    assert limit_twist(-0.05, 0.3, state, cfg, NOW) == (-0.05, 0.3)
    v, w = limit_twist(-0.3, 0.6, state, cfg, NOW)
    assert (v, w) == pytest.approx((-0.1, 0.2))
    assert limit_twist(-0.3, 0.6, eddie(), cfg, 0) == pytest.approx((-0.1, 0.2))
    assert limit_twist(-0.5, 0.0, state, SafetyConfig(max_reverse_speed=0.0), NOW) == (0.0, 0.0)
    assert limit_twist(-0.5, 1.0, state, SafetyConfig(max_reverse_speed=math.inf), NOW) == (-0.5, 1.0)


def test_disabled_veto_keeps_only_the_reverse_cap():
    cfg = SafetyConfig(enabled=False)
    state = _wall(0.1)
    assert limit_twist(0.3, 0.5, state, cfg, NOW) == (0.3, 0.5)
    assert limit_twist(0.3, 0.5, eddie(cfg), cfg, 0) == (0.3, 0.5)
    assert limit_twist(-0.4, 0.8, state, cfg, NOW) == pytest.approx((-0.1, 0.2))


def test_non_finite_commands_stop():
    cfg = SafetyConfig()
    state = _wall(math.inf)
    assert limit_twist(math.nan, 0.0, state, cfg, NOW) == (0.0, 0.0)
    assert limit_twist(0.0, math.inf, state, cfg, NOW) == (0.0, 0.0)


# -- emergency_status ---------------------------------------------------------------------------


def test_board_veto_monitor():
    m = BoardVetoMonitor(stale_after_ns=500 * MS)
    assert not m.okay(0)  # no board: not okay
    m.on_veto(False, 1000 * MS)
    assert m.okay(1000 * MS)
    assert m.okay(1500 * MS)
    assert not m.okay(1501 * MS)  # the board went quiet
    m.on_veto(True, 1600 * MS)
    assert not m.okay(1600 * MS)
    m.on_veto(False, 1650 * MS)
    assert m.okay(1650 * MS)


def test_safety_node_answers_from_the_board_veto():
    ctx = Context(use_sim_time=True)
    try:
        node = SafetyNode(context=ctx)
        probe = Node("probe", context=ctx)
        ex = SingleThreadedExecutor(context=ctx)
        ex.add_node(node)
        ex.add_node(probe)
        # the board node publishes the veto; SafetyNode must not
        assert SAFETY_VETO_TOPIC not in {p.topic for p in node.publishers}
        pub = probe.create_publisher(Bool, SAFETY_VETO_TOPIC, SAFETY_VETO_QOS)
        client = probe.create_client(GetStatus, "/emergency_status")

        def okay() -> bool:
            return bool(client.call(GetStatus.Request()).okay)

        ex.spin_for(0.1)
        assert okay() is False  # no board yet
        pub.publish(Bool(data=False))
        ex.spin_for(0.1)
        assert okay() is True
        ex.spin_for(0.45)  # 0.55 s since the last verdict
        assert okay() is False
        pub.publish(Bool(data=True))
        ex.spin_for(0.05)
        assert okay() is False
        pub.publish(Bool(data=False))
        ex.spin_for(0.05)
        assert okay() is True
    finally:
        ctx.shutdown()


def test_late_safety_node_gets_the_latched_verdict():
    ctx = Context(use_sim_time=True)
    try:
        board = Node("board", context=ctx)
        pub = board.create_publisher(Bool, SAFETY_VETO_TOPIC, SAFETY_VETO_QOS)
        pub.publish(Bool(data=False))
        node = SafetyNode(context=ctx, parameter_overrides={"stale_after": 1.0})
        ex = SingleThreadedExecutor(context=ctx)
        ex.add_node(node)
        ex.spin_for(0.05)
        assert node.monitor.okay(node.get_clock().now_ns())
        assert node.monitor.stale_after_ns == 1_000_000_000
    finally:
        ctx.shutdown()
