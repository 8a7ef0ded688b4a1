"""Visual odometry per-frame work: the depth cloud is built only for frames that use it (ICP or
a key frame feeding the scan map), and the keypoint attributes read in one pass equal OpenCV's."""

import cv2
import numpy as np
from test_vslam_vo_icp import ICP_VO, _spin
from vslam_synthetic import frame, kinect_camera

import eddiebot.vslam.odometry as odometry
from eddiebot.vslam.features import FeatureExtractor
from eddiebot.vslam.parameters import RtabmapParameters


def test_depth_cloud_built_only_for_icp_and_key_frames(monkeypatch):
    built: list[int] = []
    real = odometry.make_scan

    def counting(depth, camera, settings):
        built.append(1)
        return real(depth, camera, settings)

    monkeypatch.setattr(odometry, "make_scan", counting)
    blank = range(10, 24)
    res, truths = _spin({**ICP_VO, "Odom/IcpFallbackInliers": "40"}, blank)
    # the first frame starts the scan map; afterwards only ICP frames and key frames need it
    # (a fallback ICP attempt on a frame that stays visual would add one: none here)
    needed = 1 + sum(1 for r in res[1:] if r.icp or r.keyframe)
    assert len(built) == needed
    assert needed < len(res) - 10  # most tracked visual frames build no cloud
    assert sum(r.icp for r in res) >= len(blank)
    # the tracking itself is as before: the spin's end pose within 2 cm
    assert np.linalg.norm(res[-1].pose[:2, 3] - truths[-1][:2, 3]) < 0.02


def test_keypoint_attributes_match_opencv():
    rgb, depth = frame(3, 1.0, 1.0, 0.4)
    cam = kinect_camera(320, 240)
    params = RtabmapParameters.from_dict({})
    ex = FeatureExtractor(params, max_features=params.vis_max_features, strategy=params.vis_feature_type)
    f = ex.extract(rgb, depth, cam, depth_as_mask=False)
    assert len(f) > 100
    # reference: the same detector and descriptor, attributes read keypoint by keypoint
    gray = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
    kps = ex._gftt.detect(gray, None)
    for kp in kps:
        kp.size = 31.0
    kps, desc = ex._orb.compute(gray, kps)
    resp = np.array([k.response for k in kps], np.float32)
    order = np.argsort(-resp, kind="stable")[: params.vis_max_features]
    ref_uv = np.array([kps[i].pt for i in order], np.float32)
    # keypoints outside the depth range are dropped: compare the kept ones, found by position
    assert len(f) > 0.8 * len(order)
    lookup = {tuple(p): i for i, p in enumerate(ref_uv.tolist())}
    idx = np.array([lookup[tuple(p)] for p in f.uv.tolist()])
    assert np.all(np.diff(idx) > 0)  # same order
    src = order[idx]
    np.testing.assert_array_equal(f.responses, resp[src])
    np.testing.assert_array_equal(f.sizes, np.array([kps[i].size for i in src], np.float32))
    np.testing.assert_array_equal(f.angles, np.array([kps[i].angle for i in src], np.float32))
    np.testing.assert_array_equal(f.octaves, np.array([kps[i].octave for i in src], np.int32))
    np.testing.assert_array_equal(f.descriptors, desc[src])
