"""The stop state: owed until the board replies, verified when SPD reads 0 0 after the
reply, cut again when SPD does not decay within the ramp ACC allows."""

from __future__ import annotations

from eddiebot.base.board_modes import StopKind
from eddiebot.base.board_stops import StopCheck, StopTracker

MS = 1_000_000


def test_a_stop_is_owed_until_confirmed_then_verified_by_a_fresh_spd() -> None:
    s = StopTracker()
    assert s.check(0, (0, 0), 0) == StopCheck.NOTHING and s.describe() == "none"
    assert s.request(StopKind.HOLD, 0, 250 * MS)
    assert s.owed and s.describe() == "HOLD unconfirmed"
    assert s.check(10 * MS, (0, 0), 5 * MS) == StopCheck.RESEND
    assert s.confirm(StopKind.HOLD, 20 * MS, speed=0, acceleration=200, poll_period_s=0.1)
    assert not s.owed and s.awaiting_speed
    # an SPD read before the reply proves nothing
    assert s.check(30 * MS, (0, 0), 15 * MS) == StopCheck.NOTHING
    assert s.check(40 * MS, (0, 0), 35 * MS) == StopCheck.VERIFIED
    assert s.verified and not s.awaiting_speed and s.describe() == "HOLD verified"


def test_a_stop_confirmed_a_moment_ago_is_not_sent_again() -> None:
    s = StopTracker()
    s.request(StopKind.CUT, 0, 250 * MS)
    s.confirm(StopKind.CUT, 10 * MS, 0, 200, 0.1)
    assert not s.request(StopKind.HOLD, 100 * MS, 250 * MS)  # a weaker one, just confirmed
    assert not s.request(StopKind.CUT, 100 * MS, 250 * MS)
    assert s.request(StopKind.CUT, 300 * MS, 250 * MS)  # long enough ago: sent again


def test_a_stronger_owed_stop_is_kept_and_a_weaker_reply_does_not_confirm_it() -> None:
    s = StopTracker()
    s.request(StopKind.CUT, 0, 250 * MS)
    s.request(StopKind.HOLD, 1 * MS, 250 * MS)
    assert s.kind == StopKind.CUT
    assert not s.confirm(StopKind.HOLD, 2 * MS, 0, 200, 0.1)
    assert s.owed
    assert s.confirm(StopKind.CUT, 3 * MS, 0, 200, 0.1)


def test_wheels_still_turning_after_the_ramp_get_stop_0_again() -> None:
    s = StopTracker()
    s.request(StopKind.HOLD, 0, 250 * MS)
    # 200 positions/s at ACC 100: 2 s of ramp + SPD's 0.5 s average + one 0.1 s poll
    s.confirm(StopKind.HOLD, 0, speed=200, acceleration=100, poll_period_s=0.1)
    assert s.deadline_ns == 2_600 * MS
    assert s.check(2_600 * MS, (40, 40), 2_590 * MS) == StopCheck.NOTHING
    assert s.check(2_601 * MS, (40, 40), 2_590 * MS) == StopCheck.RECUT
    assert s.kind == StopKind.CUT and s.owed


def test_commanded_motion_clears_the_stop() -> None:
    s = StopTracker()
    s.request(StopKind.CUT, 0, 250 * MS)
    s.clear()
    assert s.kind is None and not s.owed and s.check(0, (5, 5), 0) == StopCheck.NOTHING
