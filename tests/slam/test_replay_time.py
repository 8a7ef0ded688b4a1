"""Replays report scans whose time goes backwards instead of dropping them silently."""

from __future__ import annotations

import math

import numpy as np
import pytest
from slam_world import ROOM, raycast

from eddiebot.slam import Scan, SlamConfig
from eddiebot.slam.replay import replay_scans


def _scans(stamps_s: list[float]) -> tuple[list[Scan], list[np.ndarray]]:
    angles = np.linspace(-math.pi / 2, math.pi / 2, 181)
    scans, odom = [], []
    for k, t in enumerate(stamps_s):
        pose = np.array([2.0 + 0.3 * k, 4.0, 0.0])
        scans.append(Scan(raycast(ROOM, pose, angles, 20.0), angles, 0.1, 20.0, round(t * 1e9)))
        odom.append(pose)
    return scans, odom


@pytest.mark.parametrize("mode", ["sync", "async"])
def test_backwards_scans_are_counted_and_named(mode: str) -> None:
    # a bag played twice in a row: the second pass starts before the first ended
    scans, odom = _scans([1.0, 2.0, 3.0, 1.5, 2.5, 4.0])
    result = replay_scans(scans, odom, SlamConfig(minimum_travel_distance=0.2), mode=mode,
                          node_time_gate=True)
    assert result.time_backwards == 2
    assert result.warnings["time_backwards"] == 2
    assert result.first_warnings[:2] == [
        "scan 3 at 1.500 s is older than the scan before it (3.000 s): skipped",
        "scan 4 at 2.500 s is older than the scan before it (3.000 s): skipped",
    ]
    assert result.statuses["added"] == 4
