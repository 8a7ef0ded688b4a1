"""Loop closure whatever the odometry: with ICP odometry (`Reg/Strategy` 1, no visual features)
the memory still extracts its own `Kp/` features, so nodes have words, the database holds them
and revisits close loops; loop-closure registration with `Reg/Strategy` 1 is visual for the
guess, then ICP on the nodes' depth (as upstream's `Memory::computeTransform`)."""

import sqlite3

import numpy as np
from scipy.spatial import cKDTree
from vslam_synthetic import frame, kinect_camera, planar_pose

from eddiebot.vslam.database import SessionDatabase
from eddiebot.vslam.depth_icp import icp_register, make_scan
from eddiebot.vslam.memory import LinkType
from eddiebot.vslam.odometry import VisualOdometry
from eddiebot.vslam.parameters import RtabmapParameters
from eddiebot.vslam.rtabmap import Rtabmap
from eddiebot.vslam.transforms import se3_inverse, yaw_of

CAM = kinect_camera(320, 240)
ICP = {"Reg/Strategy": "1", "Reg/Force3DoF": "true", "Icp/PointToPlane": "true",
       "Icp/DownsamplingStep": "2", "Icp/MaxCorrespondenceDistance": "0.1",
       "Icp/RangeMax": "0", "OdomF2M/ScanMaxSize": "10000", "Vis/MinInliers": "12",
       "RGBD/LinearUpdate": "0.05", "RGBD/ProximityBySpace": "false"}


def _out_and_back(step: float = 0.1, length: float = 1.2) -> list[float]:
    n = round(length / step)
    return [k * step for k in range(n + 1)] + [k * step for k in range(n - 1, -1, -1)]


def _run(tmp_path, params):
    """ICP odometry + SLAM on an out-and-back route in the textured box room; per frame the
    SLAM result and the odometry's feature count."""
    p = RtabmapParameters.from_dict(params)
    vo = VisualOdometry(p)
    results, odom_features = [], []
    with SessionDatabase(tmp_path / "icp.db") as db:
        slam = Rtabmap(p, database=db)
        for k, x in enumerate(_out_and_back()):
            rgb, depth = frame(3, 2.0 + x, 1.5, 0.0)
            stamp = k * 100_000_000
            odom = vo.process(rgb, depth, CAM, stamp)
            assert odom.pose is not None, f"ICP odometry lost frame {k}"
            odom_features.append(odom.features)
            results.append(slam.process(rgb, depth, CAM, odom.pose, stamp,
                                        odom_covariance=odom.covariance,
                                        features=odom.frame_features))
    return slam, results, odom_features


def test_icp_odometry_keeps_words_and_closes_loops(tmp_path):
    slam, results, odom_features = _run(tmp_path, ICP)
    assert max(odom_features) == 0  # the odometry extracted no visual features
    kept = [r for r in results if r.added]
    assert all(r.statistics["Keypoint/Current_frame/words"] >= 100 for r in kept)
    loops = [r.loop_closure_id for r in results[len(results) // 2 + 3:]]
    assert sum(1 for lc in loops if lc) >= 3
    with sqlite3.connect(tmp_path / "icp.db") as con:
        words = con.execute("SELECT COUNT(*) FROM Word").fetchone()[0]
        features = con.execute("SELECT COUNT(*) FROM Feature WHERE word_id > 0").fetchone()[0]
        closures = con.execute("SELECT COUNT(*) FROM Link WHERE type = ?",
                               (int(LinkType.GLOBAL_CLOSURE),)).fetchone()[0]
    assert words >= 500 and features >= 100 * len(kept)
    assert closures == sum(1 for r in results if r.loop_closure_id)
    # every closure agrees with the true geometry (the route's frames are exact renders)
    xs = _out_and_back()
    ids = {r.node_id: xs[k] for k, r in enumerate(results) if r.added}
    for link in slam.memory.unique_links():
        if link.type == LinkType.GLOBAL_CLOSURE:
            a, b = sorted((link.from_id, link.to_id))
            t = link.transform if link.from_id == a else se3_inverse(link.transform)
            truth = ids[b] - ids[a]
            assert abs(t[0, 3] - truth) < 0.01 and abs(t[1, 3]) < 0.01


def test_loop_closure_registration_with_reg_strategy_1_is_refined_by_icp():
    p = RtabmapParameters.from_dict({**ICP, "Mem/STMSize": "1"})
    slam = Rtabmap(p)
    old_rgb, old_depth = frame(3, 2.0, 3.0, 0.0)
    new_rgb, new_depth = frame(3, 2.15, 3.04, 0.05)
    slam.process(old_rgb, old_depth, CAM, planar_pose(0, 0, 0), 0)
    slam.process(new_rgb, new_depth, CAM, planar_pose(0.15, 0.04, 0.05), 1)
    old, new = slam.memory.nodes[1], slam.memory.nodes[2]
    verified = slam._verify(old, new, CAM, LinkType.GLOBAL_CLOSURE)
    assert verified.link is not None
    # the link is ICP's result from the visual guess, on clouds rebuilt from each node's depth
    assert old.data is not None and new.data is not None
    a, b = old.data.cloud, new.data.cloud
    assert a is not None and b is not None
    icp = icp_register(make_scan(a.depth(), a.camera, slam._icp),
                       make_scan(b.depth(), b.camera, slam._icp),
                       se3_inverse(verified.link.transform), slam._icp)
    assert icp.transform is not None
    np.testing.assert_allclose(se3_inverse(verified.link.transform), icp.transform, atol=1e-3)
    # covariance as upstream's RegistrationIcp: 2.1981 · median squared correspondence
    # distance / 10 on every axis, a tenth of that on the rotations
    t = icp.transform
    source = make_scan(b.depth(), b.camera, slam._icp)
    target = make_scan(a.depth(), a.camera, slam._icp)
    d, _ = cKDTree(target.points).query(source.points @ t[:3, :3].T + t[:3, 3],
                                        distance_upper_bound=0.1)
    var = 2.1981 * np.median(d[np.isfinite(d)] ** 2) / 10
    assert 1e-8 < var < 1e-3  # voxel-sampled clouds: correspondences a few cm apart
    np.testing.assert_allclose(np.diag(verified.link.information),
                               [1 / var] * 3 + [10 / var] * 3, rtol=0.05)
    assert np.count_nonzero(verified.link.information - np.diag(np.diag(
        verified.link.information))) == 0
    t = se3_inverse(verified.link.transform)  # new node in the old one's frame
    assert abs(t[0, 3] - 0.15) < 0.01 and abs(t[1, 3] - 0.04) < 0.01
    assert abs(yaw_of(t) - 0.05) < np.radians(0.5)


def test_odometry_features_are_reused_unless_mem_use_odom_features_is_false():
    p = RtabmapParameters.from_dict({"Vis/MinInliers": "12"})
    rgb, depth = frame(3, 2.0, 3.0, 0.0)
    vo = VisualOdometry(p)
    odom = vo.process(rgb, depth, CAM, 0)
    assert odom.frame_features is not None and len(odom.frame_features) > 0
    few = odom.frame_features.subset(np.arange(40))
    reused = Rtabmap(p).process(rgb, depth, CAM, np.eye(4), 0, features=few)
    assert reused.statistics["Keypoint/Current_frame/words"] == 40
    own = Rtabmap(RtabmapParameters.from_dict({"Vis/MinInliers": "12",
                                               "Mem/UseOdomFeatures": "false"}))
    r = own.process(rgb, depth, CAM, np.eye(4), 0, features=few)
    assert r.statistics["Keypoint/Current_frame/words"] > 100
