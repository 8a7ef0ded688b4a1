import numpy as np
import pytest

from eddiebot.vslam.graph import GraphLink, GtsamPoseGraph, link_errors
from eddiebot.vslam.transforms import from_xyz_rpy, from_xyz_yaw, se3_inverse


def _square(drift: float):
    truth = [from_xyz_yaw(0, 0, 0), from_xyz_yaw(1, 0, np.pi / 2), from_xyz_yaw(1, 1, np.pi),
             from_xyz_yaw(0, 1, -np.pi / 2)]
    info = np.diag([100.0, 100.0, 1e-6, 1e-6, 1e-6, 400.0])
    links = []
    for k in range(3):
        t = se3_inverse(truth[k]) @ truth[k + 1]
        t[0, 3] += drift  # odometry overshoots
        links.append(GraphLink(k + 1, k + 2, t, info))
    # exact loop closure 4 → 1
    links.append(GraphLink(4, 1, se3_inverse(truth[3]) @ truth[0], info * 10))
    initial = {1: truth[0]}
    for k, lk in enumerate(links[:3]):
        initial[k + 2] = initial[k + 1] @ lk.transform
    return truth, links, initial


@pytest.mark.parametrize("three_dof", [True, False])
def test_loop_closure_pulls_drifted_square_back(three_dof):
    truth, links, initial = _square(0.1)
    out = GtsamPoseGraph(three_dof).optimize(initial, links, root_id=1, iterations=50)
    before = np.linalg.norm(initial[4][:3, 3] - truth[3][:3, 3])
    after = np.linalg.norm(out[4][:3, 3] - truth[3][:3, 3])
    assert after < before / 3
    np.testing.assert_allclose(out[1], truth[0], atol=1e-6)  # root fixed


def test_link_errors_flag_an_inconsistent_link():
    truth, links, _ = _square(0.0)
    poses = dict(enumerate(truth, start=1))
    errs = link_errors(poses, links)
    assert max(max(e.linear_ratio, e.angular_ratio) for e in errs) < 1e-6
    bad = GraphLink(1, 3, from_xyz_rpy(3.0, 0, 0, 0, 0, 0), np.eye(6) * 100)
    e = link_errors(poses, [bad])[0]
    assert e.linear_ratio > 10  # (3 − 1) m away with σ = 0.1 m


def test_icp_2d_recovers_a_small_offset_of_a_corner_scan():
    from eddiebot.vslam.icp import icp_2d

    wall_a = np.stack([np.full(80, 2.0), np.linspace(-1.5, 1.5, 80)], axis=1)
    wall_b = np.stack([np.linspace(0.2, 2.0, 60), np.full(60, 1.5)], axis=1)
    reference = np.concatenate([wall_a, wall_b])
    x, y, th = 0.08, -0.05, 0.04
    c, s = np.cos(th), np.sin(th)
    # the same walls seen from the pose (x, y, th): p_scan = R^T (p_ref - t)
    scan = (reference - [x, y]) @ np.array([[c, -s], [s, c]])
    result = icp_2d(reference, scan, np.zeros(3))
    assert result is not None
    # point-to-point ICP on 3–4 cm sample spacing: centimetre-level, not exact
    assert abs(result.x - x) < 0.02 and abs(result.y - y) < 0.02
    assert abs(result.theta - th) < 0.01
    exact = icp_2d(reference, scan, np.array([x, y, th]))
    assert exact is not None and abs(exact.x - x) < 1e-6
    # no correspondences within 0.2 m of a far guess: refused, never a made-up result
    assert icp_2d(reference, scan, np.array([5.0, 5.0, 0.0])) is None
