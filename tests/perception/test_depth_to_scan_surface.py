"""``row_selection: nearest_surface``: the nearest surface's mean range, not its minimum."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from eddiebot.core.node import Node
from eddiebot.perception import DepthToScanParams, depth_image_to_laserscan
from eddiebot.perception.node import DepthToScanNode
from eddiebot.sim import KinectConfig, camera_info_msg, depth_image_msg
from eddiebot.sim.render import kinect_depth

NEAREST = DepthToScanParams(range_min=0.45, range_max=8.0, scan_height=10)
SURFACE = replace(NEAREST, row_selection="nearest_surface")


def _cfg() -> KinectConfig:
    cfg = KinectConfig()
    return replace(cfg, depth=replace(cfg.depth, width=320, height=240))


def _centre_errors(params: DepthToScanParams, z: float, frames: int = 12) -> np.ndarray:
    """Range error over the central ±15° of a noisy wall facing the camera at z."""
    cfg = _cfg()
    info = camera_info_msg(cfg.depth)
    ideal = np.full((cfg.depth.height, cfg.depth.width), z, np.float32)
    truth = np.asarray(depth_image_to_laserscan(depth_image_msg(ideal), info, NEAREST).ranges,
                       dtype=np.float64)
    centre = np.abs(np.arange(truth.size) - truth.size / 2) < truth.size * 15 / 58
    out = []
    for i in range(frames):
        noisy = kinect_depth(ideal, cfg, i)
        scan = depth_image_to_laserscan(depth_image_msg(noisy), info, params)
        out.append((np.asarray(scan.ranges, dtype=np.float64) - truth)[centre])
    return np.array(out)


@pytest.mark.parametrize("z", [3.0, 6.0])
def test_noisy_wall_is_unbiased_where_upstream_reads_short(z):
    sigma = 1.425e-3 * z * z
    upstream = _centre_errors(NEAREST, z)
    surface = _centre_errors(SURFACE, z)
    # upstream's nearest of 10 noisy rows: ≈ 1.5 σ short
    assert np.nanmean(upstream) < -1.0 * sigma
    # the surface mean: within 0.15 σ of the truth, and less scattered than the minimum
    assert abs(np.nanmean(surface)) < 0.15 * sigma
    assert np.nanstd(surface) < 0.7 * np.nanstd(upstream)
    # the same returns: no bin gains or loses a reading
    assert np.array_equal(np.isnan(surface), np.isnan(upstream))


def test_nearer_object_in_a_few_rows_still_wins():
    cfg = _cfg()
    info = camera_info_msg(cfg.depth)
    depth = np.full((240, 320), 5.0, np.float32)
    top = int(info.k[5] - 5)  # the scan's first row
    depth[top : top + 3, 100:140] = 2.0  # a table edge in the top three of the ten rows
    depth[top : top + 3, 140:150] = 2.02
    depth[top + 3 : top + 4, 140:150] = 2.0
    ideal = depth_image_to_laserscan(depth_image_msg(depth), info, NEAREST).ranges
    got = depth_image_to_laserscan(depth_image_msg(depth), info, SURFACE).ranges
    wall = np.abs(ideal - 5.0 / np.cos(np.arctan((np.arange(320)[::-1] - info.k[2]) / info.k[0])))
    # where only the wall is seen, its range (a bin fed by two columns averages their ranges,
    # a few millimetres apart at the image's edge, where upstream keeps the smaller)
    assert np.nanmax(np.abs(got - ideal)[wall < 1e-3]) < 5e-3
    assert np.nanmedian(np.abs(got - ideal)[wall < 1e-3]) < 1e-5
    # the edge's bins keep the edge: the mean of its readings within the tolerance of 2 m
    edge = np.isfinite(ideal) & (ideal < 2.5)
    assert edge.sum() >= 45
    assert np.all(got[edge] < ideal[edge] + 0.025)
    assert np.all(got[edge] >= ideal[edge] - 1e-6)
    # four rows at 2.00 and 2.02 / cos θ: their mean, not the wall's
    mixed = edge & (got > ideal + 1e-3)
    assert mixed.sum() >= 5
    assert np.all(got[mixed] - ideal[mixed] < 0.02)


def test_out_of_range_rows_behave_as_upstream():
    cfg = _cfg()
    info = camera_info_msg(cfg.depth)
    depth = np.full((240, 320), 9.0, np.float32)  # beyond range_max everywhere
    depth[:, :10] = np.inf
    a = depth_image_to_laserscan(depth_image_msg(depth), info, NEAREST).ranges
    b = depth_image_to_laserscan(depth_image_msg(depth), info, SURFACE).ranges
    np.testing.assert_array_equal(a, b)


def test_bad_row_selection_names_the_value():
    with pytest.raises(ValueError, match=r"'median'.*nearest, nearest_surface"):
        DepthToScanParams(row_selection="median")
    with pytest.raises(ValueError, match="surface_tolerance"):
        DepthToScanParams(surface_tolerance=-0.1)


def test_node_parameters_reach_the_conversion():
    node = DepthToScanNode(parameter_overrides={"row_selection": "nearest_surface",
                                                "surface_tolerance_quadratic": 0.004})
    try:
        assert isinstance(node, Node)
        assert node.params.row_selection == "nearest_surface"
        assert node.params.surface_tolerance_quadratic == pytest.approx(0.004)
        assert node.params.surface_tolerance == pytest.approx(0.02)
    finally:
        node.destroy_node()
