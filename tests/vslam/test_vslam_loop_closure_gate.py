"""`RGBD/LoopClosureMaxMahalanobis`: the graph-path covariance and the closure plausibility gate."""

import numpy as np
from vslam_synthetic import frame, kinect_camera, link_adjacency, planar_pose

from eddiebot.vslam.closure_check import closure_mahalanobis, path_covariance
from eddiebot.vslam.memory import Link, LinkType
from eddiebot.vslam.rtabmap import Rtabmap

CAM = kinect_camera(320, 240)
REPORT = {"RGBD/LinearUpdate": "0.05", "RGBD/ProximityBySpace": "false",
          "Reg/Force3DoF": "true", "Vis/MinInliers": "12"}


def _info(sx: float, sy: float, st: float) -> np.ndarray:
    return np.diag([1 / sx**2, 1 / sy**2, 1.0, 1.0, 1.0, 1 / st**2])


def test_path_covariance_composes_heading_into_lateral_uncertainty():
    sx, sy, st = 0.01, 0.02, 0.05
    step = planar_pose(1.0, 0.0, 0.0)
    adj = link_adjacency([Link(1, 2, LinkType.NEIGHBOR, step, _info(sx, sy, st)),
                      Link(2, 3, LinkType.NEIGHBOR, step, _info(sx, sy, st))])
    result = path_covariance(adj, 1, 3)
    assert result is not None
    pose, cov = result
    np.testing.assert_allclose(pose, [2.0, 0.0, 0.0], atol=1e-12)
    # first-order SE(2) propagation: the first link's heading error moves node 3 sideways by 1 m·δθ
    expected = np.array([[2 * sx**2, 0.0, 0.0],
                         [0.0, 2 * sy**2 + st**2, st**2],
                         [0.0, st**2, 2 * st**2]])
    np.testing.assert_allclose(cov, expected, rtol=1e-9, atol=1e-15)
    # the reverse direction has the same size of uncertainty
    back = path_covariance(adj, 3, 1)
    assert back is not None
    np.testing.assert_allclose(back[0], [-2.0, 0.0, 0.0], atol=1e-12)
    assert abs(np.trace(back[1]) - np.trace(cov)) < 1e-12
    assert path_covariance(adj, 1, 99) is None


def test_path_covariance_takes_the_least_uncertain_route():
    # a chain of 20 loose odometry links, and a tight closure straight from 1 to 21
    loose = _info(0.05, 0.05, 0.05)
    links = [Link(k, k + 1, LinkType.NEIGHBOR, planar_pose(0.1, 0.0, 0.0), loose)
             for k in range(1, 21)]
    chain = path_covariance(link_adjacency(links), 1, 21)
    tight = Link(21, 1, LinkType.GLOBAL_CLOSURE, planar_pose(-2.0, 0.0, 0.0),
                 _info(0.01, 0.01, 0.01))
    short = path_covariance(link_adjacency([*links, tight]), 1, 21)
    assert chain is not None and short is not None
    assert np.trace(short[1]) < 0.01 * np.trace(chain[1])
    np.testing.assert_allclose(short[0], [2.0, 0.0, 0.0], atol=1e-9)


def test_closure_mahalanobis_scores_consistent_and_jumping_closures():
    info = _info(0.02, 0.02, 0.01)
    adj = link_adjacency([Link(k, k + 1, LinkType.NEIGHBOR, planar_pose(0.5, 0.0, 0.0), info)
                      for k in range(1, 11)])
    here, there = planar_pose(5.0, 0.0, 0.0), planar_pose(0.0, 0.0, 0.0)
    closure_info = _info(0.01, 0.01, 0.005)
    good = Link(11, 1, LinkType.GLOBAL_CLOSURE, planar_pose(-5.02, 0.03, 0.01), closure_info)
    bad = Link(11, 1, LinkType.GLOBAL_CLOSURE, planar_pose(-2.5, 1.0, 0.6), closure_info)
    d_good = closure_mahalanobis(good, here, there, adj)
    d_bad = closure_mahalanobis(bad, here, there, adj)
    assert d_good is not None and d_bad is not None
    assert d_good < 1.5
    assert d_bad > 10.0


def test_gate_rejects_a_closure_far_from_the_odometry_prediction():
    # Odometry (default variance 0.001) says the robot is 3 m from the first node while the
    # image is node 1's view: with RGBD/OptimizeMaxError off, only the gate can refuse it.
    def run(gate: str) -> tuple[Rtabmap, object]:
        slam = Rtabmap({**REPORT, "Mem/STMSize": "2", "Rtabmap/LoopThr": "0.05",
                        "RGBD/OptimizeMaxError": "0", "RGBD/LoopClosureMaxMahalanobis": gate})
        for k in range(5):
            slam.process(*frame(3, 2.0 + 0.3 * k, 3.0, 0.0), CAM, planar_pose(0.3 * k, 0, 0),
                         k * 1_000_000_000)
        r = slam.process(*frame(3, 2.0, 3.0, 0.0), CAM, planar_pose(4.2, 0.0, 0.0),
                         5_000_000_000)
        return slam, r

    _, off = run("0")
    assert off.loop_closure_id == 1  # type: ignore[attr-defined]
    slam, on = run("4")
    assert on.loop_closure_id == 0  # type: ignore[attr-defined]
    assert on.rejected_loop_id == 1  # type: ignore[attr-defined]
    assert "LoopClosureMaxMahalanobis" in on.rejection_reason  # type: ignore[attr-defined]
    _, links = slam.graph()
    touching = [lk for lk in links if on.node_id in (lk.from_id, lk.to_id)]  # type: ignore[attr-defined]
    assert [lk.type for lk in touching] == [LinkType.NEIGHBOR]


def test_gate_keeps_a_closure_that_agrees_with_odometry():
    slam = Rtabmap({**REPORT, "Mem/STMSize": "2", "Rtabmap/LoopThr": "0.05",
                    "RGBD/LoopClosureMaxMahalanobis": "4"})
    for k in range(5):
        slam.process(*frame(3, 2.0 + 0.3 * k, 3.0, 0.0), CAM, planar_pose(0.3 * k, 0, 0),
                     k * 1_000_000_000)
    # back at the start with 3 cm of odometry drift: plausible, accepted
    r = slam.process(*frame(3, 2.0, 3.0, 0.0), CAM, planar_pose(0.03, 0.0, 0.0), 5_000_000_000)
    assert r.loop_closure_id == 1


def test_loop_cov_limited_caps_closure_information_at_odometry():
    def closure_info(limited: str) -> np.ndarray:
        slam = Rtabmap({**REPORT, "Mem/STMSize": "2", "Rtabmap/LoopThr": "0.05",
                        "RGBD/LoopCovLimited": limited})
        cov = np.diag([1e-2, 1e-2, 1e-2, 1e-3, 1e-3, 1e-3])
        for k in range(5):
            slam.process(*frame(3, 2.0 + 0.3 * k, 3.0, 0.0), CAM, planar_pose(0.3 * k, 0, 0),
                         k * 1_000_000_000, odom_covariance=cov)
        r = slam.process(*frame(3, 2.0, 3.0, 0.0), CAM, planar_pose(0.02, 0.0, 0.0),
                         5_000_000_000, odom_covariance=cov)
        assert r.loop_closure_id == 1
        _, links = slam.graph()
        closure = next(lk for lk in links if lk.type == LinkType.GLOBAL_CLOSURE
                       and r.node_id in (lk.from_id, lk.to_id))
        return np.diag(closure.information)

    free = closure_info("false")
    capped = closure_info("true")
    assert free[0] > 1000.0 and free[5] > 1e4  # registration alone: mm / sub-mrad
    np.testing.assert_allclose(capped[[0, 1, 2]], 100.0)
    np.testing.assert_allclose(capped[[5]], 1000.0)


def test_pnp_jacobian_covariance_grows_along_the_unconstrained_direction():
    from eddiebot.vslam.registration import pnp_jacobian_covariance

    rng = np.random.default_rng(3)
    lt = CAM.local_transform
    # inliers straight ahead (base x forward): a narrow cluster on one wall 3 m away, or
    # points spread over the view between 1 and 5 m
    narrow = np.column_stack([np.full(40, 3.0), rng.uniform(-0.15, 0.15, 40),
                              rng.uniform(0.2, 0.5, 40)])
    spread = np.column_stack([rng.uniform(1.0, 5.0, 40), rng.uniform(-1.0, 1.0, 40),
                              rng.uniform(0.0, 1.0, 40)])
    link = planar_pose(-0.2, 0.05, 0.1)  # pose of the old frame in the new one

    def uv_of(points: np.ndarray) -> np.ndarray:
        from eddiebot.vslam.transforms import se3_inverse

        m = se3_inverse(lt) @ link
        pc = points @ m[:3, :3].T + m[:3, 3]
        return np.column_stack([CAM.fx * pc[:, 0] / pc[:, 2] + CAM.cx,
                                CAM.fy * pc[:, 1] / pc[:, 2] + CAM.cy]).astype(np.float32)

    var_narrow = np.diag(pnp_jacobian_covariance(link, narrow, uv_of(narrow), CAM, True))
    var_spread = np.diag(pnp_jacobian_covariance(link, spread, uv_of(spread), CAM, True))
    # exact projections: the 0.5 px floor sets the scale; out-of-plane axes are left at 0
    assert np.all(var_narrow[[2, 3, 4]] == 0.0) and np.all(var_spread[[0, 1, 5]] > 0.0)
    # one cluster at one depth: sideways shift and yaw trade off, both far less certain
    assert var_narrow[1] > 20 * var_spread[1]
    assert var_narrow[5] > 20 * var_spread[5]
    # the spread case is well constrained: yaw to ~0.1°
    assert np.sqrt(var_spread[5]) < np.deg2rad(0.1)
    # noisy pixels raise the variances through the residual
    noisy = uv_of(spread) + rng.normal(0, 3.0, (40, 2)).astype(np.float32)
    var_noisy = np.diag(pnp_jacobian_covariance(link, spread, noisy, CAM, True))
    assert var_noisy[5] > 10 * var_spread[5]
