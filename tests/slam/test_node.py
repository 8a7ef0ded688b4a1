"""The SLAM node on a simulated clock: queueing, services, modes, start-up loading, bad input."""

from __future__ import annotations

import logging
import math
import os
import stat
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from slam_world import ROOM, raycast

from eddiebot.core.context import Context
from eddiebot.core.executors import SingleThreadedExecutor
from eddiebot.core.node import Node
from eddiebot.core.tf import make_transform_2d
from eddiebot.core.time import ns_to_stamp
from eddiebot.geometry import se2_compose
from eddiebot.msgs.sensor_msgs import LaserScan
from eddiebot.msgs.slam_toolbox import (
    ClearQueue,
    DeserializePoseGraph,
    Pause,
    SaveMap,
    SerializePoseGraph,
)
from eddiebot.msgs.std_msgs import String
from eddiebot.msgs.tf2_msgs import TFMessage
from eddiebot.msgs.visualization_msgs import MarkerArray
from eddiebot.slam.node import SlamNode

BEAMS = 181
MOUNT = np.array([0.1, 0.0, 0.0])
SECOND = 1_000_000_000
#: the robot's route in the room, along y = 4; its odometry starts out equal to the room's
#: frame, so the map frame is the room's
START = np.array([2.0, 4.0, 0.0])


class Rig:
    """A SLAM node, a probe publishing scans, and odometry written into the node's TF buffer."""

    def __init__(self, **params: object) -> None:
        self.ctx = Context(use_sim_time=True)
        self.ctx.sim_clock.set_ns(100 * SECOND)
        overrides: dict[str, object] = {
            "processing": "sync",
            "minimum_time_interval": 0.0,
            "minimum_travel_distance": 0.2,
            "transform_timeout": 0.2,
            "tf_buffer_duration": 1000.0,
            **params,
        }
        self.node = SlamNode(context=self.ctx, parameter_overrides=overrides)
        self.ex = SingleThreadedExecutor(context=self.ctx)
        self.ex.add_node(self.node)
        self.probe = Node("probe", context=self.ctx)
        self.ex.add_node(self.probe)
        self.scan_pub = self.probe.create_publisher(LaserScan, "/scan", 1000)
        self.tf_seen: list[Any] = []
        self.probe.create_subscription(TFMessage, "/tf", self.tf_seen.append, 100)
        self.node.tf_buffer.set_transform_static(
            make_transform_2d("base_footprint", "laser", 0, *MOUNT), "test"
        )

    def close(self) -> None:
        self.node.destroy_node()
        self.probe.destroy_node()
        self.ctx.shutdown()

    def odom(self, t_ns: int, pose: np.ndarray) -> None:
        self.node.tf_buffer.set_transform(
            make_transform_2d("odom", "base_footprint", t_ns, *(float(v) for v in pose)), "test"
        )

    def publish(
        self, t_ns: int, truth: np.ndarray, odom: np.ndarray | None = None, *,
        frame: str = "laser", beams: int = BEAMS, nan_every: int = 0,
    ) -> None:
        """A scan of the room from ``truth`` (map frame) stamped ``t_ns``, with its odometry."""
        if odom is not None:
            self.odom(t_ns, odom)
        angles = np.linspace(-math.pi / 2, math.pi / 2, beams)
        ranges = raycast(ROOM, se2_compose(truth, MOUNT), angles, 20.0)
        if nan_every:
            ranges[::nan_every] = np.nan
        msg = LaserScan()
        msg.header.frame_id = frame
        msg.header.stamp = ns_to_stamp(t_ns)
        msg.angle_min, msg.angle_max = -math.pi / 2, math.pi / 2
        msg.angle_increment = math.pi / (beams - 1)
        msg.range_min, msg.range_max = 0.1, 20.0
        msg.ranges = ranges.astype(np.float32)
        self.scan_pub.publish(msg)

    def drive(self, steps: int, step: float = 0.25, t0: int = 0, jump_at: int = -1,
              jump: np.ndarray | None = None) -> np.ndarray:
        """Drive along +x from START one scan per step (half a second apart, spinning after
        each); the odometry is exact, plus ``jump`` from step ``jump_at`` on. Returns the
        last true pose."""
        truth = START.copy()
        for k in range(steps):
            truth = START + np.array([step * k, 0.0, 0.0])
            odom = truth.copy()
            if jump is not None and 0 <= jump_at <= k:
                odom = se2_compose(jump, odom)
            t = self.now + t0
            self.publish(t, truth, odom)
            self.ex.spin_for(0.5)
        return truth

    @property
    def now(self) -> int:
        return self.ctx.sim_clock.now_ns()

    def call(self, srv_type: Any, service_name: str, **fields: Any) -> Any:
        req = srv_type.Request()
        for key, value in fields.items():
            setattr(req, key, value)
        (service,) = [
            s for s in self.node.services if s.service_name == f"/slam_toolbox/{service_name}"
        ]
        return service.handle(req)

    def robot_in_map(self) -> np.ndarray:
        """Where the node places the robot now: map→odom ∘ the latest odometry."""
        odom = self.node.tf_buffer.lookup_pose2d("odom", "base_footprint", 0)
        return se2_compose(self.node.core.map_to_odom, np.array(odom))


@pytest.fixture
def rig_factory() -> Iterator[Any]:
    rigs: list[Rig] = []

    def make(**params: object) -> Rig:
        rigs.append(Rig(**params))
        return rigs[-1]

    yield make
    for r in rigs:
        r.close()


# -- queueing --------------------------------------------------------------------------------
def _burst(rig: Rig, n: int = 60) -> None:
    """``n`` scans published before the node runs (a slow consumer, a bag played fast)."""
    t0 = rig.now
    for k in range(n):
        truth = START + np.array([0.05 * k, 0.0, 0.0])
        rig.publish(t0 + k * SECOND // 10, truth, truth.copy())
    rig.ex.spin_for(0.1)


def test_sync_processes_every_scan_of_a_burst(rig_factory: Any) -> None:
    rig = rig_factory(processing="sync")
    _burst(rig, 60)
    assert rig.node.scans_received == 60
    assert rig.node.scans_processed == 60
    assert rig.node.scans_dropped == 0
    assert len(rig.node.core.nodes) == 15  # 3 m in 0.2 m steps, the first included


@pytest.mark.parametrize("queue", [1, 3])
def test_async_keeps_the_newest_scan_queue_size_scans(rig_factory: Any, queue: int) -> None:
    rig = rig_factory(processing="async", scan_queue_size=queue)
    _burst(rig, 60)
    assert rig.node.scans_processed == queue


def test_clear_queue_drops_scans_waiting_for_odometry(rig_factory: Any) -> None:
    rig = rig_factory(transform_timeout=5.0)
    t0 = rig.now
    rig.odom(t0 - SECOND, np.zeros(3))
    for k in range(4):  # odometry for these times has not arrived yet: they wait
        rig.publish(t0 + k * SECOND // 10, START)
    rig.ex.spin_for(0.05)
    assert len(rig.node._scan_queue) == 4
    res = rig.call(ClearQueue, "clear_queue")
    assert res.status is True
    assert len(rig.node._scan_queue) == 0
    assert rig.node.scans_dropped == 4
    rig.odom(t0 + SECOND, np.zeros(3))
    rig.ex.spin_for(0.5)
    assert rig.node.scans_processed == 0


# -- transforms ------------------------------------------------------------------------------
def _map_odom_count(rig: Rig) -> int:
    return sum(
        1 for m in rig.tf_seen for tf in m.transforms
        if tf.header.frame_id == "map" and tf.child_frame_id == "odom"
    )


def test_transform_publish_period_zero_publishes_nothing(rig_factory: Any) -> None:
    silent = rig_factory(transform_publish_period=0.0)
    silent.ex.spin_for(1.0)
    assert _map_odom_count(silent) == 0


def test_transform_publish_period_sets_the_rate(rig_factory: Any) -> None:
    rig = rig_factory(transform_publish_period=0.1)
    rig.ex.spin_for(1.0)
    assert _map_odom_count(rig) == 10


def test_the_map_goes_out_every_interval_even_when_the_graph_is_unchanged(rig_factory: Any) -> None:
    # slam_toolbox's updateMap publishes every map_update_interval, stamped now. Sending
    # only changed maps kept an explorer that waits for a map made after its arrival
    # waiting up to its 10 s bound whenever the arrival added no node (the warehouse:
    # 9 such waits in 600 s)
    from eddiebot.msgs.nav_msgs import OccupancyGrid

    rig = rig_factory(map_update_interval=1.0)
    maps: list[Any] = []
    rig.probe.create_subscription(OccupancyGrid, "/map", maps.append, 10)
    rig.drive(5)
    rig.ex.spin_for(1.05)  # the last node's map
    nodes = len(rig.node.core.nodes)
    built = len(rig.node.map_update_cpu_s)
    before = len(maps)
    rig.ex.spin_for(3.0)  # standing still: no scan, no new node
    assert len(rig.node.core.nodes) == nodes
    stamps = [m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 for m in maps[before:]]
    assert len(stamps) == 3 and all(b - a == pytest.approx(1.0) for a, b in zip(stamps, stamps[1:]))
    assert len(rig.node.map_update_cpu_s) == built  # sent again, not rebuilt
    assert np.array_equal(np.asarray(maps[-1].data), np.asarray(maps[before - 1].data))


# -- services --------------------------------------------------------------------------------
def _mapped(rig: Rig) -> None:
    rig.drive(17)  # x 2 → 6 along y = 4
    assert len(rig.node.core.nodes) >= 15


@pytest.mark.parametrize("umask", [0o022, 0o027])
def test_saved_files_keep_the_umask(rig_factory: Any, tmp_path: Path, umask: int) -> None:
    rig = rig_factory()
    _mapped(rig)
    old = os.umask(umask)
    try:
        res = rig.call(SaveMap, "save_map", name=String(data=str(tmp_path / "room")))
        assert res.result == SaveMap.Response.RESULT_SUCCESS
        res = rig.call(SerializePoseGraph, "serialize_map", filename=str(tmp_path / "room.slam"))
        assert res.result == SerializePoseGraph.Response.RESULT_SUCCESS
    finally:
        os.umask(old)
    for name in ("room.yaml", "room.pgm", "room.slam"):
        assert stat.S_IMODE((tmp_path / name).stat().st_mode) == 0o666 & ~umask, name


def test_pause_toggles_and_the_parameter_follows(rig_factory: Any) -> None:
    rig = rig_factory(paused_new_measurements=True)
    rig.publish(rig.now, START, np.zeros(3))
    rig.ex.spin_for(0.5)
    assert rig.node.scans_processed == 0
    rig.call(Pause, "pause_new_measurements")
    assert rig.node.get_parameter("paused_new_measurements").value is False
    rig.publish(rig.now, START, np.zeros(3))
    rig.ex.spin_for(0.5)
    assert rig.node.scans_processed == 1


# -- sessions: start-up loading and deserialize_map ---------------------------------------
@pytest.fixture
def session(rig_factory: Any, tmp_path: Path) -> tuple[Path, np.ndarray, np.ndarray]:
    """A session mapped along y = 4 from x = 2 to 6; its first and last node poses."""
    rig = rig_factory()
    _mapped(rig)
    path = tmp_path / "room.slam"
    rig.call(SerializePoseGraph, "serialize_map", filename=str(path))
    poses = rig.node.core.node_poses()
    return path, poses[0].copy(), poses[-1].copy()


def _first_scan_at(rig: Rig, truth: np.ndarray, odom: np.ndarray) -> np.ndarray:
    rig.publish(rig.now, truth, odom)
    rig.ex.spin_for(0.5)
    return rig.robot_in_map()


@pytest.mark.parametrize("mode", ["mapping", "lifelong"])
def test_map_file_name_loads_at_map_start_pose(
    rig_factory: Any, session: Any, mode: str
) -> None:
    path, first, last = session
    here = np.array([4.0, 4.5, 0.1])
    rig = rig_factory(mode=mode, map_file_name=str(path), map_start_pose=[4.0, 4.5, 0.1])
    n = len(rig.node.core.nodes)
    assert n >= 15
    # the odometry of the new run starts anywhere: the start pose holds, not the odometry
    pose = _first_scan_at(rig, here, np.array([7.0, -3.0, 1.0]))
    assert len(rig.node.core.nodes) == n + 1
    assert np.hypot(*(pose[:2] - here[:2])) < 0.05
    assert abs(pose[2] - here[2]) < 0.02


def test_map_start_at_dock_starts_at_the_first_node(rig_factory: Any, session: Any) -> None:
    path, first, last = session
    assert np.hypot(*(last[:2] - first[:2])) > 3.5  # the session ended far from its start
    rig = rig_factory(map_file_name=str(path), map_start_at_dock=True)
    pose = _first_scan_at(rig, first, np.array([1.0, 1.0, 0.0]))
    assert np.hypot(*(pose[:2] - first[:2])) < 0.05


def test_localization_loads_map_file_name_at_start(rig_factory: Any, session: Any) -> None:
    path, first, last = session
    here = np.array([3.0, 4.0, 0.0])
    rig = rig_factory(mode="localization", map_file_name=str(path),
                      map_start_pose=[3.05, 3.95, 0.02])
    n = len(rig.node.core.nodes)
    pose = _first_scan_at(rig, here, np.array([0.5, 0.5, 0.5]))
    assert len(rig.node.core.nodes) == n  # localization never extends the graph
    assert np.hypot(*(pose[:2] - here[:2])) < 0.05


def _pose2d(x: float, y: float, theta: float) -> Any:
    p = DeserializePoseGraph.Request().initial_pose
    p.x, p.y, p.theta = x, y, theta
    return p


@pytest.mark.parametrize(
    ("mode", "match_type", "loaded"),
    [
        ("mapping", DeserializePoseGraph.Request.UNSET, False),
        ("mapping", DeserializePoseGraph.Request.LOCALIZE_AT_POSE, False),
        ("lifelong", DeserializePoseGraph.Request.LOCALIZE_AT_POSE, False),
        ("mapping", DeserializePoseGraph.Request.START_AT_GIVEN_POSE, True),
        ("mapping", DeserializePoseGraph.Request.START_AT_FIRST_NODE, True),
        ("localization", DeserializePoseGraph.Request.LOCALIZE_AT_POSE, True),
        ("localization", DeserializePoseGraph.Request.START_AT_GIVEN_POSE, False),
        ("localization", DeserializePoseGraph.Request.UNSET, False),
    ],
)
def test_deserialize_match_types(
    rig_factory: Any, session: Any, caplog: pytest.LogCaptureFixture,
    mode: str, match_type: int, loaded: bool,
) -> None:
    path, first, last = session
    rig = rig_factory(mode=mode)
    caplog.set_level(logging.INFO)
    caplog.clear()
    rig.call(DeserializePoseGraph, "deserialize_map", filename=str(path), match_type=match_type,
             initial_pose=_pose2d(4.0, 4.0, 0.0))
    assert (len(rig.node.core.nodes) > 0) is loaded
    errors = [r.getMessage() for r in caplog.records if r.levelno >= logging.ERROR]
    assert len(errors) == (0 if loaded else 1)
    if not loaded:
        assert "not loaded" in errors[0]
        return
    expected = first if match_type == DeserializePoseGraph.Request.START_AT_FIRST_NODE else (
        np.array([4.0, 4.0, 0.0]))
    pose = _first_scan_at(rig, expected, np.array([-2.0, 1.0, 0.3]))
    assert np.hypot(*(pose[:2] - expected[:2])) < 0.05


# -- one laser -------------------------------------------------------------------------------
def test_a_second_laser_with_another_mount_is_refused(rig_factory: Any) -> None:
    rig = rig_factory()
    rig.node.tf_buffer.set_transform_static(
        make_transform_2d("base_footprint", "laser_rear", 0, -0.2, 0.0, math.pi), "test"
    )
    rig.node.tf_buffer.set_transform_static(
        make_transform_2d("base_footprint", "laser_twin", 0, *MOUNT), "test"
    )
    rig.drive(5)
    n = len(rig.node.core.nodes)
    truth = START + np.array([2.0, 0.0, 0.0])
    rig.publish(rig.now, truth, truth.copy(), frame="laser_rear")
    rig.ex.spin_for(0.5)
    assert rig.node.scans_refused_frame == 1
    assert len(rig.node.core.nodes) == n
    assert np.allclose(rig.node.core.sensor_offset, MOUNT)
    # a second frame name on the same mount is the same laser
    truth = START + np.array([2.5, 0.0, 0.0])
    rig.publish(rig.now, truth, truth.copy(), frame="laser_twin")
    rig.ex.spin_for(0.5)
    assert len(rig.node.core.nodes) == n + 1


# -- bad input -------------------------------------------------------------------------------
def test_scan_of_another_shape_is_skipped_and_logged_once(
    rig_factory: Any, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.WARNING)
    rig = rig_factory()
    rig.drive(3)
    n = len(rig.node.core.nodes)
    for k in range(2):
        truth = START + np.array([1.0 + 0.5 * k, 0.0, 0.0])
        t = rig.now
        rig.publish(t, truth, truth.copy(), beams=91)
        rig.ex.spin_for(0.5)
    assert len(rig.node.core.nodes) == n
    shape = [r.getMessage() for r in caplog.records if "91 beams" in r.getMessage()]
    assert len(shape) == 1
    assert f"at {t * 1e-9 - 0.5:.3f} s" in shape[0]  # the first one's time
    assert "the first scan had 181" in shape[0]


def test_nan_ranges_are_ignored_and_logged_once(
    rig_factory: Any, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.WARNING)
    rig = rig_factory()
    for k in range(4):
        truth = START + np.array([0.25 * k, 0.0, 0.0])
        rig.publish(rig.now, truth, truth.copy(), nan_every=3)
        rig.ex.spin_for(0.5)
    assert len(rig.node.core.nodes) == 4
    assert rig.node.core.nonfinite_range_scans == 4
    nan = [r.getMessage() for r in caplog.records if "NaN" in r.getMessage()]
    assert len(nan) == 1
    assert "has 61 NaN and 0 ±Inf ranges of 181" in nan[0]


@pytest.mark.parametrize(("max_jump", "worst"), [(1.0, 0.1), (0.0, None)])
def test_odometry_jump_is_not_integrated(
    rig_factory: Any, caplog: pytest.LogCaptureFixture, max_jump: float, worst: float | None
) -> None:
    """The odometry jumps 3 m ahead half-way along the drive: refused and re-anchored, the
    robot stays within 0.1 m of the truth; integrated (the check off), it ends metres off."""
    caplog.set_level(logging.WARNING)
    rig = rig_factory(max_odometry_jump=max_jump)
    truth = rig.drive(17, jump_at=8, jump=np.array([3.0, 0.0, 0.0]))
    error = float(np.hypot(*(rig.robot_in_map()[:2] - truth[:2])))
    jumps = [r.getMessage() for r in caplog.records if "odometry jumped" in r.getMessage()]
    if worst is not None:
        assert error < worst
        assert rig.node.core.odometry_jumps == 1
        assert len(jumps) == 1
        assert "odometry jumped 3.25 m, 0.00 rad before the scan at 104.000 s" in jumps[0]
    else:
        assert error > 1.0
        assert jumps == []


# -- localization: initialpose, pose, relocalisation, the buffer ----------------------------
def _initialpose(rig: Rig, pose: np.ndarray, frame: str = "map") -> None:
    from eddiebot.geometry import yaw_to_quaternion
    from eddiebot.msgs.geometry_msgs import PoseWithCovarianceStamped

    msg = PoseWithCovarianceStamped()
    msg.header.frame_id = frame
    msg.pose.pose.position.x, msg.pose.pose.position.y = float(pose[0]), float(pose[1])
    o = msg.pose.pose.orientation
    o.x, o.y, o.z, o.w = yaw_to_quaternion(float(pose[2]))
    pub = rig.probe.create_publisher(PoseWithCovarianceStamped, "/initialpose", 1)
    pub.publish(msg)
    rig.ex.spin_for(0.05)


def _poses_seen(rig: Rig) -> list[Any]:
    from eddiebot.msgs.geometry_msgs import PoseWithCovarianceStamped

    seen: list[Any] = []
    rig.probe.create_subscription(PoseWithCovarianceStamped, "/pose", seen.append, 10)
    return seen


def test_initialpose_places_the_next_scan_and_pose_is_published(
    rig_factory: Any, session: Any
) -> None:
    path, first, last = session
    rig = rig_factory(mode="localization", map_file_name=str(path), map_start_pose=[3.0, 4.0, 0.0])
    seen = _poses_seen(rig)
    _first_scan_at(rig, np.array([3.0, 4.0, 0.0]), np.zeros(3))
    assert len(rig.node.core._loc_buffer) == 1
    # the robot is carried elsewhere; the operator says where
    here = np.array([5.0, 4.0, 0.05])
    _initialpose(rig, here + np.array([0.06, -0.04, 0.02]))
    assert len(rig.node.core._loc_buffer) == 0  # cleared, as upstream
    pose = _first_scan_at(rig, here, np.array([0.4, 0.1, 0.0]))
    assert np.hypot(*(pose[:2] - here[:2])) < 0.03
    assert len(seen) == 2
    got = seen[-1]
    assert got.header.frame_id == "map"
    assert abs(got.pose.pose.position.x - 5.0) < 0.03
    assert got.pose.covariance[0] > 0.0  # the match's x variance
    # another frame is refused with one warning; the pose is not touched
    _initialpose(rig, np.array([9.0, 9.0, 0.0]), frame="odom")
    assert rig.node.core._state.pending_start is None


def test_localization_without_a_start_pose_relocalises_globally(
    rig_factory: Any, session: Any, caplog: pytest.LogCaptureFixture
) -> None:
    path, first, last = session
    caplog.set_level(logging.INFO)
    rig = rig_factory(mode="localization", map_file_name=str(path))
    here = np.array([4.5, 4.0, 0.0])
    odom = np.array([-1.0, 2.0, 0.7])
    rig.publish(rig.now, here, odom)
    rig.ex.spin_for(0.5)
    # the scan callback handed the whole-map search to its process and returned
    assert rig.node.scans_processed == 1 and rig.node.core.relocalizations == []
    assert rig.node.relocalization_search.wait(120.0)
    # the next scan takes the answer (placing the first scan) and is tracked from it
    there = here + np.array([0.3, 0.0, 0.0])
    pose = _first_scan_at(rig, there, se2_compose(odom, np.array([0.3, 0.0, 0.0])))
    assert np.hypot(*(pose[:2] - there[:2])) < 0.05
    (attempt,) = rig.node.core.relocalizations
    assert attempt.accepted
    assert any("relocalised globally" in r.getMessage() for r in caplog.records)


def test_clear_localization_buffer_service(rig_factory: Any, session: Any) -> None:
    from eddiebot.msgs.std_srvs import Empty

    path, first, last = session
    rig = rig_factory(mode="localization", map_file_name=str(path), map_start_pose=[3.0, 4.0, 0.0])
    _first_scan_at(rig, np.array([3.0, 4.0, 0.0]), np.zeros(3))
    assert len(rig.node.core._loc_buffer) == 1
    rig.call(Empty, "clear_localization_buffer")
    assert len(rig.node.core._loc_buffer) == 0
    mapping = rig_factory()
    assert not [s for s in mapping.node.services if s.service_name.endswith("clear_localization_buffer")]


def test_graph_markers_leave_out_marginalised_nodes_and_their_edges(rig_factory: Any) -> None:
    rig = rig_factory()
    _mapped(rig)
    seen: list[Any] = []
    rig.probe.create_subscription(MarkerArray, rig.node.graph_pub.topic_name, seen.append, 10)
    graph = rig.node.core.graph
    n = len(rig.node.core.nodes)
    assert graph.marginalize([3, 4]) == 2
    rig.node._publish_graph()
    rig.ex.spin_for(0.1)
    nodes, edges = seen[-1].markers
    assert len(nodes.points) == n - 2
    live = [e for k, e in enumerate(graph.edges) if k not in set(graph.removed_edges)]
    assert len(edges.points) == 2 * len(live)
    assert all(3 not in (e.i, e.j) and 4 not in (e.i, e.j) for e in live)
