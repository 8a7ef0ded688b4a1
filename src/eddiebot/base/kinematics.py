"""Body twist ⇄ wheel speeds for Eddie (pure core).

Converts (v m/s, ω rad/s; REP-103) into per-wheel encoder positions per second, saturating
both wheels together so the commanded curvature is kept, and back.
"""

from __future__ import annotations

import math

from eddiebot.robot.constants import METRES_PER_POSITION, TRACK_M

__all__ = ["twist_to_wheel_positions", "wheel_positions_to_twist"]


def twist_to_wheel_positions(
    linear: float,
    angular: float,
    *,
    max_positions_per_s: float,
    track: float = TRACK_M,
    metres_per_position: float = METRES_PER_POSITION,
    radius_multipliers: tuple[float, float] = (1.0, 1.0),
) -> tuple[int, int]:
    """(v, ω) → (left, right) positions/s, rounded; scaled down together to the limit.

    ``radius_multipliers`` (left, right) are the calibrated wheel radii over the nominal one
    (``eddie calibrate``'s ``*_wheel_radius_multiplier``): a larger wheel needs fewer
    positions for the same speed. Non-finite inputs give (0, 0): a NaN must never reach the
    motors.
    """
    if not (math.isfinite(linear) and math.isfinite(angular)):
        return 0, 0
    left = (linear - angular * track / 2.0) / (metres_per_position * radius_multipliers[0])
    right = (linear + angular * track / 2.0) / (metres_per_position * radius_multipliers[1])
    biggest = max(abs(left), abs(right))
    if biggest > max_positions_per_s > 0:
        scale = max_positions_per_s / biggest
        left *= scale
        right *= scale
    return round(left), round(right)


def wheel_positions_to_twist(
    left: float,
    right: float,
    *,
    track: float = TRACK_M,
    metres_per_position: float = METRES_PER_POSITION,
) -> tuple[float, float]:
    """(left, right) positions/s → (v m/s, ω rad/s)."""
    vl = left * metres_per_position
    vr = right * metres_per_position
    return 0.5 * (vl + vr), (vr - vl) / track
