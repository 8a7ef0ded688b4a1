"""Collision monitor: stop, slowdown, limit and approach zones; source handling."""

from __future__ import annotations

import math

import numpy as np
import pytest

from eddiebot.nav.collision_monitor import (
    ActionType,
    build_collision_monitor,
    cloud_source_points,
    points_in_polygon,
    range_source_points,
    scan_source_points,
)
from eddiebot.nav.errors import ParameterError
from eddiebot.nav.types import Twist2D

SQUARE = "[[0.3, 0.3], [0.3, -0.3], [-0.3, -0.3], [-0.3, 0.3]]"


def _monitor(**polys):
    params = {"polygons": list(polys), "observation_sources": ["scan"], "stop_pub_timeout": 1.0}
    params.update(polys)
    return build_collision_monitor(params)


def _pts(*xy):
    return {"scan": np.array(xy, dtype=float).reshape(-1, 2)}


def test_stop_polygon() -> None:
    m = _monitor(Stop={"type": "polygon", "points": SQUARE, "action_type": "stop", "min_points": 2})
    out = m.process(Twist2D(0.4, 0, 0.2), _pts((0.2, 0.0)), 0)
    assert out.publish == Twist2D(0.4, 0, 0.2) and out.action == ActionType.DO_NOTHING
    out = m.process(Twist2D(0.4, 0, 0.2), _pts((0.2, 0.0), (0.1, 0.1)), 1)
    assert out.publish == Twist2D() and out.action == ActionType.STOP
    assert out.polygon_name == "Stop" and out.state_changed


def test_deprecated_max_points() -> None:
    m = _monitor(Stop={"type": "polygon", "points": SQUARE, "action_type": "stop", "max_points": 2})
    assert m.zones[0].min_points == 3


def test_slowdown_circle_strict_inside() -> None:
    m = _monitor(Slow={"type": "circle", "radius": 0.5, "action_type": "slowdown",
                       "slowdown_ratio": 0.3, "min_points": 1})
    out = m.process(Twist2D(0.5, 0, 1.0), _pts((0.5, 0.0)), 0)  # on the circle: not inside
    assert out.action == ActionType.DO_NOTHING
    out = m.process(Twist2D(0.5, 0, 1.0), _pts((0.49, 0.0)), 0)
    assert out.action == ActionType.SLOWDOWN
    assert out.publish == pytest.approx(Twist2D(0.15, 0, 0.3))


def test_limit_preserves_curvature() -> None:
    m = _monitor(Lim={"type": "circle", "radius": 1.0, "action_type": "limit",
                      "linear_limit": 0.2, "angular_limit": 0.5, "min_points": 1})
    out = m.process(Twist2D(0.4, 0, 0.5), _pts((0.5, 0.0)), 0)
    assert out.publish == pytest.approx(Twist2D(0.2, 0, 0.25))


def test_approach_scales_by_time_to_collision() -> None:
    m = _monitor(App={"type": "polygon", "points": SQUARE, "action_type": "approach",
                      "time_before_collision": 2.0, "simulation_time_step": 0.1, "min_points": 1})
    # Obstacle 1.0 m ahead at 0.5 m/s: the square's front (0.3) reaches x = 1.0 after
    # travelling 0.7 m, i.e. 14 steps -> upstream reports 13 * 0.1 = 1.3 s.
    out = m.process(Twist2D(0.5, 0, 0), _pts((1.0, 0.0)), 0)
    assert out.action == ActionType.APPROACH
    assert out.publish.vx == pytest.approx(0.5 * 1.3 / 2.0)
    # Far away: no action.
    out = m.process(Twist2D(0.5, 0, 0), _pts((3.0, 0.0)), 0)
    assert out.action == ActionType.DO_NOTHING and out.publish.vx == 0.5
    # Already inside: zero.
    out = m.process(Twist2D(0.5, 0, 0), _pts((0.1, 0.0)), 0)
    assert out.publish == Twist2D()


def test_safest_candidate_wins_and_stop_short_circuits() -> None:
    m = _monitor(
        Slow={"type": "circle", "radius": 1.0, "action_type": "slowdown", "slowdown_ratio": 0.5,
              "min_points": 1},
        Slower={"type": "circle", "radius": 1.0, "action_type": "slowdown", "slowdown_ratio": 0.2,
                "min_points": 1},
    )
    out = m.process(Twist2D(1.0, 0, 0), _pts((0.5, 0.0)), 0)
    assert out.polygon_name == "Slower" and out.publish.vx == pytest.approx(0.2)


def test_invalid_source_stops_and_zero_publish_timeout() -> None:
    m = _monitor(Stop={"type": "circle", "radius": 0.3, "action_type": "stop", "min_points": 1})
    s = 1_000_000_000
    out = m.process(Twist2D(0.3, 0, 0), {"scan": None}, 0)
    assert out.action == ActionType.STOP and out.polygon_name == "invalid source"
    assert out.publish == Twist2D()
    assert m.process(Twist2D(0.3, 0, 0), {"scan": None}, s // 2).publish == Twist2D()
    assert m.process(Twist2D(0.3, 0, 0), {"scan": None}, 2 * s).publish is None
    assert m.process(Twist2D(0.3, 0, 0), _pts((2.0, 0.0)), 3 * s).publish == Twist2D(0.3, 0, 0)


def test_sources_to_points() -> None:
    pts = scan_source_points([1.0, float("inf"), 0.01], -0.1, 0.1, 0.05, 5.0)
    assert pts.shape == (1, 2) and pts[0] == pytest.approx([math.cos(-0.1), math.sin(-0.1)])
    cloud = cloud_source_points([[1, 0, 0.01], [1, 0, 0.3], [1, 0, 2.0]], 0.05, 0.5)
    assert cloud.tolist() == [[1.0, 0.0]]
    arc = range_source_points(0.5, 0.02, 3.0, 0.4, (0.2, 0.0, 0.0), obstacles_angle=0.1)
    assert np.allclose(np.hypot(arc[:, 0] - 0.2, arc[:, 1]), 0.5)
    assert range_source_points(3.0, 0.02, 3.0, 0.4, (0.0, 0.0, 0.0)).shape == (0, 2)
    inside = points_in_polygon(np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float),
                               np.array([[0.5, 0.5], [1.5, 0.5]]))
    assert inside.tolist() == [True, False]


def test_bad_config_is_named() -> None:
    with pytest.raises(ParameterError) as exc:
        _monitor(P={"type": "polygon", "points": SQUARE, "action_type": "explode"})
    assert exc.value.key == "action_type"
    with pytest.raises(ParameterError) as exc:
        _monitor(P={"type": "polygon", "points": "[[0, 0], [1, 1]]", "action_type": "stop"})
    assert exc.value.key == "points"
