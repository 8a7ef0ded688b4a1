"""Loop-closure range options and the node's time gate in replays."""

from __future__ import annotations

import math

import numpy as np
import pytest
from slam_world import ROOM, SCAN_ANGLES, drifting_odometry, loop_path, raycast

from eddiebot.slam import Scan, SlamConfig, SlamCore
from eddiebot.slam.errors import ConfigError
from eddiebot.slam.mapper import scan_position_covariance
from eddiebot.slam.pose_graph import EdgeKind
from eddiebot.slam.replay import replay_scans
from eddiebot.slam.scan import scan_points
from eddiebot.slam.scan_matcher import MatchResult, point_normals


def _scan(pose: np.ndarray, stamp_ns: int) -> Scan:
    return Scan(raycast(ROOM, pose, SCAN_ANGLES, 12.0), SCAN_ANGLES.copy(), 0.05, 12.0, stamp_ns)


def _run(cfg: SlamConfig) -> SlamCore:
    truth = loop_path()
    odom = drifting_odometry(truth)
    core = SlamCore(cfg)
    for k, (p, o) in enumerate(zip(truth, odom)):
        core.process(_scan(p, k * 100_000_000), o)
    return core


def _loops(core: SlamCore) -> list:
    return [e for e in core.graph.edges if e.kind is EdgeKind.LOOP]


def test_loop_range_cap_limits_the_points_a_loop_match_uses() -> None:
    base = SlamConfig(minimum_travel_distance=0.9, loop_match_minimum_chain_size=3)
    off = _run(base)
    assert len(_loops(off)) >= 1
    # a cap beyond every range changes nothing
    same = _run(SlamConfig(**{**base.to_parameters(), "loop_match_max_laser_range": 30.0}))
    assert len(_loops(same)) == len(_loops(off))
    assert np.array_equal(same.node_poses(), off.node_poses())
    # the room's walls are 1.5-10 m away: within 0.5 m too few points remain to try a loop
    near = _run(SlamConfig(**{**base.to_parameters(), "loop_match_max_laser_range": 0.5}))
    assert len(_loops(near)) == 0
    with pytest.raises(ConfigError, match="loop_match_max_laser_range"):
        SlamConfig(loop_match_max_laser_range=-1.0).validated()


def test_loop_range_covariance_weakens_a_far_wall_along_the_view_only() -> None:
    # a 57° scan facing a wall 7 m ahead, with side walls 1 m either side
    walls = np.array([[0.0, -1.0, 8.0, -1.0], [0.0, 1.0, 8.0, 1.0], [7.0, -1.0, 7.0, 1.0]])
    angles = np.linspace(-0.5, 0.5, 200)
    scan = Scan(raycast(walls, np.zeros(3), angles, 8.0), angles, 0.05, 8.0, 0)
    points = scan_points(scan, 8.0)
    cfg = SlamConfig(loop_match_range_covariance=True, scan_range_sigma=0.01,
                     scan_range_sigma_quadratic=0.0025)
    core = SlamCore(cfg)
    geo = scan_position_covariance(points, point_normals(points), 0.01, 0.0025)
    # along the view only the end wall pins the position: its range error at 7 m
    sigma_far = 0.01 + 0.0025 * 49.0
    assert 0.5 * sigma_far**2 < geo[0, 0] < 2.0 * sigma_far**2
    assert geo[1, 1] < 0.1 * geo[0, 0]
    heading = math.pi / 2  # the match's pose turns the sensor-frame covariance into the map
    match = MatchResult(np.array([1.0, 2.0, heading]), 0.9, np.diag([1e-4, 1e-4, 1e-5]))
    out = core._with_range_error(match, points, 0)
    assert out.covariance[1, 1] == pytest.approx(1e-4 + geo[0, 0], rel=1e-6)
    assert out.covariance[0, 0] == pytest.approx(1e-4 + geo[1, 1], rel=1e-6)
    assert out.covariance[2, 2] == 1e-5
    assert np.array_equal(out.pose, match.pose)


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
