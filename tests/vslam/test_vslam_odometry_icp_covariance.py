"""ICP registration covariance as upstream's `RegistrationIcp` computes it
(`util3d::computeVarianceAndCorrespondences`: 2.1981 · the median squared distance of the
reciprocal correspondences, / 10 on translation, / 100 on rotation), checked on real frames:
the σ an ICP odometry link claims must cover its actual error (the fit's σ² (JᵀJ)⁻¹ claimed
5–20× too little), and a forward-backward revisit with ICP odometry closes its loops. (On the
whole ICL sequence played forward and back, `benchmarks/bench_vslam_icl.py --runs fb_icp`,
`RGBD/OptimizeMaxError` then rejects 24 closures instead of 161.)"""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from icl_data import ICL, ICL_DEPTH_SCALE, needs_icl, read_redwood_log, write_icl_tum

from eddiebot.vslam.depth_icp import (
    IcpSettings,
    ScanCloud,
    correspondence_variance,
    icp_covariance,
    registration_covariance,
)
from eddiebot.vslam.odometry import VisualOdometry
from eddiebot.vslam.parameters import RtabmapParameters
from eddiebot.vslam.rtabmap import Rtabmap
from eddiebot.vslam.transforms import rotation_angle, se3_inverse
from eddiebot.vslam.tum import absolute_trajectory_error, load_tum_frame, read_tum_sequence

TUM_DESK = Path("/work/shared/datasets/rgbd/tum_fr1_desk_9frames")
needs_tum = pytest.mark.skipif(not (TUM_DESK / "rgb.txt").is_file(),
                               reason=f"TUM fr1/desk frames not found at {TUM_DESK}")
#: the ICL benchmark's `fb_icp` profile: ICP odometry, no visual features in it
ICP_ODOMETRY = {"Reg/Strategy": "1", "Icp/PointToPlane": "true", "Icp/DownsamplingStep": "4"}


def test_variance_is_upstreams_median_rule_over_reciprocal_pairs():
    d = np.array([0.001, 0.002, 0.003, 0.004, 0.040])
    # PCL's median: the element at size >> 1 of the sorted squared distances
    assert correspondence_variance(d) == pytest.approx(2.1981 * 0.003**2)
    assert correspondence_variance(np.full(7, 1e-5)) == pytest.approx(1e-5)  # (1 mm)² / 10 floor
    cov = icp_covariance(d)
    np.testing.assert_allclose(np.diag(cov), 2.1981 * 0.003**2 * np.array([0.1] * 3 + [0.01] * 3))
    # reciprocal pairs only: two source points near one target point count once (the nearer)
    up = np.tile([0.0, 0.0, 1.0], (4, 1))
    target = ScanCloud(np.array([[0.0, 0, 0], [1.0, 0, 0], [2.0, 0, 0], [3.0, 0, 0]]), up)
    source = ScanCloud(np.array([[0.0, 0, 0.001], [1.0, 0, 0.002], [2.0, 0, 0.003],
                                 [3.0, 0, 0.004], [3.0, 0, 0.03], [2.0, 0, 0.035]]),
                       np.tile(up[:1], (6, 1)))
    settings = IcpSettings(max_correspondence_distance=0.05)
    var = registration_covariance(target, source, np.eye(4), settings)[0, 0] * 10
    assert var == pytest.approx(2.1981 * 0.003**2)  # the 3 and 3.5 cm pairs are not reciprocal
    lax = IcpSettings(max_correspondence_distance=0.05, reciprocal_correspondences=False)
    assert registration_covariance(target, source, np.eye(4), lax)[0, 0] * 10 == pytest.approx(
        2.1981 * 0.004**2)


def _sigma_ratios(folder: Path, depth_scale: float,
                  truth: list[np.ndarray] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Per consecutive frame pair of an ICP odometry run: the largest axis error of the base's
    motion over the smallest σ the covariance claims for it, and the rotation error over the
    angular σ (`RGBD/OptimizeMaxError`'s ratios)."""
    seq = read_tum_sequence(folder)
    vo = VisualOdometry(RtabmapParameters.from_dict(ICP_ODOMETRY))
    lt = seq.camera.local_transform
    poses, covs = [], []
    for f in seq.frames:
        rgb, depth = load_tum_frame(f, depth_scale)
        o = vo.process(rgb, depth, seq.camera, round(f.stamp * 1e9))
        assert o.pose is not None
        poses.append(o.pose)
        covs.append(o.covariance)
    if truth is None:  # the ground truth nearest each frame's stamp (camera optical frame)
        stamps = np.asarray(seq.groundtruth_stamps)
        truth = [seq.groundtruth_poses[int(np.argmin(np.abs(stamps - f.stamp)))]
                 for f in seq.frames]
    base_truth = [t @ se3_inverse(lt) for t in truth]
    lin, ang = [], []
    for k in range(1, len(poses)):
        moved = se3_inverse(poses[k - 1]) @ poses[k]
        true_move = se3_inverse(base_truth[k - 1]) @ base_truth[k]
        error = se3_inverse(true_move) @ moved
        sigma = np.sqrt(np.diag(covs[k]))
        lin.append(np.max(np.abs(error[:3, 3])) / np.min(sigma[:3]))
        ang.append(rotation_angle(error) / np.min(sigma[3:]))
    return np.array(lin), np.array(ang)


@needs_icl
def test_icp_odometry_sigma_covers_its_error_on_icl_ground_truth(tmp_path: Path):
    truth = read_redwood_log(ICL / "gt_livingroom1_frames0-4_from_open3d_TestData.log")
    lin, ang = _sigma_ratios(write_icl_tum(tmp_path, range(5)), ICL_DEPTH_SCALE, truth)
    # errors 0.2–0.5 mm and 0.01°: within σ (the fit's covariance: 4–11 σ linear)
    assert lin.max() < 1.0 and ang.max() < 1.0


@needs_tum
def test_icp_odometry_sigma_covers_its_error_on_real_kinect_frames():
    # TUM fr1/desk (hand-held, ≈ 0.4° and 4 mm of ICP error per frame at 30 Hz)
    lin, ang = _sigma_ratios(TUM_DESK, 5000.0)
    assert len(lin) == 8
    assert lin.max() < 1.0  # the fit's covariance: 7–20 σ
    # upstream's rotation rule (the translation's variance / 10) still claims ≈ 3× too little
    # here (the fit's: ≈ 12×)
    assert np.median(ang) < 4.0


@needs_icl
def test_forward_backward_with_icp_odometry_closes_every_revisit(tmp_path: Path):
    out = list(range(60))
    seq = read_tum_sequence(write_icl_tum(tmp_path, out + out[::-1][1:]))  # 119 frames
    params = RtabmapParameters.from_dict(
        {"RGBD/LinearUpdate": "0", "RGBD/AngularUpdate": "0", **ICP_ODOMETRY})
    vo, slam = VisualOdometry(params), Rtabmap(params)
    closed, rejected = 0, Counter[str]()
    odom, node_of = {}, {}
    for k, f in enumerate(seq.frames):
        rgb, depth = load_tum_frame(f, ICL_DEPTH_SCALE)
        o = vo.process(rgb, depth, seq.camera, round(f.stamp * 1e9))
        assert o.pose is not None
        odom[k] = o.pose
        r = slam.process(rgb, depth, seq.camera, o.pose, round(f.stamp * 1e9),
                         odom_covariance=o.covariance, features=o.frame_features)
        node_of[k] = r.node_id
        closed += bool(r.loop_closure_id or r.proximity_id)
        if r.rejected_loop_id:
            rejected[r.rejection_reason] += 1
    assert not rejected, rejected
    assert closed >= 100  # 109 of 118 frames link to an earlier node
    graph, _ = slam.graph()
    lt = seq.camera.local_transform
    stamps = np.array([f.stamp for f in seq.frames])

    def ate(p: dict[int, np.ndarray]) -> float:
        return absolute_trajectory_error(stamps, np.array([p[k] @ lt for k in sorted(p)]),
                                         seq.groundtruth_stamps, seq.groundtruth_poses)[0]

    slam_ate = ate({k: graph[n] for k, n in node_of.items()})
    assert slam_ate < 0.0045  # 3.9 mm (the fit's covariance: 5.0 mm)
    assert slam_ate < ate(odom)
