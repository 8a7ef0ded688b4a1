"""``nav2_constrained_smoother::ConstrainedSmoother``: Nav2's own test cases (smoothness of a
sharp turn with and without a cusp, anchoring to the original path, pushing a path away from
an obstacle) with their figures, the residual terms, down/upsampling, and the parameters."""

from __future__ import annotations

import math

import numpy as np
import pytest

from eddiebot.nav.controllers.dwb_critics import score_obstacle_footprint
from eddiebot.nav.costmap.costmap2d import Costmap2D
from eddiebot.nav.errors import ParameterError
from eddiebot.nav.smoother import (
    ConstrainedOptimizerConfig,
    ConstrainedSmoother,
    ConstrainedSmootherConfig,
    bicubic_cost,
    build_smoother,
)

#: SmootherTest::SetUp in nav2_constrained_smoother/test/test_constrained_smoother.cpp
NAV2_TEST = {"w_smooth": 2000000.0, "minimum_turning_radius": 0.4, "w_curve": 30.0,
             "w_dist": 0.0, "w_cost": 0.0, "cusp_zone_length": -1.0,
             "w_cost_cusp_multiplier": 1.0}

SHARP_TURN_90 = np.array([[0, 0, 0], [0.1, 0, 0], [0.2, 0, 0], [0.3, 0, math.pi / 4],
                          [0.3, 0.1, math.pi / 2], [0.3, 0.2, math.pi / 2],
                          [0.3, 0.3, math.pi / 2]])
SHARP_TURN_90_THEN_REVERSE = np.array(
    [[0.1 * k, 0, 0] for k in range(6)] + [[0.6, 0, math.pi / 4]]
    + [[0.6, -0.1 * k, math.pi / 2] for k in range(1, 7)])


def _smoother(**overrides: object) -> ConstrainedSmoother:
    return build_smoother("SmoothPath", {"plugin": "nav2_constrained_smoother/ConstrainedSmoother",
                                         **NAV2_TEST, **overrides})  # type: ignore[return-value]


def _mvmt(path: np.ndarray, cusp: int = -1) -> np.ndarray:
    """The test's mvmt_smoothness_criterion: change of the step vector at each inner pose."""
    prev = path[1:-1, :2] - path[:-2, :2]
    nxt = path[2:, :2] - path[1:-1, :2]
    if cusp > 0:
        nxt[cusp - 1] *= -1.0
    return np.hypot(*(nxt - prev).T)


def _orientation(path: np.ndarray) -> np.ndarray:
    """The test's orientation criterion (tf2 getAngle() of the yaw quaternion is |yaw|)."""
    a = np.abs(np.arctan2(np.sin(path[:, 2]), np.cos(path[:, 2])))
    return np.asarray([math.remainder(v, 2 * math.pi) for v in np.diff(a)])


def _improvement(before: np.ndarray, after: np.ndarray) -> float:
    """assessPathImprovement: 100 · (1 - rms(after) / rms(before))."""
    return 100.0 * (1.0 - math.sqrt(np.mean(after ** 2)) / math.sqrt(np.mean(before ** 2)))


def _zig_zag(path: np.ndarray, offset: float) -> np.ndarray:
    out = path.copy()
    for i in range(1, len(path) - 1):
        d = path[i + 1, :2] - path[i - 1, :2]
        d /= np.hypot(*d)
        out[i, :2] += np.array([d[1], -d[0]]) * offset * (1.0 if i % 2 == 0 else -1.0)
    return out


def test_smoothness_of_a_sharp_turn_as_nav2() -> None:
    s = _smoother(w_curve=0.0)
    out = s.smooth(SHARP_TURN_90).path
    assert _improvement(_mvmt(SHARP_TURN_90), _mvmt(out)) == pytest.approx(55.3, abs=1.0)
    assert _improvement(_orientation(SHARP_TURN_90), _orientation(out)) == pytest.approx(
        38.7, abs=1.0)
    # the ends and their headings stay
    np.testing.assert_allclose(out[[0, 1, -2, -1], :2], SHARP_TURN_90[[0, 1, -2, -1], :2])
    assert out[0, 2] == pytest.approx(0.0) and out[-1, 2] == pytest.approx(math.pi / 2)
    assert s.last_cost[1] < 0.01 * s.last_cost[0]


def test_smoothness_with_a_cusp_as_nav2() -> None:
    path = SHARP_TURN_90_THEN_REVERSE
    out = _smoother(w_curve=0.0).smooth(path).path
    assert _improvement(_mvmt(path, 6), _mvmt(out, 6)) == pytest.approx(37.2, abs=1.0)
    assert _improvement(_orientation(path), _orientation(out)) == pytest.approx(28.5, abs=1.0)
    # the cusp stays where the path reverses: the reversing part still faces +y backwards
    assert np.allclose(out[6, :2], path[6, :2], atol=0.05)
    assert all(math.cos(out[i, 2] - math.pi / 2) > 0.9 for i in range(8, 12))


def test_anchoring_to_the_original_path_as_nav2() -> None:
    free = _smoother(w_smooth=30.0, w_curve=0.0).smooth(SHARP_TURN_90).path
    anchored = _smoother(w_smooth=30.0, w_curve=0.0, w_dist=30.0).smooth(SHARP_TURN_90).path

    def off(p: np.ndarray) -> np.ndarray:
        return np.hypot(*(p[:, :2] - SHARP_TURN_90[:, :2]).T)

    assert _improvement(off(free), off(anchored)) == pytest.approx(45.5, abs=1.0)


def _nav2_obstacle_costmap() -> Costmap2D:
    """DummyCostmapSubscriber: 10 x 10 m at 0.1 m, a lethal box x 1..3, y -2..-1 inflated
    (inscribed 0.3, cost_scaling_factor 1.6) within the window x -1..5, y -4..1."""
    cm = Costmap2D(100, 100, 0.1, -5.0, -5.0)
    for i in range(10, 60):
        for j in range(40, 100):
            dx = max(0, max(60 - j, j - 80))
            dy = max(0, max(30 - i, i - 40))
            dist = math.hypot(dx, dy) * 0.1
            if dist == 0:
                cost = 254
            elif dist < 0.3:
                cost = 253
            else:
                cost = int(252 * math.exp(-1.6 * (dist - 0.3)))
            cm.data[i, j] = cost
    return cm


def test_a_path_along_an_obstacle_moves_away_from_it() -> None:
    cm = _nav2_obstacle_costmap()
    footprint = np.array([[0.4, 0.25], [-0.4, 0.25], [-0.4, -0.25], [0.4, -0.25]])
    path = np.array([[0.05 + 0.4 * k, 0.05, 0.0] for k in range(11)])
    out = _smoother(w_cost=0.015).smooth(path, cm).path

    def cost(p: np.ndarray) -> np.ndarray:
        return np.array([score_obstacle_footprint(
            q[None, None, :], footprint, cm.data, cm.origin_x, cm.origin_y, cm.resolution,
            False)[0][0] for q in p])

    # Nav2 (Ceres) improves the footprint cost by 9.4 %; this solver by 11.3 %
    assert 8.0 < _improvement(cost(path), cost(out)) < 13.0
    assert out[5, 1] > 0.055 and (out[:, 1] >= 0.05 - 1e-9).all()  # pushed away (+y)
    # no large discontinuities: smoother than the path zig-zagged by 1 cm
    assert _improvement(_mvmt(_zig_zag(path, 0.01)), _mvmt(out)) > 0.0
    # without the costmap nothing pulls it: a straight line stays
    np.testing.assert_allclose(_smoother(w_cost=0.015).smooth(path).path[:, :2], path[:, :2],
                               atol=1e-9)


def test_residual_terms() -> None:
    s = ConstrainedSmoother(ConstrainedSmootherConfig(
        w_smooth=2.0, w_curve=30.0, w_dist=5.0, w_cost=0.0, minimum_turning_radius=0.4))
    # three points on a circle of radius 0.3: curvature 1/0.3 over the 1/0.4 allowed
    a = math.pi / 6
    path = np.array([[0.3 * math.sin(-a), 0.3 - 0.3 * math.cos(a), 0.0], [0.0, 0.0, 0.0],
                     [0.3 * math.sin(a), 0.3 - 0.3 * math.cos(a), 0.0], [0.3, 0.3, 0.0]])
    world, _, _ = s._directions(path)
    pb = s._build(world)
    moved = path[:, :2].copy()
    moved[1] += (0.0, -0.01)
    r = s._residuals(moved, pb, path[:, :2], None)
    center_r = s._residuals(path[:, :2], pb, path[:, :2], None)
    assert center_r[0, 1] == pytest.approx(30.0 * (1 / 0.3 - 1 / 0.4) ** 2, rel=1e-9)
    assert center_r[0, 2] == 0.0
    assert r[0, 2] == pytest.approx(5.0 * 0.01 ** 2)
    d = (path[2, :2] - path[1, :2]) - (path[1, :2] - path[0, :2])
    assert center_r[0, 0] == pytest.approx(2.0 * float(d @ d))
    wide = ConstrainedSmoother(ConstrainedSmootherConfig(minimum_turning_radius=0.25, w_cost=0.0))
    assert wide._residuals(path[:, :2], pb, path[:, :2], None)[0, 1] == 0.0


def test_bicubic_cost_is_ceres_catmull_rom() -> None:
    grid = np.zeros((6, 6), dtype=np.uint8)
    grid[2, 3] = 100
    # at cell centres it returns the cell; halfway between a peak and 0 the spline gives 56.25
    assert bicubic_cost(grid, np.array([2.0]), np.array([3.0]))[0] == pytest.approx(100.0)
    assert bicubic_cost(grid, np.array([2.0]), np.array([3.5]))[0] == pytest.approx(56.25)
    assert bicubic_cost(grid, np.array([2.0]), np.array([1.0]))[0] == pytest.approx(0.0)
    # beyond the grid the edge values extend
    assert bicubic_cost(grid, np.array([-3.0]), np.array([3.0]))[0] == pytest.approx(0.0)


def test_downsampling_and_upsampling() -> None:
    t = np.linspace(0.0, math.pi / 2, 31)
    path = np.stack([np.sin(t), 1.0 - np.cos(t), t], axis=1) * np.array([2.0, 2.0, 1.0])
    path[5:25, :2] += np.random.default_rng(0).normal(0.0, 0.01, (20, 2))
    down = _smoother(path_downsampling_factor=3, path_upsampling_factor=1, w_curve=0.0)
    out = down.smooth(path).path
    assert out.shape == path.shape
    np.testing.assert_allclose(out[[0, -1]], path[[0, -1]], atol=1e-12)
    assert _improvement(_mvmt(path), _mvmt(out)) > 35.0  # 42 % (refilled poses included)
    up = _smoother(path_downsampling_factor=3, path_upsampling_factor=2, w_curve=0.0)
    # twice the original granularity: 2 · 30 + 1 poses, the optimised ones at even indices
    fine = up.smooth(path).path
    assert fine.shape == (61, 3)
    np.testing.assert_allclose(fine[::2][[0, 1, 4, 7, 28, 29, 30], :2],
                               out[[0, 1, 4, 7, 28, 29, 30], :2], atol=1e-9)


def test_parameters_use_nav2_names() -> None:
    s = build_smoother("SmoothPath", {
        "plugin": "nav2_constrained_smoother::ConstrainedSmoother", "w_smooth": 15.0,
        "cost_check_points": [-0.185, 0.0, 1.0],
        "optimizer": {"max_iterations": 70, "gradient_tol": 5e3, "fn_tol": 1.0e-15,
                      "param_tol": 1.0e-20, "linear_solver_type": "DENSE_QR"}})
    assert isinstance(s, ConstrainedSmoother)
    assert s.config.w_smooth == 15.0 and s.config.cost_check_points == (-0.185, 0.0, 1.0)
    assert s.config.optimizer == ConstrainedOptimizerConfig(
        max_iterations=70, gradient_tol=5e3, fn_tol=1.0e-15, param_tol=1.0e-20,
        linear_solver_type="DENSE_QR")
    with pytest.raises(ParameterError, match=r"optimizer\.linear_solver_type"):
        _smoother(optimizer={"linear_solver_type": "ITERATIVE_SCHUR"})
    with pytest.raises(ParameterError, match=r"optimizer\.max_iters"):
        _smoother(optimizer={"max_iters": 5})
    with pytest.raises(ParameterError, match="cost_check_points"):
        _smoother(cost_check_points=[0.1, 0.0, 1.0, 0.2])


def test_cost_check_point_weights_are_normalised() -> None:
    cm = _nav2_obstacle_costmap()
    path = np.array([[0.05 + 0.4 * k, 0.05, 0.0] for k in range(11)])
    one = _smoother(w_cost=0.015, cost_check_points=[-0.2, 0.0, 1.0]).smooth(path, cm).path
    two = _smoother(w_cost=0.015, cost_check_points=[-0.2, 0.0, 2.0]).smooth(path, cm).path
    np.testing.assert_array_equal(one, two)
    assert not np.allclose(one, path)
