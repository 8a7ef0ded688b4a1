"""Depth ICP for the odometry (`Reg/Strategy` 1/2, `Odom/IcpFallbackInliers`): registration of
synthetic depth images of a box room (walls, corners, floor, ceiling), the covariance of a
single wall, and the odometry through a textureless stretch.

Depth images are ray-cast here (a 320×240 Kinect-like camera at Eddie's mount, depth in mm),
so the tests run in about a second.
"""

import numpy as np
import pytest

from _support.vslam_room import CAM, ICP_VO, ROOM, render_room, spin_in_room
from eddiebot.vslam.depth_icp import (
    IcpSettings,
    ScanCloud,
    ScanMap,
    depth_cloud,
    estimate_normals,
    icp_register,
    make_scan,
    normals_complexity,
    voxel_filter,
)
from eddiebot.vslam.errors import ParameterError
from eddiebot.vslam.features import FrameFeatures
from eddiebot.vslam.odometry import VisualOdometry
from eddiebot.vslam.parameters import RtabmapParameters
from eddiebot.vslam.transforms import from_xyz_yaw, se3_inverse, yaw_of

SETTINGS = IcpSettings(point_to_plane=True, force_3dof=True, downsampling_step=4,
                       max_correspondence_distance=0.1, range_max=3.0)


def _pose_error(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    d = se3_inverse(a) @ b
    return float(np.hypot(d[0, 3], d[1, 3])), float(np.degrees(abs(yaw_of(d))))


def test_cloud_normals_and_voxels_of_a_room():
    pose = from_xyz_yaw(0.0, 0.0, 0.3)
    depth = render_room(pose)
    pts = depth_cloud(depth, CAM, step=4)
    world = pts @ pose[:3, :3].T + pose[:3, 3]
    # every point lies on one of the room's planes (mm quantisation)
    dist = np.min(np.stack([np.abs(world @ np.asarray(n) - c) for n, c in ROOM]), axis=0)
    assert np.percentile(dist, 99) < 0.01
    thinned, _ = voxel_filter(pts, 0.1)
    assert 0 < len(thinned) < len(pts)
    scan = make_scan(depth, CAM, SETTINGS)
    assert len(scan) > 200
    assert np.all(np.abs(scan.normals[:, 2]) < 0.9)  # floor and ceiling dropped under 3 DoF
    # unorganised normals of a plane: perpendicular to it, towards the viewpoint
    rng = np.random.default_rng(1)
    plane = np.column_stack([rng.uniform(0, 1, 300), rng.uniform(0, 1, 300), np.zeros(300)])
    n = estimate_normals(plane, k=8, viewpoint=np.array([0.5, 0.5, 2.0]))
    assert np.all(n[:, 2] > 0.999)


@pytest.mark.parametrize("truth_xyt", [(0.10, 0.03, 0.087), (-0.05, 0.12, -0.14)])
def test_icp_recovers_a_planar_motion_in_a_room_corner(truth_xyt):
    rng = np.random.default_rng(2)
    a = from_xyz_yaw(0.5, 0.3, 0.6)  # looking into the (2, 1.5) corner
    b = a @ from_xyz_yaw(*truth_xyt)
    ref = make_scan(render_room(a, noise=0.002, rng=rng), CAM, SETTINGS).transformed(a)
    new = make_scan(render_room(b, noise=0.002, rng=rng), CAM, SETTINGS)
    guess = b @ from_xyz_yaw(0.04, -0.03, np.radians(2.0))
    r = icp_register(ref, new, guess, SETTINGS, np.eye(6) * 1e-4)
    assert r.ok and r.free_axis is None  # two walls at right angles fix x, y and yaw
    lin, ang = _pose_error(b, r.transform)
    assert lin < 0.005 and ang < 0.1
    # upstream's RegistrationIcp covariance: translation variance v / 10, rotation v / 100
    # (v from the correspondences' scatter), which covers the error without being loose
    var = np.diag(r.covariance)
    np.testing.assert_allclose(var[3:], var[:3] / 10.0)
    sd = np.sqrt(var[[0, 1, 5]])
    assert np.all(sd[:2] < 0.01) and sd[2] < np.radians(0.3)
    assert lin < sd[0] and np.radians(ang) < sd[2]
    # a correction beyond Icp/MaxTranslation is refused, not returned
    tight = IcpSettings(**{**SETTINGS.__dict__, "max_translation": 0.02})
    assert not icp_register(ref, new, guess, tight).ok


def test_single_wall_leaves_the_shift_along_it_to_the_guess():
    wall = [((0.0, 1.0, 0.0), 1.1), ((0.0, 0.0, 1.0), 0.0)]  # a side wall 1.1 m away, floor
    a = from_xyz_yaw(0.0, 0.0, np.pi / 2)  # facing the wall
    b = a @ from_xyz_yaw(0.0, 0.0, np.radians(4.0))  # one frame of a spin
    ref = make_scan(render_room(a, wall), CAM, SETTINGS).transformed(a)
    new = make_scan(render_room(b, wall), CAM, SETTINGS)
    complexity, _ = normals_complexity(new.normals, three_dof=True)
    assert complexity < 0.02
    guess_var = 0.02**2
    guess = b.copy()
    guess[:3, 3] += (0.05, 0.03, 0.0)  # 5 cm along the wall, 3 cm towards it
    guess[:3, :3] = from_xyz_yaw(0, 0, np.pi / 2 + np.radians(5.0))[:3, :3]
    r = icp_register(ref, new, guess, SETTINGS, np.eye(6) * guess_var)
    assert r.ok and r.free_axis is not None
    assert abs(abs(r.free_axis[0]) - 1.0) < 0.01  # free: x, along the wall
    assert abs(r.transform[1, 3] - b[1, 3]) < 0.003  # distance to the wall recovered
    assert abs(np.degrees(yaw_of(r.transform) - yaw_of(b))) < 0.1  # and the heading
    # along the wall: the guess (the free axis is taken at the guess's heading, 1° off)
    assert abs(r.transform[0, 3] - guess[0, 3]) < 0.002
    cov = r.covariance
    assert cov[0, 0] >= 0.99 * guess_var  # says so: the guess's variance there
    assert cov[1, 1] < 1e-4 and cov[5, 5] < 1e-5
    # the fit's own variance (as across the wall) plus the guess's along the wall
    assert cov[0, 0] == pytest.approx(guess_var + cov[1, 1], rel=0.02)
    # Icp/PointToPlaneLowComplexityStrategy 0 rejects such geometry
    reject = IcpSettings(**{**SETTINGS.__dict__, "low_complexity_strategy": 0})
    assert not icp_register(ref, new, guess, reject).ok


def test_scan_map_subtracts_and_keeps_the_newest():
    rng = np.random.default_rng(3)
    pts = rng.uniform(0, 1, (500, 3))
    m = ScanMap(max_size=600, subtract_radius=0.05)
    cloud = ScanCloud(pts, np.tile([0.0, 0.0, 1.0], (500, 1)))
    assert m.add(cloud, 1) == 500
    assert m.add(cloud, 2) == 0  # the same points again: all within the subtract radius
    moved = ScanCloud(pts + np.array([5.0, 0.0, 0.0]), cloud.normals)
    assert m.add(moved, 3) == 500
    assert len(m) == 600 and np.sum(m.cloud.points[:, 0] > 4.0) == 500  # oldest dropped



def test_fallback_tracks_a_textureless_stretch_and_off_reports_lost():
    blank = range(10, 24)  # 1.4 s, 40° of the spin without a single feature
    on, truths = spin_in_room({**ICP_VO, "Odom/IcpFallbackInliers": "40"}, blank)
    assert all(r.pose is not None for r in on)
    assert sum(r.icp for r in on) >= len(blank)
    lin, ang = _pose_error(truths[-1], on[-1].pose)
    assert lin < 0.02 and ang < 0.5
    # the visual map re-formed: the textured frames after the stretch register visually again
    assert all(r.inliers >= 40 and not r.icp for r in on[30:])
    # the blank frames' covariance: small across the view, not the lost 9999
    assert all(np.all(np.diag(r.covariance)[[0, 1, 5]] < 1.0) for r in on[10:24])

    off, _ = spin_in_room(ICP_VO, blank)
    lost = [k for k, r in enumerate(off) if r.pose is None]
    assert set(blank) <= set(lost)
    assert all(np.all(np.diag(off[k].covariance) == 9999.0) for k in lost)


def test_reg_strategy_icp_and_vis_icp_track_thespin_in_room():
    for strategy in ("1", "2"):
        res, truths = spin_in_room({**ICP_VO, "Reg/Strategy": strategy}, range(0), frames=20)
        assert all(r.pose is not None and r.icp for r in res[1:])
        lin, ang = _pose_error(truths[-1], res[-1].pose)
        assert lin < 0.02 and ang < 0.3, strategy
    vo = VisualOdometry(RtabmapParameters.from_dict({**ICP_VO, "Reg/Strategy": "2"}))
    with pytest.raises(ParameterError):
        vo.process_features(FrameFeatures.empty(), CAM, 0)
    with pytest.raises(ParameterError):
        RtabmapParameters.from_dict({"Reg/Strategy": "3"})
