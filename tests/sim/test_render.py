"""Kinect rendering: geometry, depth behaviour, determinism, features, messages."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from eddiebot.perception import DepthToScanParams, depth_image_to_laserscan, image_to_array
from eddiebot.sim import (
    KINECT_DEPTH,
    KinectConfig,
    Renderer,
    camera_info_msg,
    depth_image_msg,
    load_world,
    parse_world,
    render_view,
    rgb_image_msg,
)

ROOM = parse_world({
    "start": {"x": 0, "y": 0},
    "walls": [{"points": [[-3, -4], [4, -4], [4, 4], [-3, 4], [-3, -4]], "thickness": 0.2}],
})


def test_ideal_depth_is_optical_z_to_a_wall():
    cfg = KinectConfig()
    d = Renderer(ROOM, cfg).ideal_depth((0, 0, 0))
    wall = 4.0 - 0.1 - cfg.depth_position[0]  # inner face minus the camera's x
    h, w = d.shape
    assert (h, w) == (480, 640)
    # every pixel looking at the wall has depth = the wall's x distance (z, not ray length)
    band = d[200:270, :]
    assert np.allclose(band, wall, atol=1e-4)
    # the floor: z = h·fy/(v − cy) below the horizon
    v = 470
    assert d[v, 320] == pytest.approx(cfg.depth_position[2] * KINECT_DEPTH.fy / (v - KINECT_DEPTH.cy), rel=1e-4)


def test_kinect_depth_quantisation_and_limits():
    cfg = KinectConfig(noise_disparity_sigma=0.0, dropout=0.0, edge_dropout=0.0)
    for x_wall, expect_zero in ((1.0, False), (2.9, False), (0.2, True), (9.5, True)):
        world = parse_world({"start": {"x": 0, "y": 0},
                             "walls": [{"points": [[x_wall + 0.22, -9], [x_wall + 0.22, 9]],
                                        "thickness": 0.2}]})
        r = Renderer(world, cfg)
        z = x_wall + 0.12 + 0.12
        depth = r.depth((0, 0, 0))[234, 100:540]
        if expect_zero:
            assert np.all(depth == 0), x_wall  # closer than 0.5 m is no return; far beyond 8 m too
            continue
        step = cfg.disparity_step_coeff * z * z
        assert np.all(np.abs(depth / 1000.0 - z) <= step / 2 + 1e-3)
        # values are c/n (in mm) for integer disparities n
        c = 1.0 / cfg.disparity_step_coeff
        n = np.round(c / (depth / 1000.0))
        assert np.all(np.abs(depth - 1000.0 * c / n) <= 0.5 + 1e-3)


def test_noise_grows_with_range_and_is_seeded():
    def spread(x_wall, seed=0, frame=0):
        world = parse_world({"start": {"x": 0, "y": 0},
                             "walls": [{"points": [[x_wall, -20], [x_wall, 20]], "thickness": 0.2}]})
        r = Renderer(world, KinectConfig(seed=seed))
        d = r.depth((0, 0, 0), frame)[150:300, 100:540].astype(float) / 1000
        d = d[d > 0]
        return d, r

    near, _ = spread(1.5)
    far, r = spread(5.0)
    assert np.std(far) > 5 * np.std(near)
    a, b = r.frame((0, 0, 0), 3), r.frame((0, 0, 0), 3)
    assert np.array_equal(a.depth, b.depth) and np.array_equal(a.rgb, b.rgb)
    assert not np.array_equal(a.depth, r.frame((0, 0, 0), 4).depth)
    other = Renderer(r.world, KinectConfig(seed=1)).frame((0, 0, 0), 3)
    assert not np.array_equal(a.depth, other.depth)
    assert np.array_equal(a.rgb, other.rgb)  # RGB is noise-free


def test_edges_are_noisier():
    world = parse_world({"start": {"x": 0, "y": 0},
                         "walls": [{"points": [[6, -20], [6, 20]], "thickness": 0.2}],
                         "boxes": [{"center": [2.5, 0], "size": [0.4, 0.4], "height": 2.0}]})
    cfg = KinectConfig(edge_dropout=0.5, dropout=0.0)
    d = Renderer(world, cfg).depth((0, 0, 0))
    ideal = Renderer(world, cfg).ideal_depth((0, 0, 0))
    gx = np.abs(np.diff(ideal, axis=1)) > 0.5
    edge_cols = np.zeros_like(ideal, bool)
    edge_cols[:, 1:] |= gx
    edge_cols[:, :-1] |= gx
    rows = slice(150, 300)
    assert (d[rows][edge_cols[rows]] == 0).mean() > 0.3
    assert (d[rows][~edge_cols[rows]] == 0).mean() < 0.01


def test_same_seed_identical_frames_office():
    w = load_world("office")
    a = Renderer(w, KinectConfig(seed=5)).frame(w.start, 7)
    b = Renderer(w, KinectConfig(seed=5)).frame(w.start, 7)
    assert np.array_equal(a.rgb, b.rgb) and np.array_equal(a.depth, b.depth)
    assert a.rgb.shape == (480, 640, 3) and a.rgb.dtype == np.uint8
    assert a.depth.shape == (480, 640) and a.depth.dtype == np.uint16


def test_orb_finds_features_in_office():
    w = load_world("office")
    r = Renderer(w)
    orb = cv2.ORB_create(nfeatures=1000)
    for pose in ((1.5, 7.5, 0.0), (6.0, 3.0, 1.0), (3.5, 10.5, 0.3)):
        gray = cv2.cvtColor(r.rgb(pose), cv2.COLOR_RGB2GRAY)
        assert len(orb.detect(gray, None)) >= 200, pose


def test_low_resolution_scales_intrinsics():
    cfg = KinectConfig().at_resolution(320, 240)
    f = Renderer(ROOM, cfg).frame((0, 0, 0))
    assert f.rgb.shape == (240, 320, 3) and f.depth.shape == (240, 320)
    assert cfg.depth.fx == pytest.approx(KINECT_DEPTH.fx / 2)
    assert math.degrees(cfg.depth.hfov) == pytest.approx(math.degrees(KINECT_DEPTH.hfov), abs=0.2)


def test_tables_on_legs_missed_at_scan_height():
    world = parse_world({"start": {"x": 0, "y": 0},
                         "walls": [{"points": [[5, -9], [5, 9]], "thickness": 0.2}],
                         "tables": [{"center": [2.0, 0.0], "size": [1.0, 3.0], "height": 0.74}]})
    cfg = KinectConfig(noise_disparity_sigma=0, dropout=0, edge_dropout=0)
    d = Renderer(world, cfg).ideal_depth((0, 0, 0))
    # the principal row passes under the table top and between the legs
    assert d[int(KINECT_DEPTH.cy), 320] == pytest.approx(5 - 0.1 + 0.12, abs=1e-3)
    # rows looking up see the underside of the top at 0.70 m
    v = 205
    z_under = (0.70 - 0.6083) * KINECT_DEPTH.fy / (KINECT_DEPTH.cy - v)
    assert d[v, 320] == pytest.approx(z_under, rel=1e-3)


def test_people_are_drawn():
    cfg = KinectConfig()
    r = Renderer(ROOM, cfg)
    d0 = r.ideal_depth((0, 0, 0))
    d1 = r.ideal_depth((0, 0, 0), people=np.array([[2.0, 0.0, 0.25]]))
    assert d1[234, 320] == pytest.approx(2.0 - 0.25 + 0.12, abs=0.01)
    assert d0[234, 320] > 3.5


def test_messages_from_arrays_and_scan_pipeline():
    cfg = KinectConfig(noise_disparity_sigma=0, dropout=0, edge_dropout=0)
    f = Renderer(ROOM, cfg).frame((0, 0, 0))
    rgb = rgb_image_msg(f.rgb, 1_500_000_000)
    depth = depth_image_msg(f.depth, 1_500_000_000)
    info = camera_info_msg(cfg.depth, 1_500_000_000)
    assert rgb.header.frame_id == "camera_rgb_optical_frame" and rgb.encoding == "rgb8"
    assert depth.header.frame_id == "camera_depth_optical_frame" and depth.encoding == "16UC1"
    assert depth.header.stamp.sec == 1 and depth.header.stamp.nanosec == 500_000_000
    assert info.k[0] == pytest.approx(587.0460716) and np.all(info.d == 0)
    assert np.array_equal(image_to_array(depth), f.depth)
    assert np.array_equal(image_to_array(rgb, ("rgb8",)), f.rgb)
    scan = depth_image_to_laserscan(depth, info, DepthToScanParams(scan_height=10))
    r = scan.ranges[np.isfinite(scan.ranges)]
    assert len(r) > 400
    # the wall 3.9 m ahead of the camera (x = 3.9 + 0.12): r·cos(angle) ≈ 4.02 ± quantisation
    ang = scan.angle_min + np.arange(640) * scan.angle_increment
    ok = np.isfinite(scan.ranges)
    fwd = scan.ranges[ok] * np.cos(ang[ok])
    assert np.median(fwd) == pytest.approx(4.02, abs=0.03)


def test_render_view_direct_call():
    rgb, depth = render_view(ROOM, (0.0, 0.0, 0.6, math.pi / 2), KINECT_DEPTH, want_rgb=False)
    assert rgb.size == 0
    assert depth[240, 317] == pytest.approx(3.9, abs=1e-3)


def test_ground_truth_odometry_message():
    from eddiebot.sim import ground_truth_odometry_msg

    msg = ground_truth_odometry_msg(1.0, 2.0, math.pi / 2, 0.3, 0.1, 2_000_000_001)
    assert msg.header.frame_id == "map" and msg.child_frame_id == "base_footprint"
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (2, 1)
    q = msg.pose.pose.orientation
    assert (q.z, q.w) == pytest.approx((math.sqrt(0.5), math.sqrt(0.5)))
    assert msg.twist.twist.linear.x == 0.3 and msg.twist.twist.angular.z == 0.1
