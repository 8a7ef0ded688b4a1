"""Compiling the numba kernels ahead of the first scan."""


from __future__ import annotations

import dataclasses
import math
import time

import numpy as np

from eddiebot.slam.config import SlamConfig
from eddiebot.slam.loop_closure import (
    verify_loop,
)
from eddiebot.slam.mapper.core import SlamCore
from eddiebot.slam.mapper.results import FloatArray
from eddiebot.slam.mapper.se2_rows import _compose1
from eddiebot.slam.scan import Scan, valid_beams


def valid_point_count(scan: Scan, max_laser_range: float) -> int:
    """Number of usable beams in a scan."""
    return int(np.count_nonzero(valid_beams(scan, max_laser_range)))


def _box_ranges(pose: FloatArray, angles: FloatArray, size: tuple[float, float]) -> FloatArray:
    """Ranges from ``pose`` (inside the box [0, w] × [0, h]) to the box's walls."""
    a = pose[2] + angles
    c, s = np.cos(a), np.sin(a)
    with np.errstate(divide="ignore"):
        tx = np.where(c > 0, (size[0] - pose[0]) / c, np.where(c < 0, -pose[0] / c, np.inf))
        ty = np.where(s > 0, (size[1] - pose[1]) / s, np.where(s < 0, -pose[1] / s, np.inf))
    return np.asarray(np.minimum(tx, ty))


def warm_up(config: SlamConfig | None = None) -> float:
    """Run the core's compiled kernels once on a synthetic room, so that numba compiles them
    (first run after an install, ~10 s) or loads them from its cache (~0.3 s) now rather than
    on the first real scan; returns the seconds it took. Nothing is kept.

    A short drive along a box 4 m wide exercises sequential matching (correlative search,
    sub-cell refinement, ICP polish, covariance), the occupancy grid's ray casting and a
    loop-closure verification (multi-resolution coarse search, then fine).
    """
    t0 = time.perf_counter()
    cfg = dataclasses.replace(
        config or SlamConfig(), mode="mapping", minimum_time_interval=0.0, map_file_name=""
    )
    core = SlamCore(cfg)
    angles = np.linspace(-0.5, 0.5, 160)  # a 57° scan; the kernels do not depend on the width
    range_max = min(cfg.max_laser_range, 12.0)
    step = max(cfg.minimum_travel_distance, 0.1) + 0.05  # every pose becomes a node
    size = (2.0 + 3 * step + 3.0, 4.0)  # the last pose still 3 m short of the end wall
    for k in range(4):
        pose = np.array([1.0 + step * k, 1.5 + 0.02 * k, 0.05 * k])
        scan = Scan(_box_ranges(pose, angles, size), angles, 0.05, range_max, (k + 1) * 10**9)
        core.process(scan, pose)
    core.update_map()
    if len(core.nodes) >= 2:
        verify_loop(
            core.nodes[-1].points,
            _compose1(core.graph.pose(len(core.nodes) - 1), core.sensor_offset),
            (0,),
            core._world_points(0),
            core._positions()[:1],
            coarse=core._loop_coarse,
            fine=core._loop_fine,
            min_response_coarse=0.0,
            max_variance_coarse=math.inf,
            min_response_fine=0.0,
        )
    return time.perf_counter() - t0
