"""A Kinect-made laser scan (57°, 320 beams, 0.5–8 m) of the featureless corridor."""

from __future__ import annotations

import math

import numpy as np
from slam_world import CORRIDOR, raycast

from eddiebot.slam import Scan

#: Kinect-made scan: 57° wide, 320 beams, 0.5–8 m.
KINECT_ANGLES = np.linspace(-math.radians(28.5), math.radians(28.5), 320)


def kinect_scan(pose: np.ndarray, stamp_ns: int, rng: np.random.Generator) -> Scan:
    """Ranges with the Kinect's depth behaviour: noise and 1/8-pixel steps growing with z²."""
    r = raycast(CORRIDOR, pose, KINECT_ANGLES, 8.0)
    hit = np.isfinite(r)
    z = np.where(hit, r, 1.0) * np.cos(KINECT_ANGLES)  # depth along the optical axis
    step = 2.85e-3 * z * z
    z = np.round((z + rng.normal(0.0, 0.5, z.shape) * step) / step) * step
    ranges = z / np.cos(KINECT_ANGLES)
    ranges[~hit | (ranges < 0.5) | (ranges > 8.0)] = np.nan
    return Scan(ranges, KINECT_ANGLES.copy(), 0.5, 8.0, stamp_ns)
