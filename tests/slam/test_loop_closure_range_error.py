"""Loop closures weakened by the scan's range error."""

from __future__ import annotations

import math

import numpy as np
import pytest
from slam_world import ROOM, SCAN_ANGLES, drifting_odometry, loop_path, raycast

from eddiebot.geometry import se2_between
from eddiebot.slam import Scan, SlamConfig, SlamCore
from eddiebot.slam.mapper import scan_position_covariance
from eddiebot.slam.pose_graph import EdgeKind
from eddiebot.slam.scan import scan_points
from eddiebot.slam.scan_matcher import MatchResult, point_normals


def _scan(pose: np.ndarray, stamp_ns: int) -> Scan:
    return Scan(raycast(ROOM, pose, SCAN_ANGLES, 12.0), SCAN_ANGLES.copy(), 0.05, 12.0, stamp_ns)


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


def test_loop_edges_carry_the_range_error_only_when_asked() -> None:
    from slam_world import drifting_odometry

    from eddiebot.slam.mapper.measurement import _rotate_covariance
    from eddiebot.slam.pose_graph import EdgeKind

    truth = loop_path()
    odom = drifting_odometry(truth)
    edges = {}
    cores = {}
    for on in (False, True):
        core = SlamCore(SlamConfig(minimum_travel_distance=0.9, loop_match_minimum_chain_size=3,
                                   loop_match_range_covariance=on,
                                   scan_range_sigma_quadratic=0.0025))
        for k, (p, o) in enumerate(zip(truth, odom)):
            core.process(_scan(p, k * 100_000_000), o)
            loops = [e for e in core.graph.edges if e.kind is EdgeKind.LOOP]
            if loops:
                edges[on] = loops[0]
                break
        cores[on] = core
    off, on_ = edges[False], edges[True]
    # the same first loop, measured alike; only its position covariance grows, by the
    # range error of the closing scan's points turned into the candidate's frame
    assert (off.i, off.j) == (on_.i, on_.j)
    assert np.allclose(off.measurement, on_.measurement, atol=1e-9)
    core = cores[True]
    pts = core.nodes[on_.j].points
    geo = scan_position_covariance(pts, point_normals(pts), 0.01, 0.0025)
    match = core.loop_closures[0].match
    c, s = math.cos(float(match.pose[2])), math.sin(float(match.pose[2]))
    rot = np.array([[c, -s], [s, c]])
    added = np.zeros((3, 3))
    added[:2, :2] = rot @ geo @ rot.T
    expected = off.covariance + _rotate_covariance(added, float(core.graph.pose(on_.i)[2]))
    assert np.trace(on_.covariance[:2, :2]) > np.trace(off.covariance[:2, :2]) + 1e-4
    assert np.allclose(on_.covariance, expected, atol=1e-6)


#: the scans below read short by this times r² (a strong version of the Kinect scan's bias)
BIAS = 0.004


def _loop_edge_errors() -> np.ndarray:
    """Position error vs truth of every loop-closure edge on the synthetic loop, scans biased."""
    truth = loop_path()
    odom = drifting_odometry(truth)
    core = SlamCore(SlamConfig(minimum_travel_distance=0.9, loop_match_minimum_chain_size=3))
    nodes: list[int] = []
    with np.errstate(invalid="ignore"):
        for k, (p, o) in enumerate(zip(truth, odom)):
            r = raycast(ROOM, p, SCAN_ANGLES, 12.0)
            out = core.process(Scan(r - BIAS * r**2, SCAN_ANGLES.copy(), 0.05, 12.0,
                                    k * 100_000_000), o)
            if out.node_id is not None:
                nodes.append(k)
    loops = [e for e in core.graph.edges if e.kind is EdgeKind.LOOP]
    return np.array([
        float(np.hypot(*(e.measurement[:2] - se2_between(truth[nodes[e.i]], truth[nodes[e.j]])[:2])))
        for e in loops
    ])


def test_biased_scans_close_the_loop_off_by_their_bias() -> None:
    errors = _loop_edge_errors()
    assert len(errors) >= 2
    # the biased scans close the loop several centimetres off
    assert errors.mean() > 0.05
