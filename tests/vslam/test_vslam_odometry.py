import numpy as np
import pytest
from vslam_synthetic import frame, kinect_camera, planar_pose

from eddiebot.vslam.features import FeatureExtractor
from eddiebot.vslam.odometry import VisualOdometry
from eddiebot.vslam.parameters import RtabmapParameters
from eddiebot.vslam.registration import LOST_VARIANCE, register
from eddiebot.vslam.transforms import from_xyz_rpy, se3_inverse, xyz_rpy

CAM = kinect_camera(320, 240)


def _trajectory(n):
    return [(2.0 + 0.04 * k, 3.0 + 0.01 * k, 0.015 * k) for k in range(n)]


@pytest.mark.parametrize("strategy", ["0", "1"])
def test_vo_recovers_known_motion(strategy):
    vo = VisualOdometry(RtabmapParameters.from_dict({"Odom/Strategy": strategy}))
    poses = _trajectory(15)
    result = None
    for k, (x, y, yaw) in enumerate(poses):
        rgb, depth = frame(1, x, y, yaw)
        result = vo.process(rgb, depth, CAM, k * 33_333_333)
        assert result.pose is not None, f"lost at frame {k}"
    truth = se3_inverse(planar_pose(*poses[0])) @ planar_pose(*poses[-1])
    est = xyz_rpy(result.pose)
    ref = xyz_rpy(truth)
    assert np.hypot(est[0] - ref[0], est[1] - ref[1]) < 0.01  # 0.57 m travelled
    assert abs(est[2]) < 0.01
    assert abs(est[5] - ref[5]) < np.deg2rad(0.3)
    assert result.inliers >= 20
    assert np.all(np.diag(result.covariance) < 1e-2)


def test_first_frame_has_huge_covariance_and_identity():
    vo = VisualOdometry(RtabmapParameters())
    rgb, depth = frame(1, 2.0, 3.0, 0.0)
    r = vo.process(rgb, depth, CAM, 0)
    np.testing.assert_allclose(r.pose, np.eye(4))
    assert r.covariance[0, 0] == LOST_VARIANCE


def test_lost_tracking_on_blank_image_returns_no_pose():
    vo = VisualOdometry(RtabmapParameters())
    rgb, depth = frame(1, 2.0, 3.0, 0.0)
    vo.process(rgb, depth, CAM, 0)
    blank = np.full_like(rgb, 128)
    r = vo.process(blank, depth, CAM, 33_000_000)
    assert r.pose is None and r.lost
    assert np.all(np.diag(r.covariance) == LOST_VARIANCE)
    # tracking resumes on a good frame, from the last good pose
    rgb2, depth2 = frame(1, 2.02, 3.0, 0.0)
    r2 = vo.process(rgb2, depth2, CAM, 66_000_000)
    assert r2.pose is not None
    assert abs(r2.pose[0, 3] - 0.02) < 0.01


def test_force_3dof_keeps_planar_pose():
    params = RtabmapParameters.from_dict({"Reg/Force3DoF": "true"})
    vo = VisualOdometry(params)
    for k, (x, y, yaw) in enumerate(_trajectory(5)):
        r = vo.process(*frame(1, x, y, yaw), CAM, k * 33_000_000)
    x, y, z, roll, pitch, yaw = xyz_rpy(r.pose)
    assert z == 0.0 and roll == 0.0 and pitch == 0.0
    assert abs(x - 0.16) < 0.01 and abs(yaw - 0.06) < 0.005


def test_registration_rejects_different_place():
    params = RtabmapParameters()
    ex = FeatureExtractor(params, max_features=1000, strategy=8)
    a = ex.extract(*frame(1, 2.0, 3.0, 0.0), CAM)
    b = ex.extract(*frame(2, 2.0, 3.0, 0.0), CAM)
    result = register(a, b, CAM, params)
    assert result.transform is None
    assert result.covariance[0, 0] == LOST_VARIANCE


def test_registration_with_guess_and_3dof():
    params = RtabmapParameters.from_dict({"Reg/Force3DoF": "true"})
    ex = FeatureExtractor(params, max_features=1000, strategy=8)
    a = ex.extract(*frame(1, 2.0, 3.0, 0.0), CAM)
    b = ex.extract(*frame(1, 2.15, 3.05, 0.1), CAM)
    guess = from_xyz_rpy(0.1, 0.0, 0.0, 0.0, 0.0, 0.05)
    r = register(a, b, CAM, params, guess)
    assert r.transform is not None
    truth = se3_inverse(planar_pose(2.0, 3.0, 0.0)) @ planar_pose(2.15, 3.05, 0.1)
    np.testing.assert_allclose(r.transform[:2, 3], truth[:2, 3], atol=0.01)
    assert r.transform[2, 3] == 0.0
