"""Lost odometry starts a new map in the same session; a loop closure between maps merges
them (RTAB-Map's multi-session / multi-map behaviour)."""

import numpy as np
from vslam_synthetic import frame, kinect_camera, planar_pose

from eddiebot.vslam.database import SessionDatabase
from eddiebot.vslam.rtabmap import Rtabmap

CAM = kinect_camera(320, 240)
PARAMS = {"RGBD/LinearUpdate": "0.05", "RGBD/ProximityBySpace": "false",
          "Reg/Force3DoF": "true", "Vis/MinInliers": "12", "Mem/STMSize": "2"}
LOST = np.diag([9999.0] * 6)
#: where the re-initialised odometry puts the robot, relative to the truth
OFFSET = planar_pose(0.5, 0.4, 0.3)
#: out along x in room 3, the odometry reset at 1.5 m, three frames in room 5 (nothing to close
#: a loop with), then back along x in room 3
ROUTE = [(3, 0.0), (3, 0.3), (3, 0.6), (3, 0.9), (3, 1.2), (3, 1.5),
         (5, 1.5), (5, 1.3), (5, 1.1), (3, 0.9), (3, 0.6), (3, 0.3)]
RESET_AT = 6


def _run(slam, route=ROUTE, start=0):
    results = []
    for k, (seed, x) in enumerate(route[start:], start):
        truth = planar_pose(x, 0.0, 0.0)
        odom = truth if k < RESET_AT else OFFSET @ truth
        cov = LOST if k == RESET_AT else None
        results.append(slam.process(*frame(seed, 2.0 + x, 3.0, 0.0), CAM, odom,
                                    k * 1_000_000_000, odom_covariance=cov))
    return results


def test_lost_odometry_starts_a_map_in_its_own_frame_and_a_loop_merges_it():
    slam = Rtabmap(PARAMS)
    results = _run(slam)
    reset = results[RESET_AT]
    assert reset.new_map and reset.map_id == 1 and results[RESET_AT - 1].map_id == 0
    # no odometry link across the reset: the jump is not welded into the map
    assert reset.node_id not in slam.memory.links.get(results[RESET_AT - 1].node_id, {})
    np.testing.assert_allclose(reset.map_to_odom, np.eye(4), atol=1e-9)
    # the new map's frames see another room: still two maps, each in its own frame
    assert not any(r.maps_merged for r in results[:RESET_AT + 3])
    merge = next(r for r in results if r.maps_merged)
    assert merge.loop_closure_id and slam.frame_of(merge.loop_closure_id) == 0
    assert list(slam.map_frames()) == [0]
    # every node, old map and new, where it truly is in the first map's frame
    poses, _ = slam.graph()
    for (_, x), r in zip(ROUTE, results):
        if r.added:
            np.testing.assert_allclose(poses[r.node_id][:2, 3], [x, 0.0], atol=0.03)
    # map→odom undoes the re-initialised odometry's offset
    np.testing.assert_allclose(results[-1].map_to_odom, np.linalg.inv(OFFSET), atol=0.03)


def test_maps_stay_apart_until_merged():
    slam = Rtabmap(PARAMS)
    results = _run(slam, ROUTE[:RESET_AT + 3])
    frames = slam.map_frames()
    assert sorted(frames) == [0, 1]
    new_ids = [r.node_id for r in results[RESET_AT:] if r.added]
    assert frames[1] == new_ids
    # the new map's poses are its odometry (map→odom identity in its frame; a loop within it
    # moves them by millimetres), not moved into the old map's frame
    poses, _ = slam.graph()
    for r in results[RESET_AT:]:
        if r.added:
            np.testing.assert_allclose(poses[r.node_id],
                                       slam.memory.nodes[r.node_id].odom_pose, atol=0.01)
    assert slam.current_frame == 1


def test_identity_odometry_after_motion_is_a_reset():
    slam = Rtabmap(PARAMS)
    a = slam.process(*frame(3, 2.0, 3.0, 0.0), CAM, planar_pose(0.0, 0, 0), 0)
    b = slam.process(*frame(3, 2.3, 3.0, 0.0), CAM, planar_pose(0.3, 0, 0), 1)
    c = slam.process(*frame(3, 2.6, 3.0, 0.0), CAM, np.eye(4), 2)
    assert (a.map_id, b.map_id, c.map_id) == (0, 0, 1) and c.new_map


def test_unmerged_maps_reload_in_their_own_frames(tmp_path):
    with SessionDatabase(tmp_path / "m.db", delete_on_start=True) as db:
        _run(Rtabmap(PARAMS, database=db), ROUTE[:RESET_AT + 3])
    with SessionDatabase(tmp_path / "m.db") as db:
        slam = Rtabmap({**PARAMS, "Mem/InitWMWithAllNodes": "true"}, database=db)
        assert slam.frame_of(1) == 0 and slam.frame_of(RESET_AT + 1) == 1
        assert slam.map_id == 2 and slam.current_frame == 2


def test_export_writes_one_file_per_unmerged_map(tmp_path, capsys):
    import argparse

    from eddiebot.cli import vslam as cli
    from eddiebot.vslam.tum import read_tum_trajectory

    with SessionDatabase(tmp_path / "m.db", delete_on_start=True) as db:
        _run(Rtabmap({**PARAMS, "RGBD/CreateOccupancyGrid": "true"}, database=db),
             ROUTE[:RESET_AT + 3])
    parser = argparse.ArgumentParser()
    cli.add_arguments(parser)
    args = parser.parse_args(["db", "export", str(tmp_path / "m.db"), "--ply",
                              str(tmp_path / "c.ply"), "--poses", str(tmp_path / "p.tum")])
    assert cli.run(args) == 0
    assert "2 maps not merged" in capsys.readouterr().out
    # the first map (6 nodes) in the given files, the second (3 nodes) beside them
    first, _ = read_tum_trajectory(tmp_path / "p.tum")
    second, poses = read_tum_trajectory(tmp_path / "p_map1.tum")
    assert first.size == RESET_AT and second.size == 3
    # in its own frame: where the re-initialised odometry put it
    np.testing.assert_allclose(poses[0][:2, 3], (OFFSET @ planar_pose(1.5, 0, 0))[:2, 3],
                               atol=0.01)
    assert (tmp_path / "c.ply").read_bytes().startswith(b"ply")
    assert (tmp_path / "c_map1.ply").read_bytes().startswith(b"ply")
