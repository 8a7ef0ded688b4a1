"""Keyboard teleop timing: what is published for which key events at which times (ns)."""

from __future__ import annotations

import pytest

from eddiebot.base.teleop import KeyTeleop, TeleopState

MS = 1_000_000
ZERO = (0.0, 0.0)


def make(**kwargs: float) -> KeyTeleop:
    return KeyTeleop(TeleopState(speed=0.3, turn=1.0), **kwargs)


def test_nothing_happens_before_the_first_key():
    t = make()
    assert t.next_wakeup_ns() is None
    assert t.on_idle(10_000 * MS) is None


def test_held_key_publishes_each_event_and_release_stops_once():
    t = make(key_timeout=0.5)
    # terminal key repeat: 'i' every 33 ms for 0.3 s
    sent = [t.on_key("i", k * 33 * MS) for k in range(10)]
    assert sent == [(0.3, 0.0)] * 10
    last = 9 * 33 * MS
    assert t.next_wakeup_ns() == last + 500 * MS
    assert t.on_idle(last + 499 * MS) is None  # still within key_timeout
    assert t.on_idle(last + 500 * MS) == ZERO  # released: one zero...
    assert t.next_wakeup_ns() is None
    for dt in (501, 600, 5_000):
        assert t.on_idle(last + dt * MS) is None  # ...and then nothing: the mux is free
    assert t.state.command() == ZERO


def test_any_non_binding_key_publishes_one_zero():
    t = make()
    assert t.on_key("i", 0) == (0.3, 0.0)
    for key in ("k", " ", "p", "\x1b"):
        assert t.on_key(key, 100 * MS) == ZERO
    assert t.next_wakeup_ns() is None  # already stopped: no timeout zero to send
    assert t.on_idle(700 * MS) is None


def test_teleop_twist_keyboard_key_map():
    t = make()
    assert t.on_key("u", 0) == (0.3, 1.0)
    assert t.on_key("o", 0) == (0.3, -1.0)
    assert t.on_key("j", 0) == (0.0, 1.0)
    assert t.on_key("l", 0) == (0.0, -1.0)
    assert t.on_key(",", 0) == (-0.3, 0.0)
    assert t.on_key(".", 0) == (-0.3, 1.0)
    assert t.on_key("m", 0) == (-0.3, -1.0)
    v, w = t.on_key("q", 0)  # speed keys keep the direction and publish it
    assert (v, w) == pytest.approx((-0.33, -1.1))
    t.on_key("x", 0)
    assert t.state.speed == pytest.approx(0.297)
    t.on_key("c", 0)
    assert t.state.turn == pytest.approx(0.99)


def test_speed_key_while_stopped_publishes_zero_and_no_timeout_follows():
    t = make()
    assert t.on_key("q", 0) == ZERO
    assert t.next_wakeup_ns() is None
    assert t.on_idle(600 * MS) is None


def test_key_timeout_counts_from_the_last_key_of_any_kind():
    t = make(key_timeout=0.5)
    t.on_key("i", 0)
    assert t.on_key("w", 400 * MS) == pytest.approx((0.33, 0.0))
    assert t.on_idle(600 * MS) is None
    assert t.on_idle(900 * MS) == ZERO


def test_repeat_rate_repeats_a_moving_command_only_until_the_timeout():
    t = make(key_timeout=0.5, repeat_rate=10.0)
    t.on_key("j", 0)
    assert t.next_wakeup_ns() == 100 * MS
    assert t.on_idle(99 * MS) is None
    assert t.on_idle(100 * MS) == (0.0, 1.0)
    assert t.on_idle(150 * MS) is None
    assert t.on_idle(200 * MS) == (0.0, 1.0)
    assert t.on_idle(500 * MS) == ZERO  # timeout wins over the repeat
    assert t.on_idle(600 * MS) is None  # the zero is never repeated
    assert t.next_wakeup_ns() is None


def test_zero_key_timeout_never_times_out():
    t = make(key_timeout=0.0)
    t.on_key("i", 0)
    assert t.next_wakeup_ns() is None
    assert t.on_idle(3_600_000 * MS) is None
    assert t.state.command() == (0.3, 0.0)
