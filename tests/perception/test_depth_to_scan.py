"""depthimage_to_laserscan semantics against hand-computed geometry."""

from __future__ import annotations

import math

import numpy as np
import pytest

from eddiebot.perception import (
    DepthToScanParams,
    ImageSizeError,
    ScanHeightError,
    UnsupportedEncodingError,
    depth_image_to_laserscan,
    scan_geometry,
)
from eddiebot.sim.camera import KINECT_DEPTH, camera_info_msg, depth_image_msg


@pytest.fixture
def info():
    return camera_info_msg(KINECT_DEPTH)


def _column_angles(info):
    fx, cx = info.k[0], info.k[2]
    u = np.arange(info.width)
    return -np.arctan((u - cx) / fx)


def test_angle_limits_match_upstream_formulas(info):
    scan = depth_image_to_laserscan(depth_image_msg(np.zeros((480, 640), np.uint16)), info)
    fx, cx = KINECT_DEPTH.fx, KINECT_DEPTH.cx
    assert scan.angle_max == pytest.approx(math.atan(cx / fx), abs=1e-6)
    assert scan.angle_min == pytest.approx(-math.atan((639 - cx) / fx), abs=1e-6)
    assert scan.angle_increment == pytest.approx((scan.angle_max - scan.angle_min) / 639, rel=1e-5)
    assert scan.ranges.dtype == np.float32
    assert scan.ranges.size == 640
    assert scan.header.frame_id == "camera_depth_frame"


def test_wall_two_metres_ahead_16uc1(info):
    depth = np.full((480, 640), 2000, np.uint16)
    scan = depth_image_to_laserscan(depth_image_msg(depth), info, DepthToScanParams(scan_height=50))
    geom = scan_geometry(info)
    th = _column_angles(info)
    hit_bins = np.zeros(640, bool)
    for u in range(640):
        b = geom.bin_of_column[u]
        assert 0 <= b < 640
        hit_bins[b] = True
    # every bin that receives a column holds 2/cos θ of one of its columns (within 3 mm)
    for b in np.flatnonzero(hit_bins):
        cols = np.flatnonzero(geom.bin_of_column == b)
        expected = (2.0 / np.cos(th[cols])).min()
        assert abs(scan.ranges[b] - expected) < 3e-3
    # bins that receive no column stay NaN, as upstream
    assert np.all(np.isnan(scan.ranges[~hit_bins]))
    assert (~hit_bins).sum() > 0


def test_wall_two_metres_ahead_32fc1(info):
    depth = np.full((480, 640), 2.0, np.float32)
    scan = depth_image_to_laserscan(depth_image_msg(depth), info)
    th = _column_angles(info)
    geom = scan_geometry(info)
    for u in (0, 100, 317, 500, 639):
        assert scan.ranges[geom.bin_of_column[u]] == pytest.approx(2.0 / math.cos(th[u]), abs=3e-3)


def test_closest_in_band_wins_and_out_of_range_dropped(info):
    depth = np.full((480, 640), 3000, np.uint16)
    row = int(KINECT_DEPTH.cy)
    depth[row - 2, 300] = 1500
    depth[row + 1, 400] = 12000  # beyond range_max: dropped, not clamped
    depth[row, 400] = 12000
    depth[row - 1, 400] = 12000
    depth[row - 3 : row + 3, 200] = 12000
    scan = depth_image_to_laserscan(depth_image_msg(depth), info, DepthToScanParams(scan_height=6))
    geom = scan_geometry(info)
    th = _column_angles(info)
    b = geom.bin_of_column[300]
    assert scan.ranges[b] == pytest.approx(1.5 / math.cos(th[300]), abs=1e-3)
    # column 200 is alone in its bin? then it must be NaN (all values dropped)
    b200 = geom.bin_of_column[200]
    if np.sum(geom.bin_of_column == b200) == 1:
        assert np.isnan(scan.ranges[b200])


def test_zero_nan_inf_rules(info):
    geom = scan_geometry(info)
    # pick a bin receiving exactly one column
    counts = np.bincount(geom.bin_of_column[geom.bin_of_column >= 0], minlength=640)
    u = int(np.flatnonzero(counts[geom.bin_of_column] == 1)[100])
    b = geom.bin_of_column[u]
    row = int(KINECT_DEPTH.cy - 1.5)  # offset of a 3-row band

    def scan_with(values, dtype, **kw):
        depth = np.full((480, 640), np.nan if dtype == np.float32 else 0, dtype)
        for i, val in enumerate(values):
            depth[row + i, u] = val
        return depth_image_to_laserscan(depth_image_msg(depth), info,
                                        DepthToScanParams(scan_height=3, **kw)).ranges[b]

    # uint16 zeros never produce a value
    assert np.isnan(scan_with([0, 0, 0], np.uint16))
    # ... unless range_min <= 0
    assert scan_with([0, 0, 0], np.uint16, range_min=0.0) == 0.0
    # float: NaN never replaces anything; Inf beats NaN; a finite in-range value beats Inf
    assert np.isnan(scan_with([np.nan] * 3, np.float32))
    assert scan_with([np.nan, np.inf, np.nan], np.float32) == np.inf
    assert scan_with([np.inf, -np.inf, np.nan], np.float32) == -np.inf  # last Inf wins
    v = scan_with([np.inf, 2.0, np.nan], np.float32)
    assert np.isfinite(v) and v > 2.0
    v2 = scan_with([2.5, np.inf, 2.0], np.float32)
    assert v2 == pytest.approx(v, abs=1e-6)  # Inf after a finite value is rejected; min kept
    # an out-of-range value after Inf: Inf kept
    assert scan_with([np.inf, 20.0, np.nan], np.float32) == np.inf


def test_output_frame_empty_keeps_image_frame(info):
    msg = depth_image_msg(np.full((480, 640), 1000, np.uint16), frame_id="kinect_depth")
    scan = depth_image_to_laserscan(msg, info, DepthToScanParams(output_frame=""))
    assert scan.header.frame_id == "kinect_depth"
    assert scan.scan_time == pytest.approx(0.033)
    assert scan.range_min == pytest.approx(0.45)
    assert scan.range_max == pytest.approx(10.0)


def test_errors_name_both_sides(info):
    bad = depth_image_msg(np.zeros((240, 320), np.uint16))
    with pytest.raises(ImageSizeError, match=r"320x240.*640x480"):
        depth_image_to_laserscan(bad, info)
    msg = depth_image_msg(np.zeros((480, 640), np.uint16))
    msg.encoding = "8UC1"
    with pytest.raises(UnsupportedEncodingError, match=r"8UC1.*16UC1, 32FC1"):
        depth_image_to_laserscan(msg, info)
    with pytest.raises(ScanHeightError):
        depth_image_to_laserscan(depth_image_msg(np.zeros((480, 640), np.uint16)), info,
                                 DepthToScanParams(scan_height=480))


def test_big_endian_and_padded_step(info):
    depth = np.full((480, 640), 2000, np.uint16)
    padded = np.zeros((480, 700), np.dtype(">u2"))
    padded[:, :640] = depth
    msg = depth_image_msg(depth)
    msg.is_bigendian = 1
    msg.step = 1400
    msg.data = padded.view(np.uint8).reshape(-1)
    a = depth_image_to_laserscan(msg, info).ranges
    b = depth_image_to_laserscan(depth_image_msg(depth), info).ranges
    np.testing.assert_array_equal(a, b)
