"""`Vis/PnPMinimal3DoF`: the 2-point planar PnP RANSAC recovers a known x, y, yaw among outliers,
rejects degenerate samples, and serves `register` and `refine_pnp` under `Reg/Force3DoF`."""

import numpy as np
from vslam_synthetic import kinect_camera

from eddiebot.vslam.features import FrameFeatures
from eddiebot.vslam.parameters import RtabmapParameters
from eddiebot.vslam.registration import (
    planar_two_point,
    refine_pnp,
    register,
    reprojection_errors,
    solve_pnp_planar,
)
from eddiebot.vslam.transforms import from_xyz_rpy, from_xyz_yaw, yaw_of

PLANAR = RtabmapParameters.from_dict({"Reg/Force3DoF": "true", "Vis/PnPMinimal3DoF": "true"})


def _scene(truth, n, outlier_share, rng, noise_px=0.0):
    """Old-frame 3D points in front of the camera and their keypoints in the new image (the new
    base at `truth` in the old base frame); the last `outlier_share` of them are moved anywhere
    in the image."""
    cam = kinect_camera()
    lt = truth @ cam.local_transform  # new camera in the old base frame
    depth = rng.uniform(1.0, 6.0, n)
    u = rng.uniform(20, cam.width - 20, n)
    v = rng.uniform(20, cam.height - 20, n)
    ray = np.stack([(u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy, np.ones(n)], axis=1)
    pts = (ray * depth[:, None]) @ lt[:3, :3].T + lt[:3, 3]
    uv = np.stack([u, v], axis=1) + rng.normal(0.0, noise_px, (n, 2))
    bad = np.arange(n) >= round(n * (1 - outlier_share))
    uv[bad] = np.stack([rng.uniform(0, cam.width, bad.sum()),
                        rng.uniform(0, cam.height, bad.sum())], axis=1)
    return cam, pts, uv.astype(np.float32), ~bad


def test_two_point_solution_is_exact_and_degenerate_samples_are_rejected():
    rng = np.random.default_rng(1)
    truth = from_xyz_yaw(0.31, -0.12, np.radians(7.0))
    cam, pts, uv, _ = _scene(truth, 10, 0.0, rng)
    t = planar_two_point(pts[:2], uv[:2], cam)
    assert t is not None
    np.testing.assert_allclose(t, truth, atol=1e-4)  # float32 keypoints
    # degenerate: the same point twice (singular system), two points 1 cm apart in the plane
    assert planar_two_point(pts[[3, 3]], uv[[3, 3]], cam) is None
    close = pts[[4, 4]].copy()
    close[1, :2] += 0.01
    assert planar_two_point(close, uv[[4, 5]], cam) is None
    # an inconsistent pair (second keypoint far from its point): no unit rotation fits it
    wrong = uv[:2].copy()
    wrong[1] = (cam.width - wrong[1, 0], cam.height - wrong[1, 1])
    bad = planar_two_point(pts[:2], wrong, cam)
    assert bad is None or np.hypot(*(bad[:2, 3] - truth[:2, 3])) > 0.05


def test_planar_ransac_recovers_pose_with_outliers_and_no_roll_pitch_z():
    rng = np.random.default_rng(7)
    truth = from_xyz_yaw(0.42, 0.08, np.radians(-12.0))
    cam, pts, uv, good = _scene(truth, 200, 0.6, rng, noise_px=0.3)  # 60 % outliers
    t, inl = solve_pnp_planar(pts, uv, cam, PLANAR)
    assert t is not None
    assert np.hypot(*(t[:2, 3] - truth[:2, 3])) < 0.01
    assert abs(yaw_of(t) - yaw_of(truth)) < np.radians(0.2)
    assert t[2, 3] == 0.0 and abs(t[2, 2] - 1.0) < 1e-12  # planar by construction
    # the inliers are the good matches (a few outliers may land within 2 px by chance)
    assert good[inl].sum() >= 0.95 * good.sum()
    assert (~good[inl]).sum() <= 3
    assert np.all(reprojection_errors(t, pts[inl], uv[inl], cam) < PLANAR.vis_pnp_reproj_error)
    # deterministic
    t2, inl2 = solve_pnp_planar(pts, uv, cam, PLANAR)
    np.testing.assert_array_equal(t, t2)
    np.testing.assert_array_equal(inl, inl2)


def test_planar_ransac_fails_on_pure_outliers():
    rng = np.random.default_rng(3)
    cam, pts, uv, _ = _scene(from_xyz_yaw(0.2, 0.0, 0.1), 60, 1.0, rng)
    t, inl = solve_pnp_planar(pts, uv, cam, PLANAR)
    assert t is None or inl.size < PLANAR.vis_min_inliers


def test_register_uses_planar_solver_and_refine_matches_numpy_refinement():
    rng = np.random.default_rng(11)
    truth = from_xyz_yaw(0.15, -0.05, np.radians(4.0))
    cam, pts, uv, _good = _scene(truth, 150, 0.3, rng, noise_px=0.5)
    n = pts.shape[0]
    desc = rng.integers(0, 256, (n, 32), dtype=np.uint8)
    old = FrameFeatures(np.zeros((n, 2), np.float32), np.ones(n, np.float32),
                        np.zeros(n, np.float32), np.zeros(n, np.float32), np.zeros(n, np.int32),
                        desc, pts)
    new = FrameFeatures(uv, np.ones(n, np.float32), np.zeros(n, np.float32),
                        np.zeros(n, np.float32), np.zeros(n, np.int32), desc.copy(),
                        np.full((n, 3), np.nan))
    # a guess with roll/pitch/z: projected to 3 DoF, the result is planar
    guess = from_xyz_rpy(0.1, 0.0, 0.05, 0.02, -0.03, 0.0)
    res = register(old, new, cam, PLANAR, guess)
    assert res.ok and res.transform is not None
    assert np.hypot(*(res.transform[:2, 3] - truth[:2, 3])) < 0.01
    assert res.inliers >= 0.9 * 0.7 * n
    # the compiled planar refinement equals the numpy one (Vis/PnPMinimal3DoF false)
    start = from_xyz_yaw(0.13, -0.04, np.radians(3.0))
    inl = np.flatnonzero(reprojection_errors(truth, pts, uv, cam) < 2.0)
    one = RtabmapParameters.from_dict({"Reg/Force3DoF": "true", "Vis/PnPRefineIterations": "1"})
    t_np, i_np = refine_pnp(start, pts, uv, inl, cam, one)
    t_nb, i_nb = refine_pnp(start, pts, uv, inl, cam,
                            one.replace({"Vis/PnPMinimal3DoF": "true"}))
    np.testing.assert_allclose(t_nb, t_np, atol=1e-9)
    np.testing.assert_array_equal(i_nb, i_np)
