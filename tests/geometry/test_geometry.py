import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from eddiebot.geometry import (
    Pose2D,
    matrix_to_quaternion,
    matrix_to_se2,
    quaternion_multiply,
    quaternion_to_matrix,
    quaternion_to_rpy,
    quaternion_to_yaw,
    rpy_to_quaternion,
    se2_between,
    se2_compose,
    se2_interpolate,
    se2_inverse,
    se2_to_matrix,
    se2_transform_points,
    se3_from_tq,
    se3_interpolate,
    se3_inverse,
    se3_to_tq,
    se3_transform_points,
    slerp,
    wrap_angle,
    yaw_to_quaternion,
)

finite = st.floats(-100, 100, allow_nan=False)
angle = st.floats(-10, 10, allow_nan=False)


def test_wrap_angle_half_open_interval():
    assert wrap_angle(math.pi) == pytest.approx(math.pi)
    assert wrap_angle(-math.pi) == pytest.approx(math.pi)
    assert wrap_angle(3 * math.pi / 2) == pytest.approx(-math.pi / 2)
    a = wrap_angle(np.linspace(-20, 20, 1001))
    assert np.all(a > -math.pi) and np.all(a <= math.pi)


def test_compose_known_values():
    a = np.array([1.0, 2.0, math.pi / 2])
    b = np.array([1.0, 0.0, 0.0])
    np.testing.assert_allclose(se2_compose(a, b), [1.0, 3.0, math.pi / 2], atol=1e-12)


@given(finite, finite, angle, finite, finite, angle)
def test_compose_matches_matrices(x1, y1, t1, x2, y2, t2):
    a, b = np.array([x1, y1, t1]), np.array([x2, y2, t2])
    via_m = matrix_to_se2(se2_to_matrix(a) @ se2_to_matrix(b))
    got = se2_compose(a, b)
    np.testing.assert_allclose(got[:2], via_m[:2], atol=1e-9)
    assert abs(wrap_angle(got[2] - via_m[2])) < 1e-9


@given(finite, finite, angle)
def test_inverse_and_between(x, y, t):
    a = np.array([x, y, t])
    np.testing.assert_allclose(se2_compose(a, se2_inverse(a)), [0, 0, 0], atol=1e-9)
    b = np.array([1.0, -2.0, 0.3])
    np.testing.assert_allclose(se2_compose(a, se2_between(a, b))[:2], b[:2], atol=1e-9)


def test_vectorised_over_leading_dims():
    a = np.zeros((5, 3))
    a[:, 0] = np.arange(5)
    b = np.tile([0.0, 1.0, 0.5], (5, 1))
    out = se2_compose(a, b)
    assert out.shape == (5, 3)
    np.testing.assert_allclose(out[:, 1], 1.0)


def test_transform_points_and_interpolate():
    pts = se2_transform_points([1, 1, math.pi / 2], np.array([[1.0, 0.0], [0.0, 1.0]]))
    np.testing.assert_allclose(pts, [[1, 2], [0, 1]], atol=1e-12)
    mid = se2_interpolate([0, 0, 3.0], [2, 0, -3.0], 0.5)
    assert mid[0] == pytest.approx(1.0)
    # shortest arc through ±π, not through 0
    assert abs(abs(mid[2]) - math.pi) < 1e-9


def test_quaternions():
    q = yaw_to_quaternion(0.7)
    assert quaternion_to_yaw(*q) == pytest.approx(0.7)
    q2 = rpy_to_quaternion(0.1, -0.2, 0.3)
    assert quaternion_to_rpy(*q2) == pytest.approx((0.1, -0.2, 0.3))
    m = quaternion_to_matrix(q2)
    np.testing.assert_allclose(m @ m.T, np.eye(3), atol=1e-12)
    back = matrix_to_quaternion(m)
    np.testing.assert_allclose(back, np.asarray(q2) * np.sign(q2[3]), atol=1e-12)
    composed = quaternion_multiply(yaw_to_quaternion(0.2), yaw_to_quaternion(0.3))
    assert quaternion_to_yaw(*composed) == pytest.approx(0.5)
    half = slerp(yaw_to_quaternion(0.0), yaw_to_quaternion(1.0), 0.5)
    assert quaternion_to_yaw(*half) == pytest.approx(0.5)


def test_se3():
    t = se3_from_tq([1, 2, 3], rpy_to_quaternion(-math.pi / 2, 0, -math.pi / 2))
    np.testing.assert_allclose(t @ se3_inverse(t), np.eye(4), atol=1e-12)
    # optical frame: z forward maps to base x
    p = se3_transform_points(t, np.array([[0.0, 0.0, 1.0]]))
    np.testing.assert_allclose(p, [[2, 2, 3]], atol=1e-12)
    tr, _q = se3_to_tq(t)
    np.testing.assert_allclose(tr, [1, 2, 3])
    mid = se3_interpolate(np.eye(4), se3_from_tq([2, 0, 0], yaw_to_quaternion(1.0)), 0.5)
    np.testing.assert_allclose(mid[:3, 3], [1, 0, 0])
    assert quaternion_to_yaw(*se3_to_tq(mid)[1]) == pytest.approx(0.5)


def test_pose2d():
    a = Pose2D(1.0, 0.0, math.pi / 2)
    b = a.compose(Pose2D(1.0, 0.0, 0.0))
    assert b.x == pytest.approx(1.0) and b.y == pytest.approx(1.0)
    assert a.between(b) == pytest.approx(Pose2D(1.0, 0.0, 0.0))
    assert a.inverse().compose(a) == pytest.approx(Pose2D())
    with pytest.raises(ValueError, match="last dimension 3"):
        Pose2D.from_array([1.0, 2.0])
