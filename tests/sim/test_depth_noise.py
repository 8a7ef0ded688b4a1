"""Kinect depth noise: per-pixel σ, spatial correlation over the configured window,
determinism, and what depthimage_to_laserscan's nearest-of-rows makes of it on a flat wall."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from eddiebot.core import Context
from eddiebot.perception import DepthToScanParams, depth_image_to_laserscan
from eddiebot.sim import KinectConfig, camera_info_msg, depth_image_msg
from eddiebot.sim.render import kinect_depth, noise_boxes, noise_correlation, noise_window_px

QVGA = KinectConfig().at_resolution(320, 240)
FLAT = {"dropout": 0.0, "edge_dropout": 0.0}


def disparity_noise(cfg: KinectConfig, ideal: np.ndarray, frames: range) -> np.ndarray:
    """(frames, H, W) disparity error in steps: the integer disparity recovered from the mm
    output minus the true c / z."""
    c = 1.0 / cfg.disparity_step_coeff
    out = []
    for i in frames:
        mm = kinect_depth(ideal, cfg, i).astype(np.float64)
        assert np.all(mm > 0)
        out.append(np.round(c / (mm / 1000.0)) - c / ideal)
    return np.array(out)


def lag_correlation(n: np.ndarray, lag: int, axis: int) -> float:
    a = np.moveaxis(n, axis, -1)
    x, y = a[..., :-lag].reshape(-1), a[..., lag:].reshape(-1)
    return float(np.corrcoef(x, y)[0, 1])


def test_noise_boxes_give_the_triangle_of_the_window():
    assert noise_boxes(0.0) == ((1, 1.0),)
    assert noise_boxes(1.0) == ((1, 1.0),)
    assert noise_boxes(9.0) == ((9, 1.0),)
    (n4, a4), (n5, a5) = noise_boxes(4.5)
    assert (n4, n5) == (4, 5) and a4 + a5 == pytest.approx(1.0) and 0 < a4 < 1
    for w in (1.3, 2.0, 3.7, 4.5, 6.0, 9.0, 12.25):
        assert sum(a for _, a in noise_boxes(w)) == pytest.approx(1.0)
        assert noise_correlation(w, 0) == pytest.approx(1.0)
        for d in range(1, int(w) + 1):
            assert noise_correlation(w, d) == pytest.approx(1 - d / w), (w, d)
        assert noise_correlation(w, int(w) + 2) == 0.0
    # the window is given in native 640×480 pixels and scales with the rendered width
    cfg = KinectConfig(noise_correlation_px=9.0)
    assert noise_window_px(cfg, 640) == 9.0
    assert noise_window_px(cfg.at_resolution(320, 240), 320) == 4.5
    assert noise_window_px(KinectConfig(), 320) == 0.0


def test_per_pixel_sigma_is_unchanged_by_the_correlation():
    # a depth ramp spreads the quantisation phase: σ² = σ_d² + 1/12 step² with the 1/8-px steps
    ideal = np.tile(np.linspace(2.0, 4.0, 320, dtype=np.float32), (240, 1))
    expect = float(np.sqrt(0.5**2 + 1 / 12))
    sig = {}
    for px in (0.0, 9.0, 18.0):
        n = disparity_noise(replace(QVGA, noise_correlation_px=px, **FLAT), ideal, range(0, 60, 3))
        sig[px] = float(n.std())
        assert abs(float(n.mean())) < 0.02, px
    assert sig[0.0] == pytest.approx(expect, rel=0.02)
    assert sig[9.0] == pytest.approx(sig[0.0], rel=0.03)
    assert sig[18.0] == pytest.approx(sig[0.0], rel=0.03)


@pytest.mark.parametrize(("size", "px"), [((320, 240), 9.0), ((640, 480), 9.0), ((320, 240), 5.0)])
def test_neighbour_correlation_follows_the_window(size, px):
    # σ of 20 steps: quantisation (1/12 step²) is negligible beside it
    cfg = replace(KinectConfig().at_resolution(*size), noise_correlation_px=px,
                  noise_disparity_sigma=20.0, **FLAT)
    ideal = np.full((size[1], size[0]), 2.0, np.float32)
    n = disparity_noise(cfg, ideal, range(4))
    window = noise_window_px(cfg, size[0])
    # the triangle 1 − d/window of a box window (d in rendered pixels), zero beyond it
    for lag in (1, 2, 3, int(window), int(window) + 2):
        expect = max(0.0, 1.0 - lag / window)
        for axis in (1, 2):  # rows and columns alike (a square window)
            assert lag_correlation(n, lag, axis) == pytest.approx(expect, abs=0.03), (lag, axis)


def test_independent_noise_is_uncorrelated_and_small_windows_change_nothing():
    ideal = np.full((240, 320), 2.0, np.float32)
    cfg = replace(QVGA, noise_disparity_sigma=20.0, **FLAT)
    n = disparity_noise(cfg, ideal, range(2))
    assert abs(lag_correlation(n, 1, 1)) < 0.01 and abs(lag_correlation(n, 1, 2)) < 0.01
    # a window of one rendered pixel (2 native pixels at 320×240) is the independent noise
    base = kinect_depth(ideal, QVGA, 5)
    assert np.array_equal(kinect_depth(ideal, replace(QVGA, noise_correlation_px=2.0), 5), base)
    assert not np.array_equal(kinect_depth(ideal, replace(QVGA, noise_correlation_px=9.0), 5), base)


def test_correlated_noise_is_deterministic_in_seed_and_frame():
    ideal = np.tile(np.linspace(1.0, 6.0, 320, dtype=np.float32), (240, 1))
    cfg = replace(QVGA, noise_correlation_px=9.0, seed=3)
    a = kinect_depth(ideal, cfg, 11)
    assert np.array_equal(a, kinect_depth(ideal.copy(), replace(cfg), 11))
    assert not np.array_equal(a, kinect_depth(ideal, cfg, 12))
    assert not np.array_equal(a, kinect_depth(ideal, replace(cfg, seed=4), 11))
    # drop-outs keep their own independent draws: the same pixels as without correlation
    flat = np.full((240, 320), 3.0, np.float32)
    assert np.array_equal(kinect_depth(flat, cfg, 7) == 0,
                          kinect_depth(flat, replace(cfg, noise_correlation_px=0.0), 7) == 0)


def scan_bias(cfg: KinectConfig, z: float, frames: range) -> float:
    """Mean range error of the scan's central ±15° over ``frames`` of a wall at optical depth
    ``z`` (turned slightly about the vertical, so that its depth sweeps 3 disparity steps
    across the image and the quantisation phase averages out): scan_height 10, as the sim
    launch runs depthimage_to_laserscan."""
    info = camera_info_msg(cfg.depth)
    params = DepthToScanParams(range_min=0.45, range_max=8.0, scan_height=10)
    h, w = cfg.depth.height, cfg.depth.width
    sweep = 3 * cfg.disparity_step_coeff * z * z
    ideal = np.tile(np.linspace(z - sweep / 2, z + sweep / 2, w, dtype=np.float32), (h, 1))
    truth = np.asarray(depth_image_to_laserscan(depth_image_msg(ideal), info, params).ranges)
    centre = np.abs(np.arange(truth.size) - truth.size / 2) < truth.size * 15 / 58
    err = []
    for i in frames:
        scan = depth_image_to_laserscan(depth_image_msg(kinect_depth(ideal, cfg, i)), info, params)
        r = np.asarray(scan.ranges, dtype=np.float64)
        ok = centre & np.isfinite(r)
        err.append(r[ok] - truth[ok])
    return float(np.mean(np.concatenate(err)))


def test_scan_bias_on_a_flat_wall_shrinks_with_correlated_noise():
    frames = range(0, 24, 2)
    on = replace(QVGA, noise_correlation_px=9.0)
    bias = {(name, z): scan_bias(cfg, z, frames) for name, cfg in (("off", QVGA), ("on", on))
            for z in (3.0, 5.0, 7.0)}
    # nearest of 10 independent rows: E[max of 10 N(0, 1)] = 1.54 disparity σ (0.5 step of
    # 2.85e-3·z²), i.e. −2.19e-3·z²
    for z in (3.0, 5.0, 7.0):
        assert -2.5e-3 * z * z < bias["off", z] < -1.9e-3 * z * z, (z, bias)
    # 10 rows at 320×240 are 20 native rows, about two 9-px windows: the bias shrinks by a
    # quarter only (≈ −1.56e-3·z²)
    for z in (3.0, 5.0, 7.0):
        assert 0.85 * bias["off", z] < bias["on", z] < 0.6 * bias["off", z], (z, bias)


def test_scan_bias_at_full_resolution_shrinks_more():
    # at 640×480 the 10 rows span about one 9-px window (rows 9 apart are independent):
    # the bias drops to about 60 %
    vga = KinectConfig()
    off = scan_bias(vga, 7.0, range(0, 12, 2))
    on = scan_bias(replace(vga, noise_correlation_px=9.0), 7.0, range(0, 12, 2))
    assert -2.5e-3 * 49 < off < -1.9e-3 * 49, off
    assert 0.7 * off < on < 0.45 * off, (on, off)


def test_simulator_node_takes_the_correlation_parameter():
    from eddiebot.sim.node import SimulatorNode

    ctx = Context(use_sim_time=True)
    try:
        node = SimulatorNode(context=ctx, parameter_overrides={
            "camera_width": 320, "camera_height": 240, "camera_rate": 0.0,
            "noise_correlation_px": 9.0})
        assert node.kinect.noise_correlation_px == 9.0
        assert noise_window_px(node.kinect, node.kinect.depth.width) == 4.5
        plain = SimulatorNode("plain", context=ctx, parameter_overrides={"camera_rate": 0.0})
        assert plain.kinect.noise_correlation_px == 0.0
    finally:
        ctx.shutdown()
