"""``replay_tum`` writes a pose for every input frame, the key frames apart, and reports closures
by kind (ICL-NUIM sample, TUM folder in tmp_path)."""

from __future__ import annotations

import json

import cv2
import numpy as np
from icl_data import ICL_DEPTH_SCALE, needs_icl, write_icl_tum

from eddiebot.vslam.replay import replay_tum, tum_camera_setup
from eddiebot.vslam.tum import read_tum_trajectory


@needs_icl
def test_every_input_frame_gets_a_pose_lost_ones_included(tmp_path):
    indices = list(range(0, 90, 3))  # 30 frames
    folder = write_icl_tum(tmp_path / "seq", indices)
    # frame 12 is blank: odometry is lost there
    blank = tmp_path / "blank.jpg"
    cv2.imwrite(str(blank), np.zeros((480, 640, 3), np.uint8))
    lines = (folder / "rgb.txt").read_text().splitlines()
    stamp = lines[12].split()[0]
    lines[12] = f"{stamp} {blank}"
    (folder / "rgb.txt").write_text("\n".join(lines) + "\n")
    setup = tum_camera_setup(folder, depth_scale=ICL_DEPTH_SCALE, depth_scale_source="test")
    out = tmp_path / "out"
    report = replay_tum(folder, out, setup=setup)
    stamps, poses = read_tum_trajectory(out / "poses.txt")
    key_stamps, key_poses = read_tum_trajectory(out / "keyframes.txt")
    assert report.frames == len(indices) and report.lost_frames == 1
    assert stamps.size == len(indices)
    np.testing.assert_allclose(stamps, np.arange(len(indices)) / 30.0, atol=1e-6)
    # the lost frame holds the previous frame's pose
    np.testing.assert_allclose(poses[12], poses[11], atol=1e-6)
    # default update thresholds (0.1 m / 0.1 rad): far fewer key frames than frames
    assert 2 <= key_stamps.size == report.nodes < len(indices) // 2
    # a key frame's pose in poses.txt is its key-frame pose
    k = {round(s, 6): i for i, s in enumerate(stamps)}
    for s, p in zip(key_stamps, key_poses):
        np.testing.assert_allclose(poses[k[round(s, 6)]], p, atol=1e-6)
    assert report.ate_frames == len(indices)
    assert report.slam_ate_m < 0.03
    data = json.loads((out / "report.json").read_text())
    for key in ("loop_closures", "proximity_links", "rejected_hypotheses", "keyframe_ate_m",
                "intrinsics_source", "depth_scale_source"):
        assert key in data
    assert data["depth_scale"] == ICL_DEPTH_SCALE
