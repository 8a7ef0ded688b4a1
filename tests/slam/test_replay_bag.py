"""``eddie slam replay`` on rosbag2 input: MCAP and sqlite3 bags synthesised in tmp_path.

A robot drives once round `ROOM` with drifting odometry; a 180° laser, mounted 0.2 m ahead
of the base, is ray-cast from the true sensor pose. Odometry comes at 10 Hz, scans at 2 Hz
stamped between odometry samples, so the replay must interpolate and apply the mount.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np
import pytest
from slam_world import ROOM, drifting_odometry, loop_path, raycast

from eddiebot.cli import slam as slam_cli
from eddiebot.core.tf import make_transform_2d
from eddiebot.core.time import ns_to_stamp
from eddiebot.geometry import se2_compose, se2_interpolate, yaw_to_quaternion
from eddiebot.msgs import serialize
from eddiebot.msgs.nav_msgs import Odometry
from eddiebot.msgs.sensor_msgs import LaserScan
from eddiebot.msgs.tf2_msgs import TFMessage
from eddiebot.slam.io import read_tum
from eddiebot.slam.replay import BagInputError, BagTopics, check_bag_topics

T0 = 1_700_000_000_000_000_000
MOUNT = np.array([0.2, 0.0, 0.0])
SCAN_PERIOD_NS = 500_000_000
ODOM_PERIOD_NS = 100_000_000
SCAN_OFFSET_NS = 50_000_000  # scans fall between odometry samples
BEAMS = 181


def _at(poses: np.ndarray, t_ns: int) -> np.ndarray:
    """Piecewise-linear pose at ``t_ns`` (poses are at T0 + k·SCAN_PERIOD)."""
    u = (t_ns - T0) / SCAN_PERIOD_NS
    k = min(int(u), len(poses) - 2)
    return np.asarray(se2_interpolate(poses[k], poses[k + 1], u - k))


def _scan(truth: np.ndarray, t_ns: int) -> LaserScan:
    angles = np.linspace(-math.pi / 2, math.pi / 2, BEAMS)
    sensor = se2_compose(_at(truth, t_ns), MOUNT)
    r = raycast(ROOM, sensor, angles, 20.0)
    msg = LaserScan()
    msg.header.frame_id = "laser"
    msg.header.stamp = ns_to_stamp(t_ns)
    msg.angle_min, msg.angle_max = -math.pi / 2, math.pi / 2
    msg.angle_increment = math.pi / (BEAMS - 1)
    msg.range_min, msg.range_max = 0.1, 20.0
    msg.ranges = r.astype(np.float32)  # inf: no return
    return msg


def _odom(pose: np.ndarray, t_ns: int) -> Odometry:
    msg = Odometry()
    msg.header.frame_id, msg.child_frame_id = "odom", "base_footprint"
    msg.header.stamp = ns_to_stamp(t_ns)
    msg.pose.pose.position.x, msg.pose.pose.position.y = float(pose[0]), float(pose[1])
    q = yaw_to_quaternion(float(pose[2]))
    o = msg.pose.pose.orientation
    o.x, o.y, o.z, o.w = q
    return msg


def _messages(scan_topic: str = "/scan", odometry: str = "/odom"):
    """(truth, [(topic, type, receive_ns, message)]) in receive order."""
    truth = loop_path(0.5)
    odom = drifting_odometry(truth, seed=3)
    end = T0 + (len(truth) - 1) * SCAN_PERIOD_NS
    out: list[tuple[str, str, int, object]] = [
        ("/tf_static", "tf2_msgs/msg/TFMessage", T0,
         TFMessage(transforms=[make_transform_2d("base_footprint", "laser", T0, *MOUNT)])),
    ]
    for t in range(T0, end + 1, ODOM_PERIOD_NS):
        pose = _at(odom, t)
        if odometry == "/odom":
            out.append(("/odom", "nav_msgs/msg/Odometry", t + 1_000_000, _odom(pose, t)))
        else:
            tf = TFMessage(transforms=[
                make_transform_2d("odom", "base_footprint", t, *pose),
                make_transform_2d("base_footprint", "wheel", t, 0.0, 0.1, 0.0),
            ])
            out.append(("/tf", "tf2_msgs/msg/TFMessage", t + 1_000_000, tf))
    for t in range(T0 + SCAN_OFFSET_NS, end - SCAN_PERIOD_NS, SCAN_PERIOD_NS):
        out.append((scan_topic, "sensor_msgs/msg/LaserScan", t + 30_000_000, _scan(truth, t)))
    out.sort(key=lambda m: m[2])
    return truth, out


def _write_mcap(path: Path, messages) -> None:
    from eddiebot.bag import BagWriter

    with BagWriter(path) as w:
        for topic, _, t, msg in messages:
            w.write_message(topic, msg, t)


def _write_sqlite(path: Path, messages) -> None:
    from rosbags.rosbag2 import StoragePlugin, Writer

    from eddiebot.msgs import TYPESTORE

    with Writer(path, version=9, storage_plugin=StoragePlugin.SQLITE3) as w:
        conns = {}
        for topic, typ, t, msg in messages:
            if topic not in conns:
                conns[topic] = w.add_connection(topic, typ, typestore=TYPESTORE)
            w.write(conns[topic], t, serialize(msg, typ))


#: this odometry drifts 0.01 rad a step, far beyond Eddie's noise model (config/slam.yaml)
NOISE = ["--set", "odometry_rotation_sigma:=0.05", "--set", "odometry_translation_sigma:=0.05",
         # and its heading error accumulates: no span edges built for quantised encoders
         "--set", "odometry_span_nodes:=0"]


def _run(argv: list[str]) -> int:
    parser = argparse.ArgumentParser()
    slam_cli.add_arguments(parser)
    return slam_cli.run(parser.parse_args(argv + NOISE))


def _check_outputs(out: Path, truth: np.ndarray) -> None:
    for name in ("map.pgm", "map.yaml", "map.png", "trajectory.tum", "report.md"):
        assert (out / name).is_file(), name
    stamps, poses = read_tum(out / "trajectory.tum")
    assert len(stamps) >= 20
    # the scans' own header stamps, not the bag's receive times
    offsets = np.round((stamps * 1e9 - T0 - SCAN_OFFSET_NS) / SCAN_PERIOD_NS * 1e3)
    assert np.all(offsets % 1000 == 0)
    assert np.all(np.diff(stamps) > 0)
    errors = [np.hypot(*(p[:2] - _at(truth, round(s * 1e9))[:2])) for s, p in zip(stamps, poses)]
    # drifting odometry is ~0.3 m off by the end; a dropped mount would put every pose 0.2 m off
    assert max(errors) < 0.1, max(errors)
    assert float(np.median(errors)) < 0.05


def test_replay_mcap_bag_with_odometry_topic(tmp_path: Path) -> None:
    truth, messages = _messages()
    bag = tmp_path / "run_bag"
    _write_mcap(bag, messages)
    out = tmp_path / "out"
    assert _run(["replay", str(bag), "-o", str(out), "--no-progress"]) == 0
    _check_outputs(out, truth)
    report = (out / "report.md").read_text()
    assert "nav_msgs/Odometry on /odom" in report
    assert "x 0.200 m" in report


def test_replay_sqlite3_bag_with_tf_odometry(tmp_path: Path) -> None:
    truth, messages = _messages(scan_topic="/base_scan", odometry="/tf")
    bag = tmp_path / "db_bag"
    _write_sqlite(bag, messages)
    assert any(p.suffix == ".db3" for p in bag.iterdir())
    out = tmp_path / "out"
    assert _run(["replay", str(bag), "-o", str(out), "--no-progress",
                 "--scan-topic", "/base_scan"]) == 0
    _check_outputs(out, truth)
    assert "TF odom → base_footprint on /tf" in (out / "report.md").read_text()


def test_missing_scan_topic_is_a_clear_error(tmp_path: Path, capsys) -> None:
    _, messages = _messages(scan_topic="/base_scan")
    bag = tmp_path / "bag"
    _write_mcap(bag, messages)
    out = tmp_path / "out"
    assert _run(["replay", str(bag), "-o", str(out), "--no-progress"]) == 1
    err = capsys.readouterr().err
    assert "no scan topic '/scan'" in err
    assert "/base_scan (sensor_msgs/msg/LaserScan)" in err  # what the bag does have
    assert not out.exists()


def test_missing_odometry_is_a_clear_error(tmp_path: Path, capsys) -> None:
    _, messages = _messages()
    bag = tmp_path / "bag"
    _write_mcap(bag, [m for m in messages if m[0] != "/odom"])
    assert _run(["replay", str(bag), "--no-progress", "-o", str(tmp_path / "o")]) == 1
    err = capsys.readouterr().err
    assert "'/odom'" in err and "'/tf'" in err
    assert _run(["replay", str(bag), "--no-progress", "--odom-topic", "/wheel_odom"]) == 1
    assert "no odometry topic '/wheel_odom'" in capsys.readouterr().err


def test_check_bag_topics_choices() -> None:
    topics = {"/scan": "sensor_msgs/msg/LaserScan", "/odom": "nav_msgs/msg/Odometry",
              "/tf": "tf2_msgs/msg/TFMessage", "/tf_static": "tf2_msgs/msg/TFMessage"}
    assert check_bag_topics(topics) == BagTopics("/scan", "/odom", ("/tf_static",))
    no_static = {k: v for k, v in topics.items() if k != "/tf_static"}
    assert check_bag_topics(no_static).tf_static == ("/tf",)  # the mount may be on /tf
    assert check_bag_topics(topics, odom_topic="tf").from_tf
    no_odom = {k: v for k, v in topics.items() if k != "/odom"}
    assert check_bag_topics(no_odom).odometry == "/tf"
    with pytest.raises(BagInputError, match="'/odom' is nav_msgs/msg/Odometry, not"):
        check_bag_topics(topics, scan_topic="/odom")
