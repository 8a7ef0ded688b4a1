"""Collision monitor node: point-cloud heights, polygon sources, base shift correction,
dynamic zone shapes, published state and zone shapes, the lost-localization stop."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from eddiebot.core import Context
from eddiebot.core.tf import make_transform_2d
from eddiebot.msgs.geometry_msgs import (
    Point32,
    PolygonInstanceStamped,
    PolygonStamped,
    PoseWithCovarianceStamped,
    Twist,
)
from eddiebot.msgs.sensor_msgs import LaserScan, PointCloud2, PointField
from eddiebot.nav.collision_monitor import INVALID_SOURCE, ActionType
from eddiebot.nav.nodes.collision_monitor import CollisionMonitorNode

MS = 1_000_000
STOP = {"type": "circle", "radius": 0.5, "action_type": "stop", "min_points": 1}


class _Sink:
    def __init__(self) -> None:
        self.msgs: list[Any] = []

    def publish(self, msg: Any) -> None:
        self.msgs.append(msg)


def _stamp(msg: Any, ns: int) -> None:
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(ns, 1_000_000_000)


def _node(ctx: Context, sources: dict[str, dict[str, Any]], polygons: dict[str, dict[str, Any]],
          **extra: Any) -> tuple[CollisionMonitorNode, _Sink, _Sink]:
    params: dict[str, Any] = {"polygons": list(polygons), "observation_sources": list(sources),
                              "state_topic": "collision_monitor_state", **extra}
    for name, sub in {**sources, **polygons}.items():
        for k, v in sub.items():
            params[f"{name}.{k}"] = v
    node = CollisionMonitorNode(context=ctx, parameter_overrides=params)
    assert node.trigger_configure() == 97, node.last_error
    assert node.trigger_activate() == 97
    out, state = _Sink(), _Sink()
    node._pub, node._state_pub = out, state
    return node, out, state


def _cmd(node: CollisionMonitorNode, vx: float = 0.3) -> None:
    t = Twist()
    t.linear.x = vx
    node._on_cmd(t)


def _cloud(frame: str, pts: list[tuple[float, float, float]], stamp_ns: int) -> PointCloud2:
    arr = np.asarray(pts, dtype="<f4").reshape(-1, 3)
    msg = PointCloud2()
    _stamp(msg, stamp_ns)
    msg.header.frame_id = frame
    msg.height, msg.width = 1, arr.shape[0]
    msg.fields = [PointField(name=n, offset=4 * i, datatype=7, count=1) for i, n in enumerate("xyz")]
    msg.point_step, msg.row_step = 12, 12 * arr.shape[0]
    msg.is_bigendian, msg.is_dense = False, True
    msg.data = np.frombuffer(arr.tobytes(), dtype=np.uint8).copy()
    return msg


def _scan(frame: str, stamp_ns: int, ahead: float) -> LaserScan:
    msg = LaserScan()
    _stamp(msg, stamp_ns)
    msg.header.frame_id = frame
    msg.angle_min, msg.angle_increment = -0.1, 0.1
    msg.range_min, msg.range_max = 0.05, 5.0
    msg.ranges = np.array([math.inf, ahead, math.inf], dtype=np.float32)
    return msg


@pytest.fixture
def ctx():
    c = Context(use_sim_time=True)
    yield c
    c.shutdown()


def test_pointcloud_heights_and_state(ctx) -> None:
    node, out, state = _node(ctx, {"cloud": {"type": "pointcloud", "topic": "points",
                                             "min_height": 0.05, "max_height": 0.5}},
                             {"StopCircle": STOP}, base_shift_correction=False)
    # the camera 0.6 m up, looking forward (its z axis is up like the base here)
    node.tf_buffer.set_transform_static(_tf3("base_footprint", "camera", 0.0, 0.0, 0.6))
    ctx.sim_clock.set_ns(100 * MS)
    # 0.3 m ahead at z 0.7 (above the robot) and at z 0.02 (the floor): ignored
    node._source_callback("cloud")(_cloud("camera", [(0.3, 0.0, 0.1), (0.3, 0.0, -0.58)], 90 * MS))
    _cmd(node)
    assert out.msgs[-1].linear.x == pytest.approx(0.3) and not state.msgs
    # 0.3 m ahead at z 0.3: inside the height band and the stop circle
    node._source_callback("cloud")(_cloud("camera", [(0.3, 0.0, -0.3)], 95 * MS))
    _cmd(node)
    assert out.msgs[-1].linear.x == 0.0
    assert (state.msgs[-1].action_type, state.msgs[-1].polygon_name) == (ActionType.STOP, "StopCircle")


def _tf3(parent: str, child: str, x: float, y: float, z: float) -> Any:
    t = make_transform_2d(parent, child, 0, x, y, 0.0)
    t.transform.translation.z = z
    return t


def test_polygon_source_replaces_by_id_and_times_out(ctx) -> None:
    node, out, state = _node(ctx, {"zone": {"type": "polygon", "topic": "obstacles",
                                            "source_timeout": 1.0, "sampling_distance": 0.05}},
                             {"StopCircle": STOP}, base_shift_correction=False)

    def shape(pid: int, cx: float, stamp_ns: int) -> PolygonInstanceStamped:
        msg = PolygonInstanceStamped()
        _stamp(msg, stamp_ns)
        msg.header.frame_id = "base_footprint"
        msg.polygon.id = pid
        msg.polygon.polygon.points = [Point32(x=cx + dx, y=dy, z=0.0)
                                      for dx, dy in ((0, -0.2), (0.3, -0.2), (0.3, 0.2), (0, 0.2))]
        return msg

    ctx.sim_clock.set_ns(1000 * MS)
    _cmd(node)  # nothing received yet: invalid source
    assert state.msgs[-1].polygon_name == INVALID_SOURCE and out.msgs[-1].linear.x == 0.0
    node._source_callback("zone")(shape(1, 0.3, 1000 * MS))  # edge at 0.3 m: inside r 0.5
    _cmd(node)
    assert state.msgs[-1].polygon_name == "StopCircle"
    node._source_callback("zone")(shape(1, 1.5, 1000 * MS))  # same id, moved away
    _cmd(node)
    assert out.msgs[-1].linear.x == pytest.approx(0.3) and state.msgs[-1].polygon_name == ""
    node._source_callback("zone")(shape(2, 1.0, 1000 * MS))  # a second shape, also clear
    _cmd(node)
    assert out.msgs[-1].linear.x == pytest.approx(0.3)
    ctx.sim_clock.set_ns(2100 * MS)  # both older than source_timeout
    _cmd(node)
    assert state.msgs[-1].polygon_name == INVALID_SOURCE


def test_base_shift_correction_moves_old_points_with_the_robot(ctx) -> None:
    stop = {"type": "circle", "radius": 0.4, "action_type": "stop", "min_points": 1}
    for correction, expect_stop in ((True, True), (False, False)):
        node, out, _ = _node(ctx, {"scan": {"type": "scan", "topic": f"scan_{correction}"}},
                             {"Stop": stop}, base_shift_correction=correction)
        node.tf_buffer.set_transform_static(make_transform_2d("base_footprint", "laser", 0, 0, 0, 0))
        # scanned at 1.0 s at odom x 0 (obstacle 0.7 m ahead); the robot then drove 0.5 m
        node.tf_buffer.set_transform(make_transform_2d("odom", "base_footprint", 1000 * MS, 0, 0, 0))
        node.tf_buffer.set_transform(make_transform_2d("odom", "base_footprint", 1500 * MS, 0.5, 0, 0))
        ctx.sim_clock.set_ns(1500 * MS)
        node._source_callback("scan")(_scan("laser", 1000 * MS, 0.7))
        _cmd(node)
        assert (out.msgs[-1].linear.x == 0.0) == expect_stop
        node.trigger_deactivate()
        node.destroy_node()


def test_scan_newer_than_odometry_is_still_valid(ctx) -> None:
    node, out, state = _node(ctx, {"scan": {"type": "scan", "topic": "scan"}}, {"Stop": STOP})
    node.tf_buffer.set_transform_static(make_transform_2d("base_footprint", "laser", 0, 0, 0, 0))
    node.tf_buffer.set_transform(make_transform_2d("odom", "base_footprint", 1000 * MS, 0, 0, 0))
    ctx.sim_clock.set_ns(1030 * MS)
    node._source_callback("scan")(_scan("laser", 1030 * MS, 2.0))  # odometry not there yet
    _cmd(node)
    assert out.msgs[-1].linear.x == pytest.approx(0.3) and not state.msgs
    node._source_callback("scan")(_scan("laser", 1300 * MS, 2.0))  # beyond transform_tolerance
    _cmd(node)
    assert state.msgs[-1].polygon_name == INVALID_SOURCE


def test_dynamic_zone_shape_and_visualization(ctx) -> None:
    node, out, state = _node(
        ctx, {"scan": {"type": "scan", "topic": "scan", "source_timeout": 0.0}},
        {"Dyn": {"type": "polygon", "action_type": "stop", "min_points": 1,
                 "polygon_sub_topic": "dyn_shape", "visualize": True}},
        base_shift_correction=False)
    viz = _Sink()
    node._viz_pubs["Dyn"] = viz
    node.tf_buffer.set_transform_static(make_transform_2d("base_footprint", "laser", 0, 0.2, 0, math.pi))
    node._source_callback("scan")(_scan("laser", 0, 0.5))  # the laser looks backwards: x = -0.3
    _cmd(node)
    assert out.msgs[-1].linear.x == pytest.approx(0.3)  # no shape yet
    shape = PolygonStamped()
    shape.header.frame_id = "laser"  # a box 0.2..0.6 m ahead of the laser = behind the robot
    shape.polygon.points = [Point32(x=x, y=y, z=0.0)
                            for x, y in ((0.2, -0.2), (0.6, -0.2), (0.6, 0.2), (0.2, 0.2))]
    node._shape_callback("Dyn")(shape)
    poly = node.monitor.zone("Dyn").poly
    assert poly is not None and poly[:, 0].min() == pytest.approx(-0.4)
    _cmd(node)
    assert out.msgs[-1].linear.x == 0.0 and state.msgs[-1].polygon_name == "Dyn"
    assert len(viz.msgs[-1].polygon.points) == 4 and viz.msgs[-1].header.frame_id == "base_footprint"


def test_bad_source_type_is_named(ctx) -> None:
    node = CollisionMonitorNode(context=ctx, parameter_overrides={
        "polygons": ["Stop"], "observation_sources": ["s"], "s.type": "sonar", "s.topic": "x",
        **{f"Stop.{k}": v for k, v in STOP.items()}})
    assert node.trigger_configure() == 98
    assert "s.type" in node.last_error


def test_lost_localization_stops_autonomous_commands(ctx) -> None:
    node, out, state = _node(ctx, {"scan": {"type": "scan", "topic": "scan", "source_timeout": 0.0}},
                             {"Stop": STOP}, localization_check=True, localization_tf_timeout=1.0,
                             localization_max_xy_std=0.5)
    ctx.sim_clock.set_ns(5000 * MS)
    _cmd(node)
    assert out.msgs[-1].linear.x == 0.0 and "no map -> odom" in state.msgs[-1].polygon_name
    # AMCL's transform, future-dated by its transform_tolerance (1 s): fresh
    node.tf_buffer.set_transform(make_transform_2d("map", "odom", 5900 * MS, 1.0, 2.0, 0.0))
    _cmd(node)
    assert out.msgs[-1].linear.x == pytest.approx(0.3) and state.msgs[-1].polygon_name == ""
    # the localization's covariance blows up (global localization, kidnapping): stop
    pose = PoseWithCovarianceStamped()
    cov = [0.0] * 36
    cov[0] = cov[7] = 4.0
    pose.pose.covariance = cov
    assert node._watch is not None
    node._watch._on_pose(pose)
    _cmd(node)
    assert out.msgs[-1].linear.x == 0.0 and "position std 2.00 m" in state.msgs[-1].polygon_name
    cov[0] = cov[7] = 0.01
    pose.pose.covariance = cov
    node._watch._on_pose(pose)
    _cmd(node)
    assert out.msgs[-1].linear.x == pytest.approx(0.3)
    # no scan for a while: map -> odom goes stale 1 s after its (future) stamp
    ctx.sim_clock.set_ns(6800 * MS)
    _cmd(node)
    assert out.msgs[-1].linear.x == pytest.approx(0.3)
    ctx.sim_clock.set_ns(7000 * MS)
    _cmd(node)
    assert out.msgs[-1].linear.x == 0.0 and "stale" in state.msgs[-1].polygon_name


def _costmap(stamp_ns: int, lethal: list[tuple[float, float]]) -> Any:
    """A 2 x 2 m odom-frame costmap at 0.05 m, origin (-1, -1), lethal at the given points."""
    from eddiebot.msgs.nav2_msgs import Costmap

    data = np.zeros((40, 40), dtype=np.uint8)
    for x, y in lethal:
        data[int((y + 1.0) / 0.05), int((x + 1.0) / 0.05)] = 254
    msg = Costmap()
    _stamp(msg, stamp_ns)
    msg.header.frame_id = "odom"
    msg.metadata.resolution, msg.metadata.size_x, msg.metadata.size_y = 0.05, 40, 40
    msg.metadata.origin.position.x = msg.metadata.origin.position.y = -1.0
    msg.data = data.ravel()
    return msg


def test_costmap_source_approach_behind_the_robot(ctx) -> None:
    # a jamb the robot's forward sensors no longer see, 0.30 m behind the base (cell centre
    # (-0.325, 0.025)): the approach zone on the costmap slows backing into it, lets driving
    # away through; the scan (nothing ahead) is not used by that zone
    approach = {"type": "circle", "radius": 0.23, "action_type": "approach", "min_points": 1,
                "time_before_collision": 1.0, "simulation_time_step": 0.05,
                "sources_names": ["local_costmap"]}
    node, out, state = _node(
        ctx, {"scan": {"type": "scan", "topic": "scan", "source_timeout": 0.0},
              "local_costmap": {"type": "costmap", "topic": "/local_costmap/costmap_raw",
                                "cost_threshold": 254, "treat_unknown_as_obstacle": False}},
        {"CostmapApproach": approach})
    node.tf_buffer.set_transform(make_transform_2d("odom", "base_footprint", 1000 * MS, 0, 0, 0))
    ctx.sim_clock.set_ns(1000 * MS)
    node._source_callback("local_costmap")(_costmap(900 * MS, [(-0.32, 0.03)]))
    _cmd(node, -0.15)  # 0.097 m to go at 0.15 m/s: 0.6 s (upstream's step) of the 1.0 s
    assert out.msgs[-1].linear.x == pytest.approx(-0.15 * 0.6)
    assert (state.msgs[-1].action_type, state.msgs[-1].polygon_name) == (ActionType.APPROACH,
                                                                        "CostmapApproach")
    _cmd(node, 0.15)
    assert out.msgs[-1].linear.x == pytest.approx(0.15)
    # the cell within the body's 0.23 m: no translation either way
    node._source_callback("local_costmap")(_costmap(950 * MS, [(-0.20, 0.03)]))
    _cmd(node, -0.15)
    assert out.msgs[-1].linear.x == 0.0


def test_costmap_source_bad_threshold_is_named(ctx) -> None:
    node = CollisionMonitorNode(context=ctx, parameter_overrides={
        "polygons": ["Stop"], "observation_sources": ["cm"], "cm.type": "costmap",
        "cm.topic": "/local_costmap/costmap_raw", "cm.cost_threshold": 300,
        **{f"Stop.{k}": v for k, v in STOP.items()}})
    assert node.trigger_configure() == 98
    assert "cm.cost_threshold" in node.last_error and "0-255" in node.last_error
