"""PNG snapshots of maps with trajectories, paths, scans and the robot."""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np
import pytest

from eddiebot.bag import BagWriter
from eddiebot.geometry import yaw_to_quaternion
from eddiebot.maps import OccupancyMap, map_to_msg, map_to_world, save_map
from eddiebot.msgs.geometry_msgs import TransformStamped
from eddiebot.msgs.nav_msgs import Odometry
from eddiebot.msgs.sensor_msgs import LaserScan
from eddiebot.msgs.tf2_msgs import TFMessage
from eddiebot.viz.snapshot import (
    FREE_BGR,
    OCCUPIED_BGR,
    UNKNOWN_BGR,
    read_tum,
    render_bag,
    render_map,
    render_trajectories,
)

RES = 0.05
ORIGIN = (-1.0, -0.5, 0.0)


def _grid() -> OccupancyMap:
    """40 × 30 cells (2 m × 1.5 m): free, a wall along column 35, unknown in the top rows."""
    data = np.zeros((30, 40), np.int8)
    data[:, 35] = 100
    data[25:, :10] = -1
    return OccupancyMap(data, RES, ORIGIN)


def _centre(grid: OccupancyMap, col: int, row: int) -> tuple[float, float]:
    x, y = map_to_world(grid, [col, row])
    return float(x), float(y)


def test_cells_have_map_colours() -> None:
    grid = _grid()
    snap = render_map(grid, scale_bar=False, legend=False)
    assert snap.pixels_per_cell == 15  # 600 px / 40 cells
    assert snap.image.shape == (30 * 15 + 20, 40 * 15 + 20, 3)
    assert snap.pixel(*_centre(grid, 35, 10)) == OCCUPIED_BGR
    assert snap.pixel(*_centre(grid, 20, 10)) == FREE_BGR
    assert snap.pixel(*_centre(grid, 3, 28)) == UNKNOWN_BGR
    assert snap.pixel(*_centre(grid, 3, 20)) == FREE_BGR
    # row 0 of the grid (lowest y) is the bottom of the image
    col, row = snap.world_to_pixel(_centre(grid, 0, 0))
    assert row > snap.image.shape[0] - 10 - 15


def test_trajectory_is_drawn_in_its_colour(tmp_path: Path) -> None:
    grid = _grid()
    y = float(_centre(grid, 0, 12)[1])
    line = np.array([[-0.8, y], [0.6, y]])
    out = tmp_path / "snap.png"
    snap = render_map(grid, trajectories={"odometry": line}, out_path=out, legend=True)
    colour = snap.legend[0][1]
    assert snap.legend[0][0] == "odometry"
    on_line = snap.pixel(0.0, y)
    assert max(abs(a - b) for a, b in zip(on_line, colour)) <= 10
    assert snap.pixel(0.0, y + 0.2) == FREE_BGR  # 4 cells away: untouched
    # the PNG on disk is the image
    back = cv2.imread(str(out))
    assert back is not None
    assert np.array_equal(back, snap.image)


def test_several_trajectories_paths_scan_and_robot() -> None:
    grid = _grid()
    a = np.array([[-0.8, -0.3], [0.5, -0.3]])
    b = np.array([[-0.8, 0.3], [0.5, 0.3]])
    scan = LaserScan(angle_min=0.0, angle_max=0.0, angle_increment=0.1, range_min=0.05,
                     range_max=5.0, ranges=np.array([1.0], np.float32))
    pose = (0.0, 0.0, 0.0)
    snap = render_map(grid, trajectories=[("a", a), ("b", b)],
                      paths=np.array([[-0.5, -0.6 + 0.9], [-0.5, 0.6]]),
                      scan=scan, robot_pose=pose, legend=True)
    labels = [label for label, _ in snap.legend]
    assert labels == ["a", "b", "planned path", "scan", "robot"]
    ca, cb = snap.legend[0][1], snap.legend[1][1]
    assert ca != cb
    assert max(abs(p - q) for p, q in zip(snap.pixel(0.2, -0.3), ca)) <= 10
    assert max(abs(p - q) for p, q in zip(snap.pixel(0.2, 0.3), cb)) <= 10
    # scan end point at 1 m ahead of the robot: on the wall column
    assert snap.pixel(1.0, 0.0) == snap.legend[3][1]
    # footprint: the robot's centre is tinted, its heading line crosses x = +0.1 m
    assert snap.pixel(0.0, 0.1) != FREE_BGR
    assert snap.pixel(0.3, 0.0) == FREE_BGR or snap.pixel(0.3, 0.0) == snap.legend[3][1]
    assert snap.pixel(0.0, 0.35) == FREE_BGR  # outside the 0.2245 m circle


def test_tum_trajectory_and_blank_canvas(tmp_path: Path) -> None:
    tum = tmp_path / "traj.txt"
    rows = []
    for k in range(50):
        th = k / 49 * math.pi
        q = yaw_to_quaternion(th + math.pi / 2)
        rows.append(f"{k * 0.1:.1f} {math.cos(th):.6f} {math.sin(th):.6f} 0 {q[0]} {q[1]} {q[2]} {q[3]}")
    tum.write_text("# t x y z qx qy qz qw\n" + "\n".join(rows) + "\n")
    arr = read_tum(tum)
    assert arr.shape == (50, 8)
    snap = render_trajectories([tum], out_path=tmp_path / "t.png")
    assert snap.legend[0][0] == "traj"
    colour = snap.legend[0][1]
    mid = snap.pixel(0.0, 1.0)  # the arc's top
    assert max(abs(p - q) for p, q in zip(mid, colour)) <= 10
    assert (tmp_path / "t.png").exists()


def test_map_file_renders(tmp_path: Path) -> None:
    from eddiebot.viz.snapshot import render_file

    grid = _grid()
    save_map(grid, tmp_path / "m")
    snap = render_file(tmp_path / "m.yaml", out_path=tmp_path / "m.png", legend=False,
                       scale_bar=False)
    assert snap.pixel(*_centre(grid, 35, 10)) == OCCUPIED_BGR
    assert snap.pixel(*_centre(grid, 20, 10)) == FREE_BGR


def _tf(x: float, y: float, yaw: float) -> TFMessage:
    t = TransformStamped(child_frame_id="odom")
    t.header.frame_id = "map"
    t.transform.translation.x, t.transform.translation.y = x, y
    q = yaw_to_quaternion(yaw)
    t.transform.rotation.x, t.transform.rotation.y = q[0], q[1]
    t.transform.rotation.z, t.transform.rotation.w = q[2], q[3]
    return TFMessage(transforms=[t])


def test_bag_snapshot_at_time(tmp_path: Path) -> None:
    from eddiebot.core import qos_profile_latched

    grid = _grid()
    bag = tmp_path / "run"
    ns = 1_000_000_000
    with BagWriter(bag) as w:
        w.write_message("/map", map_to_msg(grid), ns, qos=qos_profile_latched)
        # map → odom shifts everything by +0.2 m in y
        w.write_message("/tf", _tf(0.0, 0.2, 0.0), ns)
        for k in range(11):  # odom: x from -0.8 to 0.2 over 10 s
            o = Odometry(child_frame_id="base_footprint")
            o.header.frame_id = "odom"
            o.pose.pose.position.x = -0.8 + 0.1 * k
            o.pose.pose.orientation.w = 1.0
            w.write_message("/odom", o, ns + k * ns)
            w.write_message("/scan", LaserScan(angle_increment=0.1, range_min=0.05,
                                               range_max=5.0,
                                               ranges=np.array([0.3], np.float32)), ns + k * ns)
    full = render_bag(bag, legend=True, scale_bar=False)
    labels = [label for label, _ in full.legend]
    assert labels[0] == "trajectory (map)"
    colour = full.legend[0][1]
    assert max(abs(p - q) for p, q in zip(full.pixel(-0.3, 0.2), colour)) <= 10
    assert full.pixel(-0.3, 0.0) == FREE_BGR  # not in the odom frame
    half = render_bag(bag, at=4.0, legend=False, scale_bar=False)
    # after 4 s the trajectory stops at x = -0.4 (+ line width); beyond it the map is free
    assert half.pixel(0.0, 0.2) == FREE_BGR
    assert max(abs(p - q) for p, q in zip(half.pixel(-0.7, 0.2), colour)) <= 10


def test_bad_trajectory_shape() -> None:
    with pytest.raises(ValueError, match="shape"):
        render_map(_grid(), trajectories=np.zeros(5))


def test_bag_snapshot_trajectory_from_tf_only(tmp_path: Path) -> None:
    bag = tmp_path / "tfonly"
    ns = 1_000_000_000
    with BagWriter(bag) as w:
        for k in range(11):
            msg = _tf(-0.8 + 0.1 * k, 0.4, 0.0)
            msg.transforms[0].header.frame_id = "odom"
            msg.transforms[0].child_frame_id = "base_footprint"
            w.write_message("/tf", msg, ns + k * ns)
    snap = render_bag(bag, legend=True, scale_bar=False)
    assert snap.legend[0][0] == "odometry"
    colour = snap.legend[0][1]
    assert max(abs(p - q) for p, q in zip(snap.pixel(-0.5, 0.4), colour)) <= 10
