"""Time in replays: scans whose time goes backwards are reported instead of dropped silently,
and the node's time gate (``minimum_time_interval``) applies when asked."""

from __future__ import annotations

import math

import numpy as np
import pytest
from slam_world import ROOM, SCAN_ANGLES, loop_path, raycast

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


def _scan(pose: np.ndarray, stamp_ns: int) -> Scan:
    return Scan(raycast(ROOM, pose, SCAN_ANGLES, 12.0), SCAN_ANGLES.copy(), 0.05, 12.0, stamp_ns)


def test_replay_node_time_gate_skips_scans_within_the_interval() -> None:
    truth = loop_path(step=0.6)[:20]
    stamps = [k * 200_000_000 for k in range(len(truth))]  # 0.2 s apart, 0.6 m apart
    scans = [_scan(p, s) for p, s in zip(truth, stamps)]
    cfg = SlamConfig(minimum_travel_distance=0.5, minimum_time_interval=0.5,
                     do_loop_closing=False)
    every = replay_scans(scans, list(truth), cfg)
    gated = replay_scans(scans, list(truth), cfg, node_time_gate=True)
    assert len(every.node_records) == len(truth)
    # a node every third scan (0.6 s), as the node's minimum_time_interval gate allows
    assert gated.node_records == list(range(0, len(truth), 3))
