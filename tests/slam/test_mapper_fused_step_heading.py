"""`fused_step_heading`: the fused sequential step's heading from the scan match, not odometry."""

from __future__ import annotations

import numpy as np
import pytest
from slam_world import ROOM, SCAN_ANGLES, loop_path, raycast

from eddiebot.geometry import se2_between, wrap_angle
from eddiebot.slam import Scan, SlamConfig, SlamCore
from eddiebot.slam.errors import ConfigError
from eddiebot.slam.pose_graph import EdgeKind


def _scan(pose: np.ndarray, stamp_ns: int) -> Scan:
    return Scan(raycast(ROOM, pose, SCAN_ANGLES, 12.0), SCAN_ANGLES.copy(), 0.05, 12.0, stamp_ns)


def _step_heading_errors(step_heading: str) -> np.ndarray:
    """Heading error vs truth of every sequential edge, odometry heading off by ±0.012 rad per
    pose (quantised, non-accumulating: ±0.024 rad per step)."""
    truth = loop_path()[:40]
    odom = truth.copy()
    odom[:, 2] = wrap_angle(truth[:, 2] + 0.012 * (-1.0) ** np.arange(len(truth)))
    cfg = SlamConfig(minimum_travel_distance=0.2, do_loop_closing=False, fuse_odometry=True,
                     odometry_rotation_sigma=0.002, odometry_rotation_noise=0.01,
                     odometry_rotation_noise_per_meter=0.003, odometry_span_nodes=4,
                     odometry_heading_quantization=0.014, fused_step_heading=step_heading)
    core = SlamCore(cfg.validated())
    nodes: list[int] = []
    for k, (p, o) in enumerate(zip(truth, odom)):
        r = core.process(_scan(p, k * 100_000_000), o)
        if r.node_id is not None:
            nodes.append(k)
    seq = [e for e in core.graph.edges if e.kind is EdgeKind.SCAN_MATCH and e.j - e.i == 1]
    assert len(seq) >= 25
    return np.array([
        float(wrap_angle(e.measurement[2] - se2_between(truth[nodes[e.i]], truth[nodes[e.j]])[2]))
        for e in seq
    ])


def test_match_heading_ignores_the_quantised_odometry_step_heading() -> None:
    before = np.abs(_step_heading_errors("odometry"))
    after = np.abs(_step_heading_errors("match"))
    assert before.mean() > 0.015  # the fused step follows the odometry's ±0.024 rad steps
    assert after.mean() < 0.3 * before.mean()
    assert after.max() < 0.003


def test_quantization_floor_and_validation() -> None:
    cfg = SlamConfig(odometry_rotation_sigma=0.002, odometry_span_nodes=10,
                     odometry_heading_quantization=0.014, fused_step_heading="quantization")
    cov = SlamCore(cfg)._step_odometry_covariance(np.array([0.3, 0.0, 0.0]))
    assert cov[2, 2] == pytest.approx(2 * 0.014**2)
    # without span edges nothing holds the drift: the noise model stays
    off = SlamCore(SlamConfig(odometry_rotation_sigma=0.002, odometry_rotation_noise_per_meter=0.003,
                              fused_step_heading="match"))
    cov = off._step_odometry_covariance(np.array([0.3, 0.0, 0.0]))
    assert cov[2, 2] == pytest.approx((0.002 + 0.003 * 0.3) ** 2)
    with pytest.raises(ConfigError, match="fused_step_heading"):
        SlamConfig(fused_step_heading="wheels").validated()
