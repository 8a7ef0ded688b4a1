"""The costmap's bus side: a rolling odom-frame costmap places the static map through the
current map -> odom transform, and scans land where the sensor was when they were taken."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from eddiebot.core import Context
from eddiebot.maps import OccupancyMap
from eddiebot.maps.grid import map_to_msg
from eddiebot.msgs.builtin_interfaces import Time
from eddiebot.msgs.geometry_msgs import Quaternion, Transform, TransformStamped, Vector3
from eddiebot.msgs.sensor_msgs import LaserScan
from eddiebot.msgs.std_msgs import Header
from eddiebot.nav.cost_values import LETHAL_OBSTACLE
from eddiebot.nav.nodes._common import flatten_params
from eddiebot.nav.nodes.controller_server import ControllerServer

RES = 0.05


def _stamp(ns: int) -> Time:
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def _tf(parent: str, child: str, x: float, y: float, yaw: float, ns: int) -> TransformStamped:
    return TransformStamped(
        header=Header(stamp=_stamp(ns), frame_id=parent), child_frame_id=child,
        transform=Transform(translation=Vector3(x=x, y=y, z=0.0),
                            rotation=Quaternion(x=0.0, y=0.0, z=math.sin(yaw / 2),
                                                w=math.cos(yaw / 2))))


def _server(plugins: list[str], **layers: Any) -> tuple[Context, ControllerServer]:
    local = {"global_frame": "odom", "robot_base_frame": "base_link", "rolling_window": True,
             "width": 6, "height": 6, "resolution": RES, "robot_radius": 0.2,
             "update_frequency": 5.0, "publish_frequency": 0.0, "transform_tolerance": 0.3,
             "plugins": plugins, **layers}
    params = {"controller_plugins": ["FollowPath"], "local_costmap": local,
              "FollowPath": {"plugin": "nav2_regulated_pure_pursuit_controller::"
                                       "RegulatedPurePursuitController"}}
    ctx = Context(use_sim_time=True)
    node = ControllerServer(context=ctx, parameter_overrides=flatten_params(params))
    assert node.trigger_configure() == 97 or node.host is not None, node.last_error
    assert node.host is not None, node.last_error
    return ctx, node


def _lethal_xy(node: ControllerServer) -> np.ndarray:
    m = node.host.costmap.master
    jj, ii = np.nonzero(m.data == LETHAL_OBSTACLE)
    return np.column_stack([m.origin_x + (ii + 0.5) * m.resolution,
                            m.origin_y + (jj + 0.5) * m.resolution])


def test_rolling_static_layer_follows_map_to_odom() -> None:
    # one wall in the map frame: the line x = 2.0 m, y in [0, 4) m
    data = np.zeros((120, 120), dtype=np.int8)
    data[0:80, 40] = 100
    occ = OccupancyMap(data, RES, (0.0, 0.0, 0.0), "map")
    ctx, node = _server(["static_layer"], static_layer={"plugin": "nav2_costmap_2d::StaticLayer"})
    try:
        # odom sits 1.0 m, 0.5 m, 90 degrees off the map frame; the robot at the odom origin
        mo = (1.0, 0.5, math.pi / 2)
        node.tf_buffer.set_transform(_tf("map", "odom", *mo, 10**9))
        node.tf_buffer.set_transform(_tf("odom", "base_link", 0.0, 0.0, 0.0, 10**9))
        ctx.sim_clock.set_ns(10**9)
        node.host._on_map(map_to_msg(occ, frame_id="map"))
        odom_xy = _lethal_xy(node)
        assert len(odom_xy) > 40
        # every lethal cell, taken back to the map frame, is on the wall
        c, s = math.cos(mo[2]), math.sin(mo[2])
        map_x = mo[0] + c * odom_xy[:, 0] - s * odom_xy[:, 1]
        map_y = mo[1] + s * odom_xy[:, 0] + c * odom_xy[:, 1]
        on_wall = (np.abs(map_x - 2.025) <= RES) & (map_y >= -RES) & (map_y <= 4.0 + RES)
        assert on_wall.all(), f"{(~on_wall).sum()} of {len(odom_xy)} lethal cells off the wall"
        # localization corrects map -> odom by 0.3 m: the wall moves with it at the next update
        node.tf_buffer.set_transform(_tf("map", "odom", 1.3, 0.5, math.pi / 2, 2 * 10**9))
        node.tf_buffer.set_transform(_tf("odom", "base_link", 0.0, 0.0, 0.0, 2 * 10**9))
        ctx.sim_clock.set_ns(2 * 10**9)
        node.host.update()
        odom_xy2 = _lethal_xy(node)
        # the wall (map x = 2.0) is odom y = -(2.0 - mo_x) before, -(2.0 - 1.3) after
        assert np.median(odom_xy[:, 1]) == pytest.approx(-1.0, abs=RES)
        assert np.median(odom_xy2[:, 1]) == pytest.approx(-0.7, abs=RES)
        assert np.abs(odom_xy2[:, 1] + 0.7).max() <= RES  # nothing left at the old place
    finally:
        ctx.shutdown()


def test_rolling_static_layer_waits_for_map_to_odom() -> None:
    data = np.zeros((40, 40), dtype=np.int8)
    data[:, 20] = 100
    ctx, node = _server(["static_layer"], static_layer={"plugin": "nav2_costmap_2d::StaticLayer"})
    try:
        node.tf_buffer.set_transform(_tf("odom", "base_link", 0.0, 0.0, 0.0, 10**9))
        ctx.sim_clock.set_ns(10**9)
        node.host._on_map(map_to_msg(OccupancyMap(data, RES, (0.0, 0.0, 0.0), "map"),
                                     frame_id="map"))
        # no map -> odom yet: nothing is drawn (it used to be drawn as if map were odom)
        assert len(_lethal_xy(node)) == 0
    finally:
        ctx.shutdown()


def _scan(ns: int, ranges: np.ndarray) -> LaserScan:
    return LaserScan(header=Header(stamp=_stamp(ns), frame_id="base_link"),
                     angle_min=-0.3, angle_max=0.3, angle_increment=0.6 / (len(ranges) - 1),
                     range_min=0.05, range_max=5.0, ranges=ranges.astype(np.float32))


def test_moving_robot_scans_do_not_smear() -> None:
    """The robot drives at 1 m/s towards a wall at odom x = 3.0 m; each scan arrives 0.1 to
    0.25 s after it was taken, when TF is already newer. Placed with the pose at the scan's
    stamp, the wall stays one cell thick and in place (with the latest pose it spread over
    x 3.09..3.24 m)."""
    ctx, node = _server(["obstacle_layer"], obstacle_layer={
        "plugin": "nav2_costmap_2d::ObstacleLayer", "observation_sources": "scan",
        "scan": {"topic": "scan", "data_type": "LaserScan", "marking": True, "clearing": False,
                 "obstacle_max_range": 4.5, "raytrace_max_range": 5.0,
                 "observation_persistence": 5.0}})
    try:
        layer = node.host.costmap.layers[0]
        callback = node.host._scan_cb(layer, "scan")
        angles = np.linspace(-0.3, 0.3, 31)
        ms = 1_000_000
        tf_ns = [1000 * ms + k * 50 * ms for k in range(40)]  # TF every 50 ms, x = t - 1 s
        latency = [100, 250, 150, 200, 100, 250, 150, 200]  # ms from taking to arriving
        sent = 0
        for k in range(8):  # scans taken every 0.2 s from t = 1.0 s
            t = 1000 * ms + k * 200 * ms
            while sent < len(tf_ns) and tf_ns[sent] <= t + latency[k] * ms:
                ts = tf_ns[sent]
                node.tf_buffer.set_transform(_tf("odom", "base_link", ts / 1e9 - 1.0, 0.0, 0.0, ts))
                sent += 1
            x = t / 1e9 - 1.0
            callback(_scan(t, (3.0 - x) / np.cos(angles)))
        for ts in tf_ns[sent:]:
            node.tf_buffer.set_transform(_tf("odom", "base_link", ts / 1e9 - 1.0, 0.0, 0.0, ts))
        ctx.sim_clock.set_ns(2950 * ms)
        node.host.update()
        xs = _lethal_xy(node)[:, 0]
        assert len(xs) > 10
        assert xs.max() - xs.min() <= RES + 1e-9, f"wall spread over x {xs.min():.3f}..{xs.max():.3f}"
        assert np.median(xs) == pytest.approx(3.0, abs=RES)
    finally:
        ctx.shutdown()
