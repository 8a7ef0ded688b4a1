"""Wheel counters: joint counts continue across board reboots and reset_encoder; SPD's average."""

from __future__ import annotations

from eddiebot.base.board_counters import WheelCounters

MS = 1_000_000
MAX_SPEED = 90.0  # positions/s: 1.5 × 90 × 0.1 s + 5 = 18.5 positions plausible per 0.1 s


def test_joint_counts_continue_across_a_counter_restart() -> None:
    c = WheelCounters(MAX_SPEED)
    assert c.update(0, (100, 40)) == (0, 0)  # the first sample is the joints' zero
    assert not c.restarted(100 * MS, (110, 50), None)
    assert c.update(100 * MS, (110, 50)) == (10, 10)
    # 107 positions back in 0.1 s is farther than the wheels can go: a reboot
    assert c.restarted(200 * MS, (3, 3), None)
    c.rebase = True
    assert c.update(200 * MS, (3, 3)) == (10, 10)
    assert c.update(300 * MS, (13, -7)) == (20, 0)


def test_counters_near_zero_after_a_silence_are_a_reboot() -> None:
    c = WheelCounters(MAX_SPEED)
    c.update(0, (0, 0))
    c.update(100 * MS, (500, 500))
    # 10 s later the jump is within reach, but the counters fell back near zero after the
    # board went silent: it rebooted
    assert c.restarted(10_100 * MS, (2, 2), silent_since_ns=200 * MS)
    assert not c.restarted(10_100 * MS, (2, 2), silent_since_ns=None)
    assert not c.restarted(10_100 * MS, (600, 600), silent_since_ns=200 * MS)


def test_reset_encoder_restarts_the_encoder_counts_only() -> None:
    c = WheelCounters(MAX_SPEED)
    c.update(0, (0, 0))
    c.update(100 * MS, (12, 8))
    c.reset_zero()
    assert c.since_zero() == (0, 0)
    assert c.update(200 * MS, (20, 10)) == (20, 10)
    assert c.since_zero() == (8, 2)


def test_average_speed_over_the_last_half_second() -> None:
    c = WheelCounters(MAX_SPEED)
    assert c.average_speed() is None
    for k in range(11):  # 10 positions per 0.1 s on the left, -5 on the right
        c.update(k * 100 * MS, (10 * k, -5 * k))
    assert c.average_speed() == (100, -50)
    assert c.history[-1][0] - c.history[0][0] <= 500 * MS + 100 * MS
    assert len(c.history) <= 7
