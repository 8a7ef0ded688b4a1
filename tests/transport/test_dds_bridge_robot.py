"""Issue #23's done scenario: ``eddie sim --world office`` and ``eddie bridge dds`` running,
a Cyclone DDS program that behaves as a ROS 2 node on rmw_cyclonedds receives ``/odom`` and
``/scan``, drives the robot through ``/cmd_vel_teleop`` and calls its services; ``eddie
topic echo`` prints a type we do not ship, published from the DDS side.

Both ``eddie`` programs run as processes on a private Zenoh router and a DDS domain id
reserved for this module; this process is only the DDS peer (and runs ``eddie topic echo``).
"""

from __future__ import annotations

import math
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from _procs import Proc, private_router

pytest.importorskip("cyclonedds")

from cyclonedds.idl import make_idl_struct
from cyclonedds.idl import types as idl
from cyclonedds.pub import DataWriter
from cyclonedds.qos import Policy, Qos

from _support.dds_peer import (
    LaserScan_,
    Odometry_,
    RosPeer,
    Twist_,
    private_dds_domain,
    wait,
)
from eddiebot.msgs.geometry_msgs import Twist, Vector3
from eddiebot.robot.constants import POSITIONS_PER_REV, WHEEL_RADIUS_M

EDDIE = [sys.executable, "-m", "eddiebot.cli.main"]
#: What the bridge carries here: the scenario's topics and services, and the test type's.
ALLOW = "^/(odom|scan|cmd_vel_teleop|get_distance|reset_encoder|dds_reading)$"
PKG = "dds_test_msgs"
READING = "string sensor\nfloat64[] values\nuint32 count\n"

_header = {"rmw_request_guid": idl.uint64, "rmw_request_seq": idl.int64}
_Empty = {**_header, "structure_needs_at_least_one_member": idl.uint8}
GetDistanceRequest_ = make_idl_struct(
    "GetDistance_Request_", "eddiebot_msgs::srv::dds_::GetDistance_Request_", _Empty)
GetDistanceResponse_ = make_idl_struct(
    "GetDistance_Response_", "eddiebot_msgs::srv::dds_::GetDistance_Response_",
    {**_header, "left": idl.int32, "right": idl.int32})
ResetEncoderRequest_ = make_idl_struct(
    "ResetEncoder_Request_", "eddiebot_msgs::srv::dds_::ResetEncoder_Request_", _Empty)
ResetEncoderResponse_ = make_idl_struct(
    "ResetEncoder_Response_", "eddiebot_msgs::srv::dds_::ResetEncoder_Response_", _Empty)
# the test package's type, as a ROS 2 node built with it declares it on DDS
Reading_ = make_idl_struct("Reading_", f"{PKG}::msg::dds_::Reading_", {
    "sensor": str, "values": idl.sequence[idl.float64], "count": idl.uint32})


@pytest.fixture(scope="module")
def interfaces(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A package folder with one ``.msg`` file, for ``EDDIE_INTERFACE_PATH``."""
    root = tmp_path_factory.mktemp("interfaces")
    (root / PKG / "msg").mkdir(parents=True)
    (root / PKG / "msg" / "Reading.msg").write_text(READING)
    return root


@pytest.fixture(scope="module")
def env(interfaces: Path) -> Iterator[dict[str, str]]:
    with private_router() as zenoh_env:
        env = {k: v for k, v in zenoh_env.items() if k != "AMENT_PREFIX_PATH"}
        yield {**env, "ROS_DOMAIN_ID": "0", "EDDIE_INTERFACE_PATH": str(interfaces)}


@pytest.fixture(scope="module")
def dds_domain() -> Iterator[int]:
    with private_dds_domain() as domain:
        yield domain


@pytest.fixture(scope="module")
def robot(env: dict[str, str], dds_domain: int) -> Iterator[tuple[Proc, Proc]]:
    """``eddie sim --world office`` and ``eddie bridge dds``, started together."""
    sim = Proc([*EDDIE, "sim", "--world", "office", "--camera", "160x120@5"], env)
    bridge = Proc([*EDDIE, "bridge", "dds", "--domain", str(dds_domain), "--allow", ALLOW], env)
    try:
        if not bridge.wait_for("eddie bridge dds: domain", timeout=60):
            pytest.fail(f"the bridge did not start: {bridge.stderr}")
        if not wait(lambda: "board on emulator" in sim.stderr or sim.popen.poll() is not None,
                    timeout=60) or sim.popen.poll() is not None:
            pytest.fail(f"eddie sim did not start: {sim.stderr}")
        yield sim, bridge
    finally:
        for p in (sim, bridge):
            if p.popen.poll() is None:
                p.popen.send_signal(signal.SIGINT)
        for p in (sim, bridge):
            p.finish(timeout=15)


@pytest.fixture(scope="module")
def peer(dds_domain: int) -> RosPeer:
    return RosPeer(dds_domain)


def _yaw(odom: Any) -> float:
    q = odom.pose.pose.orientation
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def test_a_ros2_node_on_dds_reads_drives_and_calls_the_robot(
        robot: tuple[Proc, Proc], peer: RosPeer) -> None:
    _sim, bridge = robot
    # as a sensor-data subscription would (best effort matches any writer)
    odom_reader = peer.reader("/odom", Odometry_, "nav_msgs/msg/Odometry", best_effort=True)
    scan_reader = peer.reader("/scan", LaserScan_, "sensor_msgs/msg/LaserScan",
                              best_effort=True, depth=5)
    odoms: list[Any] = []
    scans: list[Any] = []

    def poll() -> None:
        odoms.extend(RosPeer.take(odom_reader, "nav_msgs/msg/Odometry"))
        scans.extend(RosPeer.take(scan_reader, "sensor_msgs/msg/LaserScan"))

    assert wait(lambda: poll() or (len(odoms) >= 3 and len(scans) >= 2), 30), bridge.stderr
    odom, scan = odoms[-1], scans[-1]
    assert (odom.header.frame_id, odom.child_frame_id) == ("odom", "base_footprint")
    assert scan.range_min < scan.range_max
    assert scan.angle_min < 0.0 < scan.angle_max
    assert len(scan.ranges) == round((scan.angle_max - scan.angle_min) / scan.angle_increment) + 1
    in_range = [r for r in scan.ranges if scan.range_min <= r <= scan.range_max]
    assert len(in_range) > len(scan.ranges) // 4  # the office's walls are in view

    # a service, as rmw_cyclonedds calls it
    assert peer.client("/get_distance", "eddiebot_msgs/srv/GetDistance",
                       GetDistanceRequest_, GetDistanceResponse_), bridge.stderr
    assert peer.client("/reset_encoder", "eddiebot_msgs/srv/ResetEncoder",
                       ResetEncoderRequest_, ResetEncoderResponse_), bridge.stderr
    from eddiebot.msgs.eddiebot_msgs import GetDistance, ResetEncoder

    before = peer.call("/get_distance", "eddiebot_msgs/srv/GetDistance", GetDistance.Request())
    assert before is not None, bridge.stderr

    # drive: 0.2 m/s ahead for 2 s, as a teleop node at 20 Hz
    poll()
    start = odoms[-1]
    teleop = peer.writer("/cmd_vel_teleop", Twist_, "geometry_msgs/msg/Twist")
    assert wait(lambda: teleop.get_publication_matched_status().current_count > 0), bridge.stderr
    forward = Twist(linear=Vector3(x=0.2, y=0.0, z=0.0), angular=Vector3(x=0.0, y=0.0, z=0.0))
    end = time.monotonic() + 2.0
    while time.monotonic() < end:
        RosPeer.write(teleop, forward)
        poll()
        time.sleep(0.05)
    fastest = max(float(o.twist.twist.linear.x) for o in odoms)
    # the twist mux lets teleop go 0.5 s after its last message: the robot stops
    assert wait(lambda: poll() or abs(float(odoms[-1].twist.twist.linear.x)) < 0.01, 10)
    stop = odoms[-1]
    dx = stop.pose.pose.position.x - start.pose.pose.position.x
    dy = stop.pose.pose.position.y - start.pose.pose.position.y
    moved = math.hypot(dx, dy)
    assert 0.15 < fastest < 0.25
    assert 0.2 < moved < 0.6, (moved, bridge.stderr)  # 0.4 m less the acceleration ramps
    assert abs(math.remainder(_yaw(stop) - _yaw(start), math.tau)) < 0.1
    # the encoders counted the same drive on both wheels
    after = peer.call("/get_distance", "eddiebot_msgs/srv/GetDistance", GetDistance.Request())
    assert after is not None
    left, right = after.left - before.left, after.right - before.right
    assert abs(left - right) <= 1, (before, after)
    # ... as far as /odom says the robot went (a position is 2π·r/36 = 13.3 mm of wheel)
    assert abs((left + right) / 2 * 2 * math.pi * WHEEL_RADIUS_M / POSITIONS_PER_REV
               - moved) < 0.04, (before, after, moved)
    # /reset_encoder zeroes GetDistance's counts
    assert peer.call("/reset_encoder", "eddiebot_msgs/srv/ResetEncoder",
                     ResetEncoder.Request()) is not None
    zeroed = peer.call("/get_distance", "eddiebot_msgs/srv/GetDistance", GetDistance.Request())
    assert zeroed is not None and abs(zeroed.left) < 5 and abs(zeroed.right) < 5, zeroed


def test_eddie_topic_echo_prints_a_type_we_do_not_ship(
        robot: tuple[Proc, Proc], peer: RosPeer, env: dict[str, str], interfaces: Path,
        monkeypatch: pytest.MonkeyPatch) -> None:
    """A ROS 2 node on DDS publishes ``dds_test_msgs/msg/Reading``, which only a ``.msg``
    file on ``EDDIE_INTERFACE_PATH`` describes: the bridge carries it and ``eddie topic
    echo`` decodes it."""
    from eddiebot.msgs import load_type, type_hash

    _sim, bridge = robot
    monkeypatch.setenv("EDDIE_INTERFACE_PATH", str(interfaces))
    load_type(f"{PKG}/msg/Reading")  # the node's typehash user data, from the same file
    hash_ = type_hash(f"{PKG}/msg/Reading")
    writer = DataWriter(peer.participant, peer._topic("rt/dds_reading", Reading_), qos=Qos(
        Policy.Reliability.Reliable(max_blocking_time=100_000_000), Policy.History.KeepLast(5),
        Policy.DataRepresentation(use_cdrv0_representation=True),
        Policy.Userdata(f"typehash={hash_};".encode())))
    stop = threading.Event()

    def publish() -> None:
        n = 0
        while not stop.is_set():
            n += 1
            writer.write(Reading_(sensor="thermo", values=[20.5, 21.25], count=n))
            time.sleep(0.05)

    thread = threading.Thread(target=publish, daemon=True)
    thread.start()
    try:
        out = subprocess.run([*EDDIE, "topic", "echo", "/dds_reading", "--once",
                              "--timeout", "30"], env=env, capture_output=True, text=True,
                             timeout=60, check=False)
    finally:
        stop.set()
        thread.join(2)
    assert out.returncode == 0, (out.stderr, bridge.stderr)
    lines = out.stdout.splitlines()
    assert "sensor: thermo" in lines, out.stdout
    assert "- 20.5" in lines and "- 21.25" in lines, out.stdout
    counts = [int(line.split(":")[1]) for line in lines if line.startswith("count:")]
    assert len(counts) == 1 and counts[0] >= 1, out.stdout
