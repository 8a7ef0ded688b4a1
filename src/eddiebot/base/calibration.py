"""UMBmark odometry calibration (Borenstein & Feng, 1996) — pure core.

The robot drives an L×L square clockwise and counter-clockwise several times; after each
run the user measures where it stopped relative to where it started (x forward, y left, in
the start pose's frame). Two systematic errors explain the closing errors:

- unequal wheel diameters (``Ed = D_R / D_L``): the path curves, error angle β;
- a wrong wheel separation (``Eb = b_actual / b_nominal``): every 90° turn is off by α.

From the centres of gravity of the CW and CCW end positions:
``α = (x_cw + x_ccw) / (−4L)``, ``β = (x_cw − x_ccw) / (−4L)``,
``R = (L/2) / sin(β/2)``, ``Ed = (R + b/2) / (R − b/2)``, ``Eb = (π/2) / (π/2 − α)``.
The results are diff_drive_controller's ``wheel_separation_multiplier`` (= Eb) and
``left_wheel_radius_multiplier`` / ``right_wheel_radius_multiplier`` (keeping the mean
diameter), so the odometry node applies them directly.

Signs follow Borenstein's paper, in which the CW run is the reference direction; our x is
forward at the start pose.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

__all__ = ["UmbmarkResult", "umbmark"]


@dataclass(frozen=True)
class UmbmarkResult:
    alpha_rad: float
    beta_rad: float
    ed: float
    eb: float
    wheel_separation_multiplier: float
    left_wheel_radius_multiplier: float
    right_wheel_radius_multiplier: float
    #: the largest distance of a run's centre of gravity from the start, before (m)
    e_max_syst: float


def umbmark(
    cw_errors: Sequence[tuple[float, float]],
    ccw_errors: Sequence[tuple[float, float]],
    side: float,
    wheel_separation: float,
) -> UmbmarkResult:
    """Correction factors from measured closing errors (x, y) in metres of each run."""
    if not cw_errors or not ccw_errors:
        raise ValueError("UMBmark needs at least one clockwise and one counter-clockwise run")
    if side <= 0 or wheel_separation <= 0:
        raise ValueError("side and wheel_separation must be positive")
    cw = np.asarray(cw_errors, dtype=float).reshape(-1, 2).mean(axis=0)
    ccw = np.asarray(ccw_errors, dtype=float).reshape(-1, 2).mean(axis=0)
    alpha = (cw[0] + ccw[0]) / (-4.0 * side)
    beta = (cw[0] - ccw[0]) / (-4.0 * side)
    b = wheel_separation
    if abs(beta) < 1e-12:
        ed = 1.0
    else:
        radius = (side / 2.0) / math.sin(beta / 2.0)
        ed = (radius + b / 2.0) / (radius - b / 2.0)
    eb = (math.pi / 2.0) / (math.pi / 2.0 - alpha)
    # keep the mean diameter: D_L = 2 / (Ed + 1), D_R = 2 / (1/Ed + 1) (times nominal)
    left = 2.0 / (ed + 1.0)
    right = 2.0 / (1.0 / ed + 1.0)
    e_max = max(float(np.hypot(*cw)), float(np.hypot(*ccw)))
    return UmbmarkResult(alpha, beta, ed, eb, eb, left, right, e_max)
