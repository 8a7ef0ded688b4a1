"""Collision monitor: stop, slowdown, limit and approach zones; circles, polygons, velocity
polygons and dynamic shapes; source handling."""

from __future__ import annotations

import math

import numpy as np
import pytest
from navtest_helpers import eddie_collision_monitor

from eddiebot.nav.collision_monitor import (
    ActionType,
    VelocitySubPolygon,
    build_collision_monitor,
    cloud_source_points,
    costmap_source_points,
    points_in_polygon,
    polygon_source_points,
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
    assert range_source_points(3.01, 0.02, 3.0, 0.4, (0.0, 0.0, 0.0)).shape == (0, 2)
    assert range_source_points(3.0, 0.02, 3.0, 0.4, (0.0, 0.0, 0.0)).shape[0] > 0  # inclusive
    assert range_source_points(math.inf, 0.02, 3.0, 0.4, (0.0, 0.0, 0.0)).shape == (0, 2)
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


def _vel_monitor(holonomic: bool = False):
    slow = "[[0.4, 0.3], [0.4, -0.3], [-0.3, -0.3], [-0.3, 0.3]]"
    fast = "[[1.0, 0.3], [1.0, -0.3], [-0.3, -0.3], [-0.3, 0.3]]"
    back = "[[0.3, 0.3], [0.3, -0.3], [-0.8, -0.3], [-0.8, 0.3]]"
    return _monitor(VP={
        "type": "velocity_polygon", "action_type": "stop", "min_points": 1,
        "holonomic": holonomic, "velocity_polygons": ["slow", "fast", "back"],
        "slow": {"points": slow, "linear_min": 0.0, "linear_max": 0.3,
                 "theta_min": -1.0, "theta_max": 1.0},
        "fast": {"points": fast, "linear_min": 0.3, "linear_max": 1.0,
                 "theta_min": -1.0, "theta_max": 1.0},
        "back": {"points": back, "linear_min": -1.0, "linear_max": 0.0,
                 "theta_min": -1.0, "theta_max": 1.0},
    })


def test_velocity_polygon_selects_sub_polygon_by_velocity() -> None:
    m = _vel_monitor()
    ahead = _pts((0.7, 0.0))
    # slow (vx 0.2): the 0.4 m box misses the point 0.7 m ahead
    out = m.process(Twist2D(0.2, 0, 0), ahead, 0)
    assert out.action == ActionType.DO_NOTHING and m.zones[0].active_sub_polygon == "slow"
    # fast (vx 0.5): the 1.0 m box holds it -> stop
    out = m.process(Twist2D(0.5, 0, 0), ahead, 0)
    assert out.action == ActionType.STOP and out.polygon_name == "VP"
    assert m.zones[0].active_sub_polygon == "fast"
    # first match in list order: vx 0.3 is in both slow and fast -> slow
    m.process(Twist2D(0.3, 0, 0), ahead, 0)
    assert m.zones[0].active_sub_polygon == "slow"
    # reversing: the box reaches behind
    out = m.process(Twist2D(-0.2, 0, 0), _pts((-0.6, 0.0)), 0)
    assert out.action == ActionType.STOP and m.zones[0].active_sub_polygon == "back"
    # no sub-polygon covers wz = 2: the previous one (back) stays
    out = m.process(Twist2D(0.5, 0, 2.0), _pts((-0.6, 0.0)), 0)
    assert out.action == ActionType.STOP and m.zones[0].active_sub_polygon == "back"


def test_velocity_polygon_without_a_match_yet_has_no_shape() -> None:
    m = _vel_monitor()
    out = m.process(Twist2D(0.0, 0, 3.0), _pts((0.0, 0.0)), 0)  # wz out of every range
    assert out.action == ActionType.DO_NOTHING and not m.zones[0].shape_set


def test_holonomic_direction_ranges() -> None:
    sub = VelocitySubPolygon("left", ((0, 0), (1, 0), (1, 1)), -1.0, 1.0, -1.0, 1.0,
                             direction_end_angle=2.0, direction_start_angle=1.0)
    assert sub.in_range(Twist2D(0.0, 0.3, 0.0), holonomic=True)  # atan2 = pi/2
    assert not sub.in_range(Twist2D(0.3, 0.0, 0.0), holonomic=True)  # atan2 = 0
    assert sub.in_range(Twist2D(0.3, 0.0, 0.0), holonomic=False)  # direction ignored
    wrap = VelocitySubPolygon("rear", ((0, 0), (1, 0), (1, 1)), -1.0, 1.0, -1.0, 1.0,
                              direction_end_angle=-2.5, direction_start_angle=2.5)
    assert wrap.in_range(Twist2D(-0.3, 0.01, 0.0), holonomic=True)  # near +pi
    assert wrap.in_range(Twist2D(-0.3, -0.01, 0.0), holonomic=True)  # near -pi
    assert not wrap.in_range(Twist2D(0.0, 0.3, 0.0), holonomic=True)


def test_velocity_polygon_bad_config_is_named() -> None:
    with pytest.raises(ParameterError) as exc:
        _monitor(VP={"type": "velocity_polygon", "action_type": "stop",
                     "velocity_polygons": ["a"], "a": {"points": SQUARE, "linear_min": 0.0}})
    assert exc.value.key == "a.linear_max"
    with pytest.raises(ParameterError) as exc:
        _monitor(VP={"type": "velocity_polygon", "action_type": "stop"})
    assert exc.value.key == "velocity_polygons"


def test_dynamic_polygon_waits_for_its_shape() -> None:
    m = _monitor(Dyn={"type": "polygon", "action_type": "stop", "min_points": 1,
                      "polygon_sub_topic": "stop_shape"},
                 App={"type": "polygon", "action_type": "approach", "min_points": 1})
    assert m.zone("Dyn").dynamic_topic == "stop_shape"
    assert m.zone("App").dynamic_topic == "local_costmap/published_footprint"
    out = m.process(Twist2D(0.3, 0, 0), _pts((0.1, 0.0)), 0)
    assert out.action == ActionType.DO_NOTHING  # no shape yet: skipped
    m.zone("Dyn").set_polygon([[0.3, 0.3], [0.3, -0.3], [-0.3, -0.3], [-0.3, 0.3]])
    out = m.process(Twist2D(0.3, 0, 0), _pts((0.1, 0.0)), 0)
    assert out.action == ActionType.STOP and out.polygon_name == "Dyn"
    with pytest.raises(ParameterError):
        _monitor(P={"type": "polygon", "action_type": "stop"})  # no points, no topic


def test_min_points_counts_across_sources_of_the_zone() -> None:
    params = {"polygons": ["Stop"], "observation_sources": ["scan", "ir"],
              "Stop": {"type": "circle", "radius": 0.5, "action_type": "stop", "min_points": 3,
                       "sources_names": ["scan", "ir"]}}
    m = build_collision_monitor(params)
    two = {"scan": np.array([[0.1, 0.0], [0.2, 0.0]]), "ir": np.zeros((0, 2))}
    assert m.process(Twist2D(0.2, 0, 0), two, 0).action == ActionType.DO_NOTHING
    three = {"scan": two["scan"], "ir": np.array([[0.3, 0.1]])}
    assert m.process(Twist2D(0.2, 0, 0), three, 0).action == ActionType.STOP
    # a zone listening to the scan only ignores the IR point
    params["Stop"]["sources_names"] = ["scan"]
    m = build_collision_monitor(params)
    assert m.process(Twist2D(0.2, 0, 0), three, 0).action == ActionType.DO_NOTHING


def test_stop_reason_overrides_and_is_reported() -> None:
    m = _monitor(Slow={"type": "circle", "radius": 0.5, "action_type": "slowdown", "min_points": 1})
    out = m.process(Twist2D(0.3, 0, 0), _pts((2.0, 0.0)), 0, stop_reason="localization lost")
    assert out.publish == Twist2D() and out.action == ActionType.STOP
    assert out.polygon_name == "localization lost" and out.state_changed
    out = m.process(Twist2D(0.3, 0, 0), _pts((2.0, 0.0)), 1)
    assert out.publish == Twist2D(0.3, 0, 0) and out.state_changed and out.polygon_name == ""


def test_lost_localization_stops_translation_but_lets_a_turn_in_place_through() -> None:
    # AMCL only updates after the robot moves: a full stop would never let it recover
    m = _monitor(Stop={"type": "circle", "radius": 0.3, "action_type": "stop", "min_points": 1})
    out = m.process(Twist2D(0.3, 0, 0.8), _pts((2.0, 0.0)), 0, stop_reason="localization lost")
    assert out.publish == Twist2D(0.0, 0.0, 0.8) and out.action == ActionType.STOP
    assert out.polygon_name == "localization lost"
    # ... but not when a stop zone holds too, nor when a source is stale
    out = m.process(Twist2D(0.3, 0, 0.8), _pts((0.2, 0.0)), 1, stop_reason="localization lost")
    assert out.publish == Twist2D()
    out = m.process(Twist2D(0.3, 0, 0.8), {"scan": None}, 2, stop_reason="localization lost")
    assert out.publish == Twist2D()


def test_polygon_source_samples_outlines() -> None:
    pts = polygon_source_points([[[0, 0], [1, 0], [1, 0.25]]], sampling_distance=0.1)
    # edges of 1.0, 0.25 and hypot(1, 0.25) m: 10, 3 and 11 steps, both ends included
    assert pts.shape == (11 + 4 + 12, 2)
    assert np.allclose(pts[:11, 1], 0.0) and np.allclose(pts[:11, 0], np.linspace(0, 1, 11))
    assert polygon_source_points([], 0.1).shape == (0, 2)


def test_eddie_near_wall_zone_limits_speed_but_keeps_turning() -> None:
    m, quiet = eddie_collision_monitor()
    wall = {**quiet, "scan": np.array([[0.42, 0.05], [0.42, -0.05]])}  # inside 0.5 m, outside the stop zone
    spin = m.process(Twist2D(0.0, 0.0, 1.2), wall, 0)
    assert spin.action == ActionType.LIMIT and spin.polygon_name == "NearWallLimit"
    assert spin.publish == Twist2D(0.0, 0.0, pytest.approx(1.0))  # 57 deg/s, not a crawl
    slow = m.process(Twist2D(0.3, 0.0, 0.2), wall, 1)
    assert slow.publish.vx == pytest.approx(0.2) and slow.publish.wz == pytest.approx(0.2 * 0.2 / 0.3)
    gentle = m.process(Twist2D(0.0, 0.0, 0.5), wall, 2)
    assert gentle.publish == Twist2D(0.0, 0.0, 0.5)  # under both limits: untouched


def test_eddie_stop_zone_lets_the_robot_turn_or_back_off_what_stands_ahead() -> None:
    """The shipped StopZone: a person who stopped 3 cm from Eddie's front (0.27 m from its
    centre) stops driving at it, but not a turn in place or backing away; a return 1.5 cm
    from the footprint stops the turn too. Behind, the mirror image."""
    m, quiet = eddie_collision_monitor()

    def run(cmd: Twist2D, *xy: tuple[float, float]) -> tuple[ActionType, Twist2D | None]:
        out = m.process(cmd, {**quiet, "scan": np.array(xy, dtype=float)}, 0)
        return out.action, out.publish

    forward, back, turn = Twist2D(0.2, 0.0, 0.1), Twist2D(-0.1, 0.0, 0.0), Twist2D(0.0, 0.0, 1.0)
    assert run(forward, (0.27, 0.05)) == (ActionType.STOP, Twist2D())
    assert run(turn, (0.27, 0.05)) == (ActionType.DO_NOTHING, turn)
    assert run(back, (0.27, 0.05)) == (ActionType.DO_NOTHING, back)
    assert run(turn, (0.24, 0.0)) == (ActionType.STOP, Twist2D())
    assert run(back, (-0.27, 0.05)) == (ActionType.STOP, Twist2D())
    assert run(forward, (-0.27, 0.05)) == (ActionType.DO_NOTHING, forward)
    assert run(forward, (-0.24, 0.0)) == (ActionType.STOP, Twist2D())  # an arc swings the back


def test_costmap_source_cells_over_threshold() -> None:
    # 4 x 3 cells of 0.1 m, origin (1.0, 2.0): lethal (1, 0), inscribed (2, 1), unknown (3, 2)
    data = np.zeros((3, 4), dtype=np.uint8)
    data[0, 1], data[1, 2], data[2, 3], data[2, 0] = 254, 253, 255, 252
    pts = costmap_source_points(data.ravel(), 4, 3, 0.1, (1.0, 2.0))
    assert np.allclose(pts, [[1.15, 2.05], [1.25, 2.15], [1.35, 2.25]])
    lethal = costmap_source_points(data.ravel(), 4, 3, 0.1, (1.0, 2.0), 254, False)
    assert np.allclose(lethal, [[1.15, 2.05]])
    # the costmap frame 1 m behind the base and turned by 90 degrees
    moved = costmap_source_points(data.ravel(), 4, 3, 0.1, (1.0, 2.0), 254, False,
                                  (-1.0, 0.0, math.pi / 2))
    assert np.allclose(moved, [[-1.0 - 2.05, 1.15]])
