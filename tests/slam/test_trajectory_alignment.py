"""The mapping stage's aligned trajectory error (TUM / ``evo_ape --align`` ATE)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from eddiebot.demo.mapping import aligned_position_errors
from eddiebot.geometry import se2_compose


def _path(n: int = 200, seed: int = 3) -> np.ndarray:
    rng = np.random.default_rng(seed)
    steps = np.column_stack([np.full(n, 0.3), np.zeros(n), rng.normal(0.0, 0.2, n)])
    poses = np.zeros((n, 3))
    for k in range(1, n):
        poses[k] = se2_compose(poses[k - 1], steps[k])
    return poses


def test_a_turned_and_shifted_path_aligns_to_zero_and_reports_the_turn() -> None:
    truth = _path()
    moved = se2_compose(np.broadcast_to(np.array([1.5, -2.0, math.radians(0.5)]), truth.shape), truth)
    anchored = np.hypot(*(moved[:, :2] - truth[:, :2]).T)
    err, turn = aligned_position_errors(moved, truth)
    assert anchored.max() > 1.0
    assert err.max() < 1e-9
    # the fit maps the estimate onto the truth: the opposite of the turn applied
    assert math.degrees(turn) == pytest.approx(-0.5, abs=1e-9)


def test_shape_errors_survive_the_alignment() -> None:
    truth = _path()
    est = truth.copy()
    est[100:, 1] += 0.2  # half the path 0.2 m off: no rigid motion removes that
    err, _ = aligned_position_errors(est, truth)
    assert 0.08 < float(np.sqrt(np.mean(err**2))) < 0.11


def test_matches_evo_ape_with_alignment() -> None:
    pytest.importorskip("evo")
    from evo.core import metrics
    from evo.core.trajectory import PoseTrajectory3D

    rng = np.random.default_rng(7)
    truth = _path()
    est = se2_compose(np.broadcast_to(np.array([0.3, 0.1, 0.02]), truth.shape), truth)
    est[:, :2] += rng.normal(0.0, 0.05, (len(est), 2))
    err, _ = aligned_position_errors(est, truth)

    def traj(p: np.ndarray) -> PoseTrajectory3D:
        z = np.zeros(len(p))
        quat = np.column_stack([np.cos(p[:, 2] / 2), z, z, np.sin(p[:, 2] / 2)])
        return PoseTrajectory3D(positions_xyz=np.column_stack([p[:, 0], p[:, 1], z]),
                                orientations_quat_wxyz=quat, timestamps=np.arange(len(p), dtype=float))

    t_est, t_ref = traj(est), traj(truth)
    t_est.align(t_ref)
    ape = metrics.APE(metrics.PoseRelation.translation_part)
    ape.process_data((t_ref, t_est))
    assert float(np.sqrt(np.mean(err**2))) == pytest.approx(
        ape.get_statistic(metrics.StatisticsType.rmse), rel=1e-9)
