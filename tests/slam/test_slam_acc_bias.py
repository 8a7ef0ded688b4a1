"""`loop_match_range_bias_quadratic`: a quadratic range bias removed from loop-closure matches."""

from __future__ import annotations

import numpy as np
import pytest
from slam_world import ROOM, SCAN_ANGLES, drifting_odometry, loop_path, raycast

from eddiebot.geometry import se2_between
from eddiebot.slam import Scan, SlamConfig, SlamCore
from eddiebot.slam.errors import ConfigError
from eddiebot.slam.mapper import unbiased_points
from eddiebot.slam.pose_graph import EdgeKind

#: the scans below read short by this times r² (a strong version of the Kinect scan's bias)
BIAS = 0.004


def test_unbiased_points_move_each_point_away_from_the_sensor() -> None:
    pts = np.array([[3.0, 4.0], [0.0, -2.0], [0.0, 0.0]])
    out = unbiased_points(pts, 0.0025)
    r = np.hypot(*out.T)
    assert r[0] == pytest.approx(5.0 + 0.0025 * 25.0, abs=1e-12)
    assert r[1] == pytest.approx(2.0 + 0.0025 * 4.0, abs=1e-12)
    assert r[2] == 0.0
    # directions unchanged
    assert out[0, 1] / out[0, 0] == pytest.approx(4.0 / 3.0)
    assert out[1, 0] == 0.0
    assert np.array_equal(unbiased_points(pts, 0.0), pts)
    with pytest.raises(ConfigError, match="loop_match_range_bias_quadratic"):
        SlamConfig(loop_match_range_bias_quadratic=-0.001).validated()


def _loop_edge_errors(correction: float) -> np.ndarray:
    """Position error vs truth of every loop-closure edge on the synthetic loop, scans biased."""
    truth = loop_path()
    odom = drifting_odometry(truth)
    core = SlamCore(SlamConfig(minimum_travel_distance=0.9, loop_match_minimum_chain_size=3,
                               loop_match_range_bias_quadratic=correction))
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


def test_loop_closures_lose_the_range_bias_only_when_asked() -> None:
    before = _loop_edge_errors(0.0)
    after = _loop_edge_errors(BIAS)
    assert len(before) >= 2 and len(after) >= 2
    # the biased scans close the loop several centimetres off; corrected, a fraction of it
    assert before.mean() > 0.05
    assert after.mean() < 0.5 * before.mean()
    assert after.max() < before.min()
