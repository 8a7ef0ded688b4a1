"""A Kinect-like 57° scan down a featureless corridor: SLAM must not do worse than odometry.

The scan sees only the two side walls (the corridor's ends are beyond its 8 m range), so
each match constrains the position across the corridor and the heading, never along it.
The match is fused with odometry by information, so along the corridor the estimate
follows odometry instead of wandering within the match window.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from _support.slam_scans import kinect_scan
from eddiebot.geometry import se2_between, se2_compose
from eddiebot.slam import SlamCore, load_slam_config
from eddiebot.slam.mapper import constrained_information, fuse_increments

EDDIE_CONFIG = Path(__file__).resolve().parents[2] / "src" / "eddiebot" / "config" / "slam.yaml"

def corridor_drive(**overrides: object) -> tuple[np.ndarray, np.ndarray, list]:
    """(SLAM errors, odometry errors) at each node of a 16 m drive, and the warnings."""
    rng = np.random.default_rng(3)
    config = load_slam_config(EDDIE_CONFIG, overrides=dict(overrides))
    seen = []
    core = SlamCore(config, on_warning=seen.append)
    truth = np.array([[3.0 + 0.1 * k, 1.0 + 0.05 * math.sin(0.05 * k), 0.0] for k in range(161)])
    truth[1:, 2] = np.arctan2(np.diff(truth[:, 1]), np.diff(truth[:, 0]))
    odom = [truth[0].copy()]
    for k in range(1, len(truth)):
        z = se2_between(truth[k - 1], truth[k])
        d = math.hypot(z[0], z[1])
        z = z + np.array([rng.normal(0, 0.01 * d), rng.normal(0, 0.002), rng.normal(0, 0.002)])
        odom.append(se2_compose(odom[-1], z))
    odom_arr = np.array(odom)
    added = []
    for k, (p, o) in enumerate(zip(truth, odom_arr)):
        if core.process(kinect_scan(p, k * 100_000_000, rng), o).processed:
            added.append(k)
    assert len(added) >= 25
    est = core.node_poses()
    err = np.hypot(*(est[:, :2] - truth[added, :2]).T)
    odo_err = np.hypot(*(odom_arr[added, :2] - truth[added, :2]).T)
    return err, odo_err, seen


def test_corridor_drive_is_no_worse_than_odometry() -> None:
    err, odo_err, seen = corridor_drive()
    assert any(w.kind == "low_feature" for w in seen)
    assert not any(w.kind == "slip" for w in seen)
    assert err[-1] <= 1.1 * odo_err[-1] + 0.02
    assert err.max() <= 1.1 * odo_err.max() + 0.02
    assert err.max() < 0.3


def test_corridor_match_constrains_only_across() -> None:
    # a match certain across the corridor (y) and unsure along it (x): the along-corridor
    # direction carries no information, so the fused increment keeps odometry's x
    cov = np.diag([0.02, 1e-4, 1e-4])
    info, dropped = constrained_information(cov, 0.01)
    assert dropped == 1
    assert info[0, 0] == 0.0 and info[1, 1] > 0.0
    z_odom = np.array([0.5, 0.0, 0.0])
    z_match = np.array([0.7, 0.03, 0.01])
    fused, fused_cov = fuse_increments(z_odom, np.diag([1e-3, 1e-3, 1e-3]), z_match, info)
    assert abs(fused[0] - 0.5) < 1e-9
    assert abs(fused[1] - 0.03) < 0.003
    assert fused_cov[0, 0] > fused_cov[1, 1]
