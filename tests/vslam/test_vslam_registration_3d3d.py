"""`Vis/EstimationType` 0: 3D->3D RANSAC registration (loop closures from both frames' depth)."""

import numpy as np
import pytest
from vslam_synthetic import frame, kinect_camera, planar_pose

from eddiebot.vslam.errors import ParameterError
from eddiebot.vslam.features import FeatureExtractor
from eddiebot.vslam.parameters import RtabmapParameters
from eddiebot.vslam.registration import register, solve_3d3d
from eddiebot.vslam.transforms import from_xyz_rpy, from_xyz_yaw, se3_inverse, yaw_of

CAM = kinect_camera(320, 240)


def _pairs(truth: np.ndarray, seed: int = 0, outliers: float = 0.3) -> tuple[np.ndarray, ...]:
    """Old points (floor and a wall, 1-4 m ahead) and the same points seen from the new frame
    with 5 mm noise; a share of the pairs is aliased by one 0.3 m floor tile."""
    rng = np.random.default_rng(seed)
    n = 120
    old = np.column_stack([rng.uniform(1.0, 4.0, n), rng.uniform(-1.5, 1.5, n),
                           np.where(rng.random(n) < 0.5, 0.0, rng.uniform(0.0, 2.0, n))])
    inv = se3_inverse(truth)
    new = old @ inv[:3, :3].T + inv[:3, 3] + rng.normal(0.0, 0.005, (n, 3))
    bad = rng.random(n) < outliers
    old[bad, 0] += 0.3
    return old, new, bad


def _params(**extra: str) -> RtabmapParameters:
    return RtabmapParameters.from_dict({"Vis/EstimationType": "0", "Vis/MinInliers": "12", **extra})


def test_planar_3d3d_recovers_the_pose_and_rejects_aliased_pairs():
    truth = from_xyz_yaw(0.4, -0.2, np.radians(7.0))
    old, new, bad = _pairs(truth)
    t, inl = solve_3d3d(old, new, _params(**{"Reg/Force3DoF": "true"}), np.array([0.0, 0.0, 0.5]))
    assert t is not None
    assert np.hypot(*(t[:2, 3] - truth[:2, 3])) < 0.004
    assert abs(np.degrees(yaw_of(t) - yaw_of(truth))) < 0.15
    assert not np.any(bad[inl])  # 0.3 m aliases are beyond Vis/InlierDistance (0.1 m)
    assert inl.size >= 0.95 * np.count_nonzero(~bad)
    again, inl2 = solve_3d3d(old, new, _params(**{"Reg/Force3DoF": "true"}), np.zeros(3))
    assert again is not None and inl2.size == inl.size  # fixed-seed sampling: repeatable


def test_six_dof_3d3d_recovers_a_tilted_pose():
    truth = from_xyz_rpy(0.3, 0.1, 0.05, np.radians(2.0), np.radians(-3.0), np.radians(10.0))
    old, new, bad = _pairs(truth, seed=1)
    t, inl = solve_3d3d(old, new, _params(), np.zeros(3))
    assert t is not None
    assert np.linalg.norm(t[:3, 3] - truth[:3, 3]) < 0.006
    rot_err = np.degrees(np.arccos(np.clip((np.trace(t[:3, :3].T @ truth[:3, :3]) - 1) / 2, -1, 1)))
    assert rot_err < 0.2
    assert not np.any(bad[inl])


def test_too_few_consistent_pairs_fail():
    truth = from_xyz_yaw(0.4, -0.2, 0.1)
    old, new, _ = _pairs(truth)
    rng = np.random.default_rng(5)
    scrambled = new[rng.permutation(len(new))]  # no consistent pairs left
    t, inl = solve_3d3d(old, scrambled, _params(**{"Reg/Force3DoF": "true"}), np.zeros(3))
    assert t is None or inl.size < 12


def test_register_with_estimation_type_0_on_rendered_frames():
    params = _params(**{"Reg/Force3DoF": "true"})
    ex = FeatureExtractor(params, max_features=1000, strategy=8)
    a = ex.extract(*frame(1, 2.0, 3.0, 0.0), CAM)
    b = ex.extract(*frame(1, 2.25, 2.9, 0.15), CAM)
    r = register(a, b, CAM, params)
    assert r.transform is not None and r.inliers >= 12
    truth = se3_inverse(planar_pose(2.0, 3.0, 0.0)) @ planar_pose(2.25, 2.9, 0.15)
    assert np.hypot(*(r.transform[:2, 3] - truth[:2, 3])) < 0.025  # PnP: 0.002-0.03 m here
    assert abs(np.degrees(yaw_of(r.transform) - 0.15)) < 0.3
    assert r.covariance[0, 0] < 1e-3
    other = ex.extract(*frame(2, 2.0, 3.0, 0.0), CAM)
    assert register(a, other, CAM, params).transform is None


def test_estimation_type_values():
    assert RtabmapParameters.from_dict({"Vis/EstimationType": "0"}).vis_estimation_type == 0
    with pytest.raises(ParameterError):
        RtabmapParameters.from_dict({"Vis/EstimationType": "2"})
