"""The core refuses odometry jumps in heading as in position, and a pause is not a jump."""

from __future__ import annotations

import math

import numpy as np
from slam_world import ROOM, raycast

from eddiebot.geometry import se2_compose
from eddiebot.slam import Scan, SlamConfig, SlamCore

ANGLES = np.linspace(-math.pi / 2, math.pi / 2, 181)


def _scan(pose: np.ndarray, k: int) -> Scan:
    return Scan(raycast(ROOM, pose, ANGLES, 20.0), ANGLES, 0.1, 20.0, k * 500_000_000)


def _drive(core: SlamCore, jump: np.ndarray, forget_at: int = -1) -> float:
    """Drive 4 m along y = 4; the odometry jumps by ``jump`` (composed) from scan 8 on."""
    truth = np.zeros(3)
    for k in range(17):
        truth = np.array([2.0 + 0.25 * k, 4.0, 0.0])
        odom = se2_compose(jump, truth) if k >= 8 else truth
        if k == forget_at:
            core.forget_odometry()
        core.process(_scan(truth, k), odom)
    estimate = core.node_poses()[-1]
    return float(np.hypot(*(estimate[:2] - truth[:2])))


def test_heading_jump_is_refused() -> None:
    core = SlamCore(SlamConfig(minimum_travel_distance=0.2))
    error = _drive(core, np.array([0.0, 0.0, 2.5]))
    assert core.odometry_jumps == 1
    assert error < 0.05


def test_below_the_limits_is_motion() -> None:
    core = SlamCore(SlamConfig(minimum_travel_distance=0.2, max_odometry_jump=5.0))
    _drive(core, np.array([3.0, 0.0, 0.0]))
    assert core.odometry_jumps == 0


def test_forget_odometry_after_a_pause() -> None:
    core = SlamCore(SlamConfig(minimum_travel_distance=0.2))
    _drive(core, np.array([3.0, 0.0, 0.0]), forget_at=8)
    assert core.odometry_jumps == 0


def _drive_blind(core: SlamCore, jump: np.ndarray, jump_at: int) -> float:
    """Drive along y = 4 as `_drive`; scans 4-9 have no valid range (a depth camera facing
    open floor) and are skipped, while the odometry goes on (jumping by ``jump`` from scan
    ``jump_at`` on)."""
    truth = np.zeros(3)
    for k in range(17):
        truth = np.array([2.0 + 0.25 * k, 4.0, 0.0])
        odom = se2_compose(jump, truth) if k >= jump_at else truth
        scan = _scan(truth, k)
        if 4 <= k <= 9:
            scan = Scan(np.full_like(scan.ranges, np.nan), ANGLES, 0.1, 20.0, scan.stamp_ns)
        result = core.process(scan, odom)
        assert (result.status.name == "SKIPPED") == (4 <= k <= 9)
    estimate = core.node_poses()[-1]
    return float(np.hypot(*(estimate[:2] - truth[:2])))


def test_driving_past_skipped_scans_is_not_a_jump() -> None:
    """1.75 m between the valid scans 3 and 10, all of it driven: the skipped scans' odometry
    still counts (taking it as a jump put the depot's robot 1.15 m back, ATE 1.66 m)."""
    core = SlamCore(SlamConfig(minimum_travel_distance=0.2))
    error = _drive_blind(core, np.zeros(3), jump_at=99)
    assert core.odometry_jumps == 0
    assert error < 0.05


def test_a_jump_among_skipped_scans_is_still_refused() -> None:
    core = SlamCore(SlamConfig(minimum_travel_distance=0.2))
    error = _drive_blind(core, np.array([3.0, 0.0, 0.0]), jump_at=6)
    assert core.odometry_jumps == 1
    assert error < 0.05
