"""The node graph API and create_rate, in one process."""

from __future__ import annotations

import threading
import time
from typing import Any

import pytest

from eddiebot.core import Context, Node, QoSProfile, SingleThreadedExecutor
from eddiebot.core.graph import TopicEndpointTypeEnum
from eddiebot.core.qos import ReliabilityPolicy
from eddiebot.msgs import type_hash
from eddiebot.msgs.sensor_msgs import LaserScan
from eddiebot.msgs.std_msgs import String
from eddiebot.msgs.std_srvs import Trigger

S = 1_000_000_000


@pytest.fixture
def ctx() -> Any:
    c = Context(use_sim_time=True)
    yield c
    c.shutdown()


def _graph(ctx: Context) -> tuple[Node, Node]:
    a = Node("lidar", namespace="/robot", context=ctx, start_parameter_services=False)
    b = Node("mapper", context=ctx, start_parameter_services=False)
    a.create_publisher(LaserScan, "scan", QoSProfile(depth=5, reliability=ReliabilityPolicy.BEST_EFFORT))
    b.create_subscription(LaserScan, "/robot/scan", lambda m: None, 10)
    b.create_subscription(LaserScan, "/robot/scan", lambda m: None, 1)
    b.create_publisher(String, "/status", 10)
    a.create_service(Trigger, "reset", lambda req, res: res)
    b.create_client(Trigger, "/robot/reset")
    return a, b


def test_node_and_topic_names_and_types(ctx: Context) -> None:
    a, b = _graph(ctx)
    assert a.get_node_names() == ["mapper", "lidar"]  # sorted by namespace, then name
    assert b.get_node_names_and_namespaces() == [("mapper", "/"), ("lidar", "/robot")]
    assert b.get_fully_qualified_node_names() == ["/mapper", "/robot/lidar"]
    assert b.get_topic_names_and_types() == [
        ("/robot/scan", ["sensor_msgs/msg/LaserScan"]),
        ("/status", ["std_msgs/msg/String"]),
    ]
    assert b.get_service_names_and_types() == [("/robot/reset", ["std_srvs/srv/Trigger"])]
    assert b.get_publisher_names_and_types_by_node("lidar", "/robot") == [
        ("/robot/scan", ["sensor_msgs/msg/LaserScan"])]
    assert b.get_subscriber_names_and_types_by_node("mapper", "/") == [
        ("/robot/scan", ["sensor_msgs/msg/LaserScan"])]
    assert b.get_client_names_and_types_by_node("mapper", "/") == [
        ("/robot/reset", ["std_srvs/srv/Trigger"])]


def test_counts_resolve_names_against_the_node(ctx: Context) -> None:
    a, b = _graph(ctx)
    assert a.count_publishers("scan") == 1  # /robot/scan from /robot/lidar
    assert a.count_subscribers("scan") == 2
    assert b.count_publishers("scan") == 0  # /scan from /mapper
    assert b.count_subscribers("/robot/scan") == 2
    assert b.count_services("/robot/reset") == 1
    assert a.count_clients("reset") == 1


def test_endpoint_info_names_node_type_qos_and_a_gid_each(ctx: Context) -> None:
    a, b = _graph(ctx)
    pubs = b.get_publishers_info_by_topic("/robot/scan")
    assert len(pubs) == 1
    info = pubs[0]
    assert (info.node_name, info.node_namespace) == ("lidar", "/robot")
    assert info.topic_type == "sensor_msgs/msg/LaserScan"
    assert info.topic_type_hash == str(type_hash("sensor_msgs/msg/LaserScan"))
    assert info.endpoint_type == TopicEndpointTypeEnum.PUBLISHER
    assert info.qos_profile.depth == 5
    assert info.qos_profile.reliability == ReliabilityPolicy.BEST_EFFORT
    subs = b.get_subscriptions_info_by_topic("/robot/scan")
    assert [s.qos_profile.depth for s in subs] == [10, 1]
    gids = {info.endpoint_gid, *(s.endpoint_gid for s in subs)}
    assert len(gids) == 3 and all(len(g) == 16 for g in gids)


def test_destroyed_entities_leave_the_graph(ctx: Context) -> None:
    a, b = _graph(ctx)
    b.destroy_subscription(b.subscriptions[0])
    assert b.count_subscribers("/robot/scan") == 1
    a.destroy_node()
    assert b.get_node_names() == ["mapper"]
    assert b.count_publishers("/robot/scan") == 0


def test_rate_sleeps_until_the_next_tick_of_the_node_clock(ctx: Context) -> None:
    ex = SingleThreadedExecutor(context=ctx, drive_sim_time=False)
    node = Node("looper", context=ctx)
    ex.add_node(node)
    rate = node.create_rate(10.0)
    done: list[int] = []

    def loop() -> None:
        for _ in range(3):
            rate.sleep()
            done.append(ctx.sim_clock.now_ns())

    spinner = threading.Thread(target=ex.spin, daemon=True)
    spinner.start()
    worker = threading.Thread(target=loop, daemon=True)
    worker.start()
    try:
        tick = 0
        while len(done) < 3 and tick < 200:
            tick += 1
            seen = len(done)
            ctx.sim_clock.set_ns(tick * S // 10)
            ex.wake()
            deadline = time.monotonic() + 0.2
            while len(done) == seen and time.monotonic() < deadline:
                time.sleep(0.002)
        assert len(done) == 3
        # each sleep ended on a tick of the 10 Hz timer, one tick after another
        assert all(t % (S // 10) == 0 for t in done)
        assert done == sorted(set(done))
    finally:
        ex.shutdown()
        worker.join(5)


def test_rate_refuses_to_sleep_on_the_spinning_thread(ctx: Context) -> None:
    ex = SingleThreadedExecutor(context=ctx)
    node = Node("deadlock", context=ctx)
    ex.add_node(node)
    rate = node.create_rate(5.0)
    errors: list[str] = []

    def tick() -> None:
        try:
            rate.sleep()
        except RuntimeError as exc:
            errors.append(str(exc))

    node.create_timer(0.1, tick, oneshot=True)
    ex.spin_for(0.2)
    assert len(errors) == 1 and "/deadlock" in errors[0]
    with pytest.raises(ValueError, match="positive"):
        node.create_rate(0)
