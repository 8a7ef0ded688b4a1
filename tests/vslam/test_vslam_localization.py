"""Localization mode without jumps: the odometry cache (`RGBD/MaxOdomCacheSize`) checks every
localization against the odometry since the earlier ones (`RGBD/OptimizeMaxError`)."""

import numpy as np
from vslam_synthetic import frame, kinect_camera, planar_pose

from eddiebot.vslam.database import SessionDatabase
from eddiebot.vslam.graph import GraphLink
from eddiebot.vslam.localization import OdometryCache
from eddiebot.vslam.rtabmap import Rtabmap
from eddiebot.vslam.transforms import se3_inverse

CAM = kinect_camera(320, 240)
PARAMS = {"RGBD/LinearUpdate": "0.05", "RGBD/ProximityBySpace": "false",
          "Reg/Force3DoF": "true", "Vis/MinInliers": "12"}
ODOM_INFO = np.diag([1e4, 1e4, 1e4, 1e4, 1e4, 1e4])  # 1 cm, 0.01 rad per step
LINK_INFO = np.diag([1e4, 1e4, 1e4, 1e4, 1e4, 1e4])
MAP = {1: planar_pose(0.0, 0.0, 0.0), 2: planar_pose(1.0, 0.0, 0.0)}


def _link(true_pose, node):
    """A localization link from a frame at `true_pose` to map node `node`."""
    return GraphLink(0, node, se3_inverse(true_pose) @ MAP[node], LINK_INFO)


def test_consistent_localizations_are_accepted_and_a_jump_is_rejected():
    cache = OdometryCache(10, True, max_error=3.0)
    # odometry starts 2 m off the map frame; the robot is truly at x = 0.2
    offset = planar_pose(2.0, -1.0, 0.5)
    cache.add(offset @ planar_pose(0.2, 0, 0), ODOM_INFO)
    first = cache.localize([_link(planar_pose(0.2, 0, 0), 1)], MAP)
    assert first.pose is not None
    np.testing.assert_allclose(first.pose[:2, 3], [0.2, 0.0], atol=1e-6)
    # 0.3 m further by odometry, and a localization that agrees (within 5 mm)
    cache.add(offset @ planar_pose(0.5, 0, 0), ODOM_INFO)
    second = cache.localize([_link(planar_pose(0.505, 0, 0), 2)], MAP)
    assert second.pose is not None and second.max_error < 3.0
    assert abs(second.pose[0, 3] - 0.5) < 0.01
    # then one 0.4 m away from where the odometry (σ 1 cm) puts the robot: rejected
    cache.add(offset @ planar_pose(0.6, 0, 0), ODOM_INFO)
    jump = cache.localize([_link(planar_pose(1.0, 0, 0), 2)], MAP)
    assert jump.pose is None and "RGBD/OptimizeMaxError" in jump.reason and jump.max_error > 3
    assert cache.localizations == 2  # the rejected link is not kept


def test_the_first_localization_has_nothing_to_contradict_it():
    cache = OdometryCache(10, True)
    cache.add(planar_pose(5.0, 5.0, 1.0), ODOM_INFO)
    check = cache.localize([_link(planar_pose(0.7, 0.1, 0.2), 2)], MAP)
    assert check.pose is not None
    np.testing.assert_allclose(check.pose, planar_pose(0.7, 0.1, 0.2), atol=1e-6)
    np.testing.assert_allclose(np.diag(check.covariance), 1e-4, rtol=1e-6)


def test_old_localizations_leave_the_cache():
    cache = OdometryCache(3, True)
    cache.add(planar_pose(0.0, 0, 0), ODOM_INFO)
    assert cache.localize([_link(planar_pose(0.0, 0, 0), 1)], MAP).pose is not None
    for k in range(1, 4):
        cache.add(planar_pose(0.1 * k, 0, 0), ODOM_INFO)
    assert len(cache) == 3 and cache.localizations == 0
    # with nothing left to contradict it, a far localization is accepted
    assert cache.localize([_link(planar_pose(1.0, 0, 0), 2)], MAP).pose is not None


def _saved_map(path):
    with SessionDatabase(path, delete_on_start=True) as db:
        slam = Rtabmap(PARAMS, database=db)
        for k in range(6):
            slam.process(*frame(3, 2.0 + 0.2 * k, 3.0, 0.0), CAM, planar_pose(0.2 * k, 0, 0),
                         k * 1_000_000_000)
        db.close(slam)


def _localizer(path, **extra):
    db = SessionDatabase(path)
    params = {**PARAMS, "Mem/IncrementalMemory": "false", "Rtabmap/LoopThr": "0.05",
              "RGBD/LinearUpdate": "0", "RGBD/AngularUpdate": "0", **extra}
    return db, Rtabmap(params, database=db)


def test_map_to_odom_does_not_follow_a_localization_the_odometry_contradicts(tmp_path):
    _saved_map(tmp_path / "map.db")
    tight = np.diag([1e-4] * 6)
    db, loc = _localizer(tmp_path / "map.db")
    try:
        # standing at x = 0.4 (room 2.4 m) for three frames: localized, map→odom settles
        results = [loc.process(*frame(3, 2.4, 3.0, 0.0), CAM, planar_pose(0.0, 0, 0), k,
                               odom_covariance=tight) for k in range(3)]
        assert results[-1].localized
        settled = loc.map_to_odom.copy()
        np.testing.assert_allclose(results[-1].pose[:2, 3], [0.4, 0.0], atol=0.02)
        # the odometry then claims 0.3 m of motion (σ 1 cm) while the images show none: the
        # localizations say the robot stayed, which the odometry contradicts by 30 σ
        r = loc.process(*frame(3, 2.4, 3.0, 0.0), CAM, planar_pose(0.3, 0, 0), 3,
                        odom_covariance=tight)
        assert r.rejected_loop_id and "OptimizeMaxError" in r.rejection_reason
        np.testing.assert_allclose(loc.map_to_odom, settled, atol=1e-9)  # no jump
    finally:
        db.close()
    # without the cache (RGBD/MaxOdomCacheSize 0) the same localization moves map→odom
    db, loc = _localizer(tmp_path / "map.db", **{"RGBD/MaxOdomCacheSize": "0"})
    try:
        for k in range(3):
            loc.process(*frame(3, 2.4, 3.0, 0.0), CAM, planar_pose(0.0, 0, 0), k,
                        odom_covariance=tight)
        r = loc.process(*frame(3, 2.4, 3.0, 0.0), CAM, planar_pose(0.3, 0, 0), 3,
                        odom_covariance=tight)
        assert r.loop_closure_id and not r.rejected_loop_id
        # pose x 0.4 with odometry x 0.3: map→odom jumped from 0.4 to 0.1
        assert abs(loc.map_to_odom[0, 3] - 0.1) < 0.03
    finally:
        db.close()
