"""The board node's two small state vocabularies: which stop it owes, what motion it runs."""

from __future__ import annotations

import enum

__all__ = ["Motion", "StopKind"]


class StopKind(enum.IntEnum):
    """The two ways to stop; a larger value is the stronger stop."""

    HOLD = 1  # GOSPD 0 0: closed-loop hold at zero speed, ramped at ACC
    CUT = 2  # STOP 0: motor power cut


class Motion(enum.Enum):
    NONE = "none"
    VELOCITY = "velocity"  # GOSPD from /eddie/simple_velocity (stale timer applies)
    SERVICE_SPEED = "service speed"  # GOSPD / GO from a service (stale timer applies)
    SERVICE_MOVE = "service move"  # TRVL / TURN: ends by itself
