"""Which stop the board node owes the board, and how far it has got (pure: no bus, no clock).

A stop goes through three states: owed (sent, no reply yet), confirmed (the board replied)
and verified (the polled SPD read 0 0 after the reply). An owed stop is sent again at every
poll; a confirmed one whose SPD does not reach 0 0 within the ramp the last speed and ``ACC``
imply, plus SPD's 0.5 s average and one poll period, becomes an owed ``STOP 0``.
"""

from __future__ import annotations

import enum

from eddiebot.base.board_counters import SPD_AVERAGE_S
from eddiebot.base.board_modes import StopKind

__all__ = ["StopCheck", "StopTracker"]


class StopCheck(enum.Enum):
    """What a poll must do about the stop (``StopTracker.check``)."""

    NOTHING = "nothing"
    RESEND = "resend"  # unconfirmed: send it again
    VERIFIED = "verified"  # SPD reads 0 0 after the reply: the wheels are still
    RECUT = "recut"  # SPD did not decay in time: STOP 0 is owed now


class StopTracker:
    """The stop state: ``kind`` (None: no stop owed, motion runs), ``confirmed_ns`` (when the
    board's reply came; None: not yet), ``verified`` and the SPD ``deadline_ns``."""

    def __init__(self) -> None:
        self.kind: StopKind | None = None
        self.confirmed_ns: int | None = None
        self.verified = False
        self.deadline_ns = 0

    @property
    def owed(self) -> bool:
        """A stop was requested and the board has not confirmed it."""
        return self.kind is not None and self.confirmed_ns is None

    @property
    def awaiting_speed(self) -> bool:
        """Confirmed, not yet verified: SPD must be polled."""
        return self.kind is not None and not self.verified and bool(self.confirmed_ns)

    def request(self, kind: StopKind, now_ns: int, recent_ns: int) -> bool:
        """Owe a ``kind`` stop; False (nothing to send) when the same or a stronger stop was
        confirmed less than ``recent_ns`` ago. A stronger stop still owed is kept."""
        current = self.kind
        if (current is not None and current >= kind and self.confirmed_ns is not None
                and now_ns - self.confirmed_ns < recent_ns):
            return False
        self.kind = max(kind, current) if self.owed and current is not None else kind
        self.confirmed_ns = None
        self.verified = False
        return True

    def confirm(self, kind: StopKind, now_ns: int, speed: float, acceleration: int,
                poll_period_s: float) -> bool:
        """The board replied to a ``kind`` stop at ``now_ns``; False when a stronger stop is
        still owed. ``speed`` (positions/s) and ``acceleration`` (ACC) set how long SPD may
        take to read 0 0."""
        if self.kind is not None and kind < self.kind:
            return False
        self.kind = kind
        self.confirmed_ns = now_ns
        self.deadline_ns = now_ns + round(
            (speed / max(acceleration, 1) + SPD_AVERAGE_S + poll_period_s) * 1e9)
        self.verified = False
        return True

    def check(self, now_ns: int, spd: tuple[int, int], spd_stamp_ns: int) -> StopCheck:
        """What to do at a poll, given the last SPD reading and when it was taken."""
        if self.kind is None:
            return StopCheck.NOTHING
        if self.confirmed_ns is None:
            return StopCheck.RESEND
        if self.verified:
            return StopCheck.NOTHING
        if spd == (0, 0) and spd_stamp_ns > self.confirmed_ns:
            self.verified = True
            return StopCheck.VERIFIED
        if now_ns > self.deadline_ns:
            self.kind = StopKind.CUT
            self.confirmed_ns = None
            return StopCheck.RECUT
        return StopCheck.NOTHING

    def clear(self) -> None:
        """Motion was commanded: no stop is owed any more."""
        self.kind = None
        self.confirmed_ns = None
        self.verified = False

    def describe(self) -> str:
        """``none``, or the kind and its state (``CUT verified``), for diagnostics."""
        if self.kind is None:
            return "none"
        state = ("verified" if self.verified else
                 "confirmed" if self.confirmed_ns else "unconfirmed")
        return f"{self.kind.name} {state}"
