"""``eddie vslam replay BAG``: a pose for every input colour frame, key frames apart, the colour
camera's optical frame, and the report's counts; `FrameTrack` on its own."""

import json

import numpy as np
from vslam_synthetic import frame, kinect_camera, planar_pose

from eddiebot.cli import vslam as cli
from eddiebot.core.tf import make_transform, make_transform_2d
from eddiebot.geometry import matrix_to_quaternion
from eddiebot.msgs.tf2_msgs import TFMessage
from eddiebot.sim.camera import camera_info_msg, depth_image_msg, rgb_image_msg
from eddiebot.vslam.frame_track import FrameTrack
from eddiebot.vslam.records import ProcessResult
from eddiebot.vslam.tum import read_tum_trajectory

CAM = kinect_camera(320, 240)
OPTICAL = "camera_rgb_optical_frame"
SEC = 1_000_000_000
STEP_M = 0.04
FRAMES = 15
NO_DEPTH = 7  # this frame's depth image is missing: a lost frame


def _bag(path):
    from eddiebot.bag import BagWriter

    lt = CAM.local_transform
    q = matrix_to_quaternion(lt[:3, :3])
    with BagWriter(path) as w:
        w.write_message("/tf_static", TFMessage(transforms=[make_transform(
            "base_footprint", OPTICAL, 0, *(float(v) for v in lt[:3, 3]),
            *(float(v) for v in q))]), SEC - 1)
        for k in range(FRAMES + 1):
            t = SEC + k * SEC // 10
            x = STEP_M * k
            w.write_message("/tf", TFMessage(transforms=[
                make_transform_2d("odom", "base_footprint", t, x, 0.0, 0.0)]), t)
            if k == FRAMES:
                break  # odometry after the last image only
            rgb, depth = frame(3, 2.0 + x, 3.0, 0.0)
            w.write_message("/camera_info", camera_info_msg(CAM, t, OPTICAL), t)
            w.write_message("/image_raw", rgb_image_msg(rgb, t, OPTICAL), t)
            if k != NO_DEPTH:
                w.write_message("/depth/image_raw", depth_image_msg(depth, t, OPTICAL), t)
    return path


def test_a_bag_replay_writes_a_pose_for_every_colour_frame(tmp_path):
    out = tmp_path / "out"
    # 2 Hz detection: every fifth set reaches the core; the others are placed by odometry
    report = cli.replay_bag(_bag(tmp_path / "bag"), out, {"Rtabmap/DetectionRate": "2"})
    assert report["frames"] == FRAMES
    assert report["lost_frames"] == 1
    assert report["frames_processed"] == 3  # frames 0, 5 and 10
    assert report["nodes"] == 3
    for key in ("loop_closures", "proximity_links", "rejected_hypotheses", "map_merges",
                "odometry_resets"):
        assert report[key] == 0
    assert report["maps"] == 1
    assert json.loads((out / "report.json").read_text())["poses"] == FRAMES
    stamps, poses = read_tum_trajectory(out / "poses.txt")
    assert len(stamps) == FRAMES
    np.testing.assert_allclose(stamps, [1.0 + k / 10 for k in range(FRAMES)], atol=1e-6)
    lt = CAM.local_transform
    for k in range(FRAMES):
        # the lost frame keeps the previous frame's pose; nothing is made up for it
        x = STEP_M * (k - 1 if k == NO_DEPTH else k)
        expected = planar_pose(x, 0.0, 0.0) @ lt  # the colour camera's optical frame
        np.testing.assert_allclose(poses[k][:3, 3], expected[:3, 3], atol=0.01)
        np.testing.assert_allclose(poses[k][:3, :3], expected[:3, :3], atol=0.01)
    key_stamps, key_poses = read_tum_trajectory(out / "keyframes.txt")
    np.testing.assert_allclose(key_stamps, [1.0, 1.5, 2.0], atol=1e-6)
    np.testing.assert_allclose(key_poses[2][:3, 3], (planar_pose(0.4, 0, 0) @ lt)[:3, 3],
                               atol=0.01)
    odom_stamps, _ = read_tum_trajectory(out / "odom.txt")
    assert len(odom_stamps) == FRAMES - 1


def _result(node_id, added, **kw):
    return ProcessResult(node_id, added, np.eye(4), np.eye(4), **kw)


def test_frame_track_places_frames_by_stamp_against_their_key_frame():
    track = FrameTrack()
    odom = [planar_pose(0.1 * k, 0.0, 0.0) for k in range(6)]
    track.tracked(0.0, _result(1, True), odom[0])
    track.tracked(0.4, _result(2, True, loop_closure_id=1), odom[4])
    track.skipped(0.2, odom[2])  # placed after a later frame: still against key frame 1
    track.lost_frame(0.3)
    track.tracked(0.5, _result(2, False, proximity_id=1, rejected_loop_id=1), odom[5])
    track.tracked(0.6, ProcessResult(0, False, np.eye(4), None), odom[5])  # rejected: lost
    assert (track.frames, track.lost, track.loop_closures, track.proximity_links,
            track.rejected_hypotheses) == (6, 2, 1, 1, 1)
    shift = planar_pose(0.0, 1.0, 0.0)
    optimized = {1: shift @ odom[0], 2: shift @ planar_pose(0.5, 0.0, 0.0)}  # 2 moved 10 cm
    stamps, poses = track.frame_poses(optimized)
    assert stamps == [0.0, 0.2, 0.3, 0.4, 0.5, 0.6]
    xs = [p[0, 3] for p in poses]
    np.testing.assert_allclose(xs, [0.0, 0.2, 0.2, 0.5, 0.6, 0.6], atol=1e-9)
    np.testing.assert_allclose([p[1, 3] for p in poses], 1.0, atol=1e-9)
    # a key frame the core merged away: its frames fall back on the key frame before it
    stamps, poses = track.frame_poses({1: odom[0]})
    np.testing.assert_allclose([p[0, 3] for p in poses], [0.0, 0.2, 0.2, 0.4, 0.5, 0.5])
    assert track.keyframe_poses(optimized)[0] == [0.0, 0.4]
