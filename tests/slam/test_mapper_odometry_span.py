"""Odometry span edges (`odometry_span_nodes`): odometry alone across several nodes of one chain."""

from __future__ import annotations

import math

import numpy as np
import pytest
from slam_world import ROOM, SCAN_ANGLES, drifting_odometry, loop_path, raycast

from eddiebot.geometry import se2_between, wrap_angle
from eddiebot.slam import Scan, SlamConfig, SlamCore
from eddiebot.slam.errors import ConfigError
from eddiebot.slam.pose_graph import EdgeKind

SPAN = 4


def _scan(pose: np.ndarray, stamp_ns: int) -> Scan:
    return Scan(raycast(ROOM, pose, SCAN_ANGLES, 12.0), SCAN_ANGLES.copy(), 0.05, 12.0, stamp_ns)


def _spans(core: SlamCore) -> list:
    return [e for e in core.graph.edges if e.kind is EdgeKind.ODOMETRY and e.j - e.i == SPAN]


def test_span_edges_carry_odometry_with_a_non_accumulating_heading_term() -> None:
    truth = loop_path()[:60]
    odom = drifting_odometry(truth)
    cfg = SlamConfig(minimum_travel_distance=0.5, do_loop_closing=False, odometry_span_nodes=SPAN,
                     odometry_heading_quantization=0.01)
    core = SlamCore(cfg)
    for k, (p, o) in enumerate(zip(truth, odom)):
        core.process(_scan(p, k * 100_000_000), o)
    n = len(core.nodes)
    spans = _spans(core)
    assert n > SPAN + 5
    assert len(spans) == n - SPAN  # every scan-matched node from the SPAN-th on
    for e in spans:
        odo = [core.nodes[m].odom_pose for m in range(e.i, e.j + 1)]
        assert np.allclose(e.measurement, se2_between(odo[0], odo[-1]), atol=1e-12)
        dist = sum(math.hypot(*(b[:2] - a[:2])) for a, b in zip(odo, odo[1:]))
        turn = sum(abs(wrap_angle(b[2] - a[2])) for a, b in zip(odo, odo[1:]))
        drift = cfg.odometry_rotation_noise * turn + cfg.odometry_rotation_noise_per_meter * dist
        sth = math.sqrt(2 * 0.01**2 + drift**2)
        sx = cfg.odometry_translation_sigma + cfg.odometry_translation_noise * dist
        assert np.allclose(np.diag(e.covariance), [sx * sx, sx * sx, sth * sth], rtol=1e-9)


def test_no_span_edge_crosses_a_new_odometry_chain() -> None:
    truth = loop_path()[:80]
    odom = drifting_odometry(truth)
    core = SlamCore(SlamConfig(minimum_travel_distance=0.5, do_loop_closing=False,
                               odometry_span_nodes=SPAN))
    for k, (p, o) in enumerate(zip(truth[:40], odom[:40])):
        core.process(_scan(p, k * 100_000_000), o)
    restart = len(core.nodes)
    # a new odometry frame (e.g. the driver restarted): the chain starts again
    core.set_initial_pose(core.node_poses()[-1], odom_pose=np.zeros(3))
    shift = odom[40].copy()
    for k, (p, o) in enumerate(zip(truth[40:], odom[40:]), start=40):
        core.process(_scan(p, k * 100_000_000), se2_between(shift, o))
    spans = _spans(core)
    assert any(e.i >= restart for e in spans)
    assert not any(e.i < restart <= e.j for e in spans)


def test_off_by_default_and_validated() -> None:
    truth = loop_path()[:30]
    odom = drifting_odometry(truth)
    core = SlamCore(SlamConfig(minimum_travel_distance=0.5, do_loop_closing=False))
    for k, (p, o) in enumerate(zip(truth, odom)):
        core.process(_scan(p, k * 100_000_000), o)
    assert all(e.j - e.i == 1 for e in core.graph.edges)
    with pytest.raises(ConfigError, match="odometry_span_nodes"):
        SlamConfig(odometry_span_nodes=-1).validated()
