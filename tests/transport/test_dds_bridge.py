"""``eddie bridge dds`` between our graph and a DDS domain, with a ROS 2-like DDS peer.

The bridge runs as a process (``eddie bridge dds``) on a private DDS domain and the session's
private Zenoh router; this test process is both a node of our graph (a context with the
Zenoh transport) and a ROS 2-like DDS participant (Cyclone DDS: ``rt/`` names,
``pkg::msg::dds_::Type_`` types, raw CDR serialized with rosbags, ``typehash`` user data).
"""

from __future__ import annotations

import os
import signal
import struct
import sys
import threading
import time
from collections.abc import Iterator
from typing import Any

import pytest
from _procs import Proc, private_router

cyclonedds = pytest.importorskip("cyclonedds")

from cyclonedds._clayer import ddspy_take, ddspy_write  # noqa: E402
from cyclonedds.builtin import (  # noqa: E402
    BuiltinDataReader,
    BuiltinTopicDcpsSubscription,
)
from cyclonedds.core import InstanceState  # noqa: E402
from cyclonedds.idl import make_idl_struct  # noqa: E402
from cyclonedds.idl import types as idl  # noqa: E402
from cyclonedds.pub import DataWriter  # noqa: E402
from cyclonedds.qos import Policy, Qos  # noqa: E402
from cyclonedds.sub import DataReader  # noqa: E402
from cyclonedds.topic import Topic  # noqa: E402

from _support.dds_peer import ANY as _ANY  # noqa: E402
from _support.dds_peer import RosPeer  # noqa: E402
from _support.dds_peer import String_ as _String  # noqa: E402
from _support.dds_peer import Twist_ as _Twist  # noqa: E402
from _support.dds_peer import private_dds_domain as _private_dds_domain  # noqa: E402
from _support.dds_peer import wait as _wait  # noqa: E402
from eddiebot.core import Context, Node, QoSProfile, SingleThreadedExecutor  # noqa: E402
from eddiebot.core.qos import DurabilityPolicy  # noqa: E402
from eddiebot.msgs import TYPESTORE, serialize, type_hash  # noqa: E402
from eddiebot.msgs.geometry_msgs import Twist, Vector3  # noqa: E402
from eddiebot.msgs.std_msgs import String  # noqa: E402
from eddiebot.transport import connect  # noqa: E402
from eddiebot.transport.dds import (  # noqa: E402
    DdsBridgeConfig,
    cyclone_config,
    dds_qos,
    dds_topic_name,
    idl_type,
    qos_from_dds,
    ros_topic_name,
)

#: Only the topics of these tests are bridged (other tests share the router).
PREFIX = "/ddstest"


# -- pure parts -----------------------------------------------------------------------------
def test_names_follow_ros2_on_dds() -> None:
    assert dds_topic_name("/odom") == "rt/odom"
    assert dds_topic_name("/eddie/ir/left") == "rt/eddie/ir/left"
    assert ros_topic_name("rt/eddie/ir/left") == "/eddie/ir/left"
    assert ros_topic_name("rq/add_two_intsRequest") is None
    assert ros_topic_name("DCPSPublication") is None
    assert idl_type("nav_msgs/msg/Odometry").__idl_typename__ == "nav_msgs::msg::dds_::Odometry_"


@pytest.mark.parametrize("msg", [
    String(data="hello"),
    Twist(linear=Vector3(x=0.25, y=-1.0, z=0.0), angular=Vector3(x=0.0, y=0.0, z=2.5)),
])
def test_generated_dds_types_are_the_ros_definitions(msg: Any) -> None:
    """The IDL struct built from rosbags' field definitions reads and writes the same CDR."""
    cdr = serialize(msg)
    cls = idl_type(msg.__msgtype__)
    assert cls.deserialize(cdr).serialize() == cdr


def test_qos_maps_both_ways() -> None:
    from eddiebot.core.qos import HistoryPolicy, ReliabilityPolicy

    latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    sensor = QoSProfile(depth=5, reliability=ReliabilityPolicy.BEST_EFFORT)
    keep_all = QoSProfile(depth=10, history=HistoryPolicy.KEEP_ALL)
    for profile in (latched, sensor, QoSProfile()):
        assert qos_from_dds(dds_qos(profile)) == profile
    assert qos_from_dds(dds_qos(keep_all)).history == HistoryPolicy.KEEP_ALL  # no depth on DDS
    q = dds_qos(latched, b"typehash=RIHS01_00;")
    assert q[Policy.Durability] == Policy.Durability.TransientLocal
    assert q[Policy.History] == Policy.History.KeepLast(1)
    assert q[Policy.Userdata].data == b"typehash=RIHS01_00;"
    assert q[Policy.IgnoreLocal] == Policy.IgnoreLocal.Participant


def test_deadline_lifespan_and_liveliness_map_both_ways() -> None:
    from eddiebot.core.qos import LivelinessPolicy
    from eddiebot.core.time import Duration
    from eddiebot.transport.dds.types import merge_publisher_qos

    timed = QoSProfile(depth=3, deadline=Duration(250_000_000), lifespan=Duration(2_000_000_000),
                       liveliness=LivelinessPolicy.MANUAL_BY_TOPIC,
                       liveliness_lease_duration=Duration(1_500_000_000))
    q = dds_qos(timed)
    assert q[Policy.Deadline] == Policy.Deadline(250_000_000)
    assert q[Policy.Lifespan] == Policy.Lifespan(2_000_000_000)
    assert q[Policy.Liveliness] == Policy.Liveliness.ManualByTopic(1_500_000_000)
    assert qos_from_dds(q) == timed
    # a reader requests none of them (every writer meets it); lifespan is a writer's
    r = dds_qos(timed, reader=True)
    assert (r[Policy.Deadline], r[Policy.Lifespan], r[Policy.Liveliness]) == (None, None, None)
    # DDS's infinity (what Cyclone reports for an unset policy) reads as "not set"
    infinite = Qos(Policy.Deadline((1 << 63) - 1), Policy.Lifespan((1 << 63) - 1),
                   Policy.Liveliness.Automatic((1 << 63) - 1))
    back = qos_from_dds(infinite)
    assert (back.deadline, back.lifespan, back.liveliness_lease_duration) == (Duration(),) * 3
    assert back.liveliness == LivelinessPolicy.AUTOMATIC
    # one writer for several publishers: the shortest deadline and lease, the longest lifespan
    other = QoSProfile(depth=3, deadline=Duration(100_000_000), lifespan=Duration(500_000_000),
                       liveliness=LivelinessPolicy.MANUAL_BY_TOPIC,
                       liveliness_lease_duration=Duration(3_000_000_000))
    merged = merge_publisher_qos([timed, other])
    assert merged.deadline == Duration(100_000_000)
    assert merged.lifespan == Duration(2_000_000_000)
    assert merged.liveliness == LivelinessPolicy.MANUAL_BY_TOPIC
    assert merged.liveliness_lease_duration == Duration(1_500_000_000)
    plain = merge_publisher_qos([timed, QoSProfile(depth=3)])
    assert plain.lifespan == Duration() and plain.deadline == Duration(250_000_000)
    assert plain.liveliness == LivelinessPolicy.AUTOMATIC


def test_topic_filters() -> None:
    config = DdsBridgeConfig(allow="^/(odom|cmd_vel|eddie/)", deny="ping")
    assert config.admits("/odom")
    assert config.admits("/eddie/ir/left")
    assert not config.admits("/eddie/ping/left")
    assert not config.admits("/map")
    assert "127.0.0.1" in cyclone_config("loopback")
    assert "127.0.0.1" not in cyclone_config("lan")


# -- through the bridge process ------------------------------------------------------------
@pytest.fixture(scope="module")
def zenoh_env() -> Iterator[dict[str, str]]:
    """This module's own Zenoh router: no other test's endpoints reach the bridge."""
    with private_router() as env:
        yield env


@pytest.fixture(scope="module")
def dds_domain() -> Iterator[int]:
    with _private_dds_domain() as domain:
        yield domain


@pytest.fixture(scope="module")
def ros_peer(dds_domain: int) -> RosPeer:
    return RosPeer(dds_domain)


@pytest.fixture(scope="module")
def bridge(zenoh_env: dict[str, str], dds_domain: int) -> Iterator[Proc]:
    env = {**zenoh_env, "ROS_DOMAIN_ID": "0"}
    p = Proc([sys.executable, "-m", "eddiebot.cli.main", "bridge", "dds",
              "--domain", str(dds_domain), "--allow", f"^{PREFIX}/"], env)
    if not p.wait_for("eddie bridge dds: domain", timeout=30):
        p.finish(timeout=5)
        pytest.fail(f"the bridge did not start: {p.stderr}")
    yield p
    p.popen.send_signal(signal.SIGINT)
    try:
        p.popen.wait(timeout=10)
    except Exception:
        p.popen.kill()


@pytest.fixture
def ours(zenoh_config: Any, bridge: Proc) -> Iterator[tuple[Context, Node, Any]]:
    """A node of our graph in this process (the bridge already runs)."""
    ctx = Context(domain_id=0)
    node = Node("dds_test_node", context=ctx)
    transport = connect(ctx, zenoh_config, required=True)
    yield ctx, node, transport
    ctx.shutdown()


def test_our_topic_appears_on_dds_with_ros_names_and_user_data(
        ours: Any, ros_peer: RosPeer, bridge: Proc) -> None:
    _ctx, node, _t = ours
    topic = f"{PREFIX}/chatter"
    pub = node.create_publisher(String, topic, 10)
    reader = ros_peer.reader(topic, _String, "std_msgs/msg/String")
    assert _wait(lambda: bool(ros_peer.publications_on("rt" + topic))), bridge.stderr
    [ep] = ros_peer.publications_on("rt" + topic)
    assert ep.type_name == "std_msgs::msg::dds_::String_"
    assert ep.qos[Policy.Userdata].data == f"typehash={type_hash('std_msgs/msg/String')};".encode()
    assert ep.qos[Policy.Reliability] != Policy.Reliability.BestEffort
    parts = {str(s.key): s for s in ros_peer.participants.read(N=100)}
    assert parts[str(ep.participant_key)].qos[Policy.Userdata].data == b"enclave=/;"

    got: list[Any] = []

    def delivered() -> bool:
        pub.publish(String(data="hello dds"))
        got.extend(ros_peer.take(reader, "std_msgs/msg/String"))
        return bool(got)

    assert _wait(delivered), bridge.stderr
    assert got[0].data == "hello dds"


def test_dds_publication_arrives_on_our_graph(ours: Any, ros_peer: RosPeer, bridge: Proc) -> None:
    ctx, node, transport = ours
    topic = f"{PREFIX}/cmd_vel"
    got: list[Any] = []
    node.create_subscription(Twist, topic, got.append, 10)
    writer = ros_peer.writer(topic, _Twist, "geometry_msgs/msg/Twist")
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    assert _wait(lambda: any(e.type_name == "geometry_msgs/msg/Twist"
                             for e in transport.cache.publishers(topic))), bridge.stderr
    twist = Twist(linear=Vector3(x=0.25, y=0.0, z=0.0), angular=Vector3(x=0.0, y=0.0, z=-0.5))

    def delivered() -> bool:
        RosPeer.write(writer, twist)
        ex.spin_once(timeout_sec=0.05)
        return bool(got)

    assert _wait(delivered), bridge.stderr
    assert (got[0].linear.x, got[0].angular.z) == (0.25, -0.5)


def test_latched_topics_reach_late_subscribers_both_ways(
        ours: Any, ros_peer: RosPeer, bridge: Proc) -> None:
    ctx, node, transport = ours
    latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    # ours → DDS: published once, before any DDS reader exists
    out_topic = f"{PREFIX}/robot_description"
    pub = node.create_publisher(String, out_topic, latched)
    pub.publish(String(data="<robot name='eddie'/>"))
    assert _wait(lambda: bool(ros_peer.publications_on("rt" + out_topic))), bridge.stderr
    [ep] = ros_peer.publications_on("rt" + out_topic)
    assert ep.qos[Policy.Durability] == Policy.Durability.TransientLocal
    time.sleep(0.5)  # the bridge's writer has the sample in its history
    reader = ros_peer.reader(out_topic, _String, "std_msgs/msg/String", latched=True, depth=1)
    got: list[Any] = []
    assert _wait(lambda: bool(got.extend(ros_peer.take(reader, "std_msgs/msg/String")) or got))
    assert [m.data for m in got] == ["<robot name='eddie'/>"]

    # DDS → ours: written once, before any subscription of ours exists
    in_topic = f"{PREFIX}/map_name"
    writer = ros_peer.writer(in_topic, _String, "std_msgs/msg/String", latched=True, depth=1)
    RosPeer.write(writer, String(data="office"))
    assert _wait(lambda: bool(transport.cache.publishers(in_topic))), bridge.stderr
    time.sleep(0.5)
    late: list[Any] = []
    node.create_subscription(String, in_topic, late.append, latched)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    assert _wait(lambda: ex.spin_once(timeout_sec=0.05) or bool(late)), bridge.stderr
    assert [m.data for m in late] == ["office"]
    del writer


def test_no_sample_loops_back(ours: Any, ros_peer: RosPeer, bridge: Proc) -> None:
    """Both sides publish on one topic; every sample is seen once on each side."""
    ctx, node, transport = ours
    topic = f"{PREFIX}/both"
    seen_ours: list[str] = []
    # deep enough to drop nothing: each warm-up round below brings two samples and runs one
    # callback, so a slow warm-up (a loaded machine, up to 300 rounds) leaves up to 300
    # queued, and at depth 100 KEEP_LAST dropped the oldest -- once one of the 20 counted
    node.create_subscription(String, topic, lambda m: seen_ours.append(m.data), 1000)
    pub = node.create_publisher(String, topic, 100)
    writer = ros_peer.writer(topic, _String, "std_msgs/msg/String", depth=100)
    reader = ros_peer.reader(topic, _String, "std_msgs/msg/String", depth=100)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    # both routes up: the bridge's writer on DDS, its publisher in our graph
    assert _wait(lambda: bool(ros_peer.publications_on("rt" + topic))
                 and bool(transport.cache.publishers(topic))), bridge.stderr
    seen_dds: list[str] = []
    # warm up until each side hears the other
    n = 0
    while not (any(s.startswith("dds") for s in seen_ours)
               and any(s.startswith("ours") for s in seen_dds)):
        assert n < 300, (seen_ours, seen_dds, bridge.stderr)
        n += 1
        pub.publish(String(data=f"ours-warm-{n}"))
        RosPeer.write(writer, String(data=f"dds-warm-{n}"))
        ex.spin_once(timeout_sec=0.05)
        seen_dds.extend(m.data for m in ros_peer.take(reader, "std_msgs/msg/String"))
    for i in range(20):
        pub.publish(String(data=f"ours-{i}"))
        RosPeer.write(writer, String(data=f"dds-{i}"))
        time.sleep(0.005)
    end = time.monotonic() + 2.0  # room for any echo to come back
    while time.monotonic() < end:
        ex.spin_once(timeout_sec=0.05)
        seen_dds.extend(m.data for m in ros_peer.take(reader, "std_msgs/msg/String"))
    ours_then = [s for s in seen_ours if not s.startswith(("ours-warm", "dds-warm"))]
    dds_then = [s for s in seen_dds if not s.startswith(("ours-warm", "dds-warm"))]
    # each side: its own samples once (in-process / within the participant), the other
    # side's once through the bridge, never an echo of its own through the bridge
    both = sorted([f"ours-{i}" for i in range(20)] + [f"dds-{i}" for i in range(20)])
    assert sorted(ours_then) == both
    assert sorted(dds_then) == both
    assert all(seen_ours.count(s) == 1 for s in seen_ours)
    assert all(seen_dds.count(s) == 1 for s in seen_dds)
    del writer, reader


def test_routes_follow_publishers_away(ours: Any, ros_peer: RosPeer, bridge: Proc) -> None:
    _ctx, node, transport = ours
    topic = f"{PREFIX}/transient"
    pub = node.create_publisher(String, topic, 10)
    assert _wait(lambda: bool(ros_peer.publications_on("rt" + topic))), bridge.stderr
    pub.destroy()
    assert _wait(lambda: not ros_peer.publications_on("rt" + topic)), bridge.stderr
    writer = ros_peer.writer(f"{PREFIX}/gone", _String, "std_msgs/msg/String")
    assert _wait(lambda: bool(transport.cache.publishers(f"{PREFIX}/gone"))), bridge.stderr
    writer.__del__()
    assert _wait(lambda: not transport.cache.publishers(f"{PREFIX}/gone")), bridge.stderr


def test_deadline_lifespan_and_liveliness_cross_the_bridge(
        ours: Any, ros_peer: RosPeer, bridge: Proc) -> None:
    """A DDS writer's deadline, lifespan and liveliness show on its endpoint in our graph;
    our publisher's on the bridge's DDS writer."""
    from eddiebot.core.qos import LivelinessPolicy
    from eddiebot.core.time import Duration

    _ctx, node, transport = ours
    # DDS → ours
    in_topic = f"{PREFIX}/timed_in"
    qos = Qos(Policy.Reliability.Reliable(max_blocking_time=100_000_000),
              Policy.History.KeepLast(4), Policy.Deadline(300_000_000),
              Policy.Lifespan(1_200_000_000), Policy.Liveliness.ManualByTopic(2_000_000_000),
              Policy.DataRepresentation(use_cdrv0_representation=True),
              Policy.Userdata(f"typehash={type_hash('std_msgs/msg/String')};".encode()))
    writer = DataWriter(ros_peer.participant, ros_peer._topic("rt" + in_topic, _String), qos=qos)
    assert _wait(lambda: bool(transport.cache.publishers(in_topic))), bridge.stderr
    [theirs] = transport.cache.publishers(in_topic)
    profile = theirs.qos_profile
    assert profile.depth == 4
    assert profile.deadline == Duration(300_000_000)
    assert profile.lifespan == Duration(1_200_000_000)
    assert profile.liveliness == LivelinessPolicy.MANUAL_BY_TOPIC
    assert profile.liveliness_lease_duration == Duration(2_000_000_000)
    # ours → DDS
    out_topic = f"{PREFIX}/timed_out"
    node.create_publisher(String, out_topic, QoSProfile(
        depth=2, deadline=Duration(400_000_000), lifespan=Duration(900_000_000),
        liveliness=LivelinessPolicy.AUTOMATIC, liveliness_lease_duration=Duration(5_000_000_000)))
    assert _wait(lambda: bool(ros_peer.publications_on("rt" + out_topic))), bridge.stderr
    [ep] = ros_peer.publications_on("rt" + out_topic)
    assert ep.qos[Policy.Deadline] == Policy.Deadline(400_000_000)
    assert ep.qos[Policy.Lifespan] == Policy.Lifespan(900_000_000)
    assert ep.qos[Policy.Liveliness] == Policy.Liveliness.Automatic(5_000_000_000)
    assert ep.qos[Policy.History] == Policy.History.KeepLast(2)
    del writer


def test_ros2_client_on_dds_calls_a_service_of_our_graph(
        ours: Any, ros_peer: RosPeer, bridge: Proc) -> None:
    """rmw_cyclonedds's request/reply: ``rq/<name>Request`` / ``rr/<name>Reply``, the CDR
    body after the client's {uint64 guid; int64 seq}, which the reply carries back."""
    from eddiebot.msgs.std_srvs import SetBool
    from eddiebot.transport.keys import service_type_hash

    _ctx, node, _t = ours
    name = f"{PREFIX}/set_led"
    calls: list[bool] = []

    def serve(request: Any, response: Any) -> Any:
        calls.append(bool(request.data))
        response.success = True
        response.message = f"led {'on' if request.data else 'off'}"
        return response

    node.create_service(SetBool, name, serve)
    # rmw_cyclonedds sends no XTypes type information, so a ROS 2 peer matches on the type
    # name alone; this Python peer does send it, so it spells the header as the bridge does
    header = {"rmw_request_guid": idl.uint64, "rmw_request_seq": idl.int64}
    req_t = make_idl_struct("SetBool_Request_", "std_srvs::srv::dds_::SetBool_Request_",
                            {**header, "data": bool})
    res_t = make_idl_struct("SetBool_Response_", "std_srvs::srv::dds_::SetBool_Response_",
                            {**header, "success": bool, "message": str})
    qos = Qos(Policy.Reliability.Reliable(max_blocking_time=100_000_000),
              Policy.History.KeepLast(10),
              Policy.DataRepresentation(use_cdrv0_representation=True),
              Policy.Userdata(f"typehash={service_type_hash('std_srvs/srv/SetBool')};".encode()))
    dds_name = name.lstrip("/")
    request_writer = DataWriter(ros_peer.participant, Topic(
        ros_peer.participant, f"rq/{dds_name}Request", req_t), qos=qos)
    reply_reader = DataReader(ros_peer.participant, Topic(
        ros_peer.participant, f"rr/{dds_name}Reply", res_t), qos=qos)
    assert _wait(lambda: bool(ros_peer.publications_on(f"rr/{dds_name}Reply"))), bridge.stderr
    # as rmw's service_is_ready: the request writer and the reply reader both matched
    assert _wait(lambda: request_writer.get_publication_matched_status().current_count > 0
                 and reply_reader.get_subscription_matched_status().current_count > 0)

    guid = 0x0110ABCDEF123456
    body = serialize(SetBool.Request(data=True))
    ddspy_write(request_writer._ref, body[:4] + struct.pack("<Qq", guid, 7) + body[4:])
    replies: list[bytes] = []
    assert _wait(lambda: bool(replies.extend(
        bytes(d) for d, info in ddspy_take(reply_reader._ref, _ANY, 10) if info.valid_data)
        or replies)), bridge.stderr
    raw = replies[0]
    assert struct.unpack_from("<Qq", raw, 4) == (guid, 7)
    response = TYPESTORE.deserialize_cdr(raw[:4] + raw[20:], "std_srvs/srv/SetBool_Response")
    assert (response.success, response.message) == (True, "led on")
    assert calls == [True]


# -- the ROS graph -------------------------------------------------------------------------
# rmw_dds_common's discovery types (Jazzy: 16-byte GIDs), as a ROS 2 node declares them
_Gid = make_idl_struct("Gid_", "rmw_dds_common::msg::dds_::Gid_",
                       {"data": idl.array[idl.uint8, 16]})
_NodeInfo = make_idl_struct("NodeEntitiesInfo_", "rmw_dds_common::msg::dds_::NodeEntitiesInfo_", {
    "node_namespace": idl.bounded_str[256], "node_name": idl.bounded_str[256],
    "reader_gid_seq": idl.sequence[_Gid], "writer_gid_seq": idl.sequence[_Gid]})
_ParticipantInfo = make_idl_struct(
    "ParticipantEntitiesInfo_", "rmw_dds_common::msg::dds_::ParticipantEntitiesInfo_",
    {"gid": _Gid, "node_entities_info_seq": idl.sequence[_NodeInfo]})
_DISCOVERY_QOS = Qos(Policy.Reliability.Reliable(max_blocking_time=100_000_000),
                     Policy.Durability.TransientLocal, Policy.History.KeepLast(1),
                     Policy.DataRepresentation(use_cdrv0_representation=True))


def _gid(guid: Any) -> Any:
    return _Gid(data=list(guid.bytes))


def _infos(peer: RosPeer) -> dict[bytes, Any]:
    """Every participant's latest ros_discovery_info sample, by participant GID."""
    if not hasattr(peer, "info_reader"):
        topic = peer._topic("ros_discovery_info", _ParticipantInfo)
        peer.info_reader = DataReader(peer.participant, topic, qos=Qos(
            Policy.Reliability.Reliable(max_blocking_time=100_000_000),
            Policy.Durability.TransientLocal, Policy.History.KeepAll,
            Policy.DataRepresentation(use_cdrv0_representation=True)))
        peer.infos = {}
    for sample in peer.info_reader.take(N=100):
        peer.infos[bytes(sample.gid.data)] = sample
    return dict(peer.infos)


def test_ros_discovery_info_lists_our_nodes_with_the_bridges_gids(
        ours: Any, ros_peer: RosPeer, bridge: Proc) -> None:
    """What ``ros2 node list`` / ``ros2 topic info -v`` read: the bridge's participant lists
    our node, and under it the GID of the DDS writer that carries its topic."""
    _ctx, node, _t = ours
    topic = f"{PREFIX}/graph_out"
    node.create_publisher(String, topic, 10)
    assert _wait(lambda: bool(ros_peer.publications_on("rt" + topic))), bridge.stderr
    [ep] = ros_peer.publications_on("rt" + topic)

    def listed() -> Any:
        info = _infos(ros_peer).get(ep.participant_key.bytes)
        if info is None:
            return None
        nodes = {(n.node_namespace, n.node_name): n for n in info.node_entities_info_seq}
        mine = nodes.get(("/", "dds_test_node"))
        if mine is None or ep.key.bytes not in [bytes(g.data) for g in mine.writer_gid_seq]:
            return None
        return nodes

    assert _wait(lambda: listed() is not None), bridge.stderr
    nodes = listed()
    assert ("/", "eddie_bridge_dds") in nodes
    # the writer is listed under the node that publishes, not under the bridge
    bridge_writers = [bytes(g.data) for g in nodes[("/", "eddie_bridge_dds")].writer_gid_seq]
    assert ep.key.bytes not in bridge_writers


def test_dds_nodes_and_their_endpoints_appear_on_our_graph(
        ours: Any, ros_peer: RosPeer, bridge: Proc) -> None:
    """A ROS 2 node's ros_discovery_info → our node list; its writer and reader → publisher
    and subscription tokens under that node; gone when it says so."""
    _ctx, _node, transport = ours
    talk, listen = f"{PREFIX}/talk", f"{PREFIX}/listen"
    writer = ros_peer.writer(talk, _String, "std_msgs/msg/String")
    reader = ros_peer.reader(listen, _String, "std_msgs/msg/String")
    info_writer = DataWriter(ros_peer.participant,
                             ros_peer._topic("ros_discovery_info", _ParticipantInfo),
                             qos=_DISCOVERY_QOS)

    def announce(nodes: list[Any]) -> None:
        info_writer.write(_ParticipantInfo(gid=_gid(ros_peer.participant.guid),
                                           node_entities_info_seq=nodes))

    announce([_NodeInfo(node_namespace="/dds", node_name="talker",
                        reader_gid_seq=[_gid(reader.guid)], writer_gid_seq=[_gid(writer.guid)])])
    cache = transport.cache

    def node_of(entities: list[Any]) -> set[str]:
        return {e.node for e in entities}

    assert _wait(lambda: "/dds/talker" in {n.node for n in cache.nodes()}
                 and node_of(cache.publishers(talk)) == {"/dds/talker"}
                 and node_of(cache.subscriptions(listen)) == {"/dds/talker"}), (
        [e.key for e in cache.entities()], bridge.stderr)
    [pub] = cache.publishers(talk)
    assert pub.type_name == "std_msgs/msg/String"
    assert pub.type_hash == str(type_hash("std_msgs/msg/String"))
    writer.__del__()
    assert _wait(lambda: not cache.publishers(talk)), bridge.stderr
    assert node_of(cache.subscriptions(listen)) == {"/dds/talker"}
    announce([])
    assert _wait(lambda: "/dds/talker" not in {n.node for n in cache.nodes()}), bridge.stderr
    # the reader stays, now under the bridge's node (no ROS node claims it)
    assert _wait(lambda: node_of(cache.subscriptions(listen)) == {"/eddie_bridge_dds"})
    reader.__del__()
    assert _wait(lambda: not cache.subscriptions(listen)), bridge.stderr


def test_one_bridged_endpoint_per_topic_and_type(
        ours: Any, ros_peer: RosPeer, bridge: Proc, zenoh_config: Any) -> None:
    """Two publishers of ours → one DDS writer; two DDS writers → each sample once here."""
    ctx, node, transport = ours
    out_topic, in_topic = f"{PREFIX}/two_out", f"{PREFIX}/two_in"
    other_ctx = Context(domain_id=0)
    other = Node("dds_test_other", context=other_ctx)
    connect(other_ctx, zenoh_config, required=True)
    try:
        node.create_publisher(String, out_topic, 10)
        other.create_publisher(String, out_topic, 10)
        assert _wait(lambda: len(transport.cache.publishers(out_topic)) == 1
                     and bool(ros_peer.publications_on("rt" + out_topic))), bridge.stderr
        time.sleep(0.5)  # a second route, were there one, would be up by now
        assert len(ros_peer.publications_on("rt" + out_topic)) == 1

        got: list[str] = []
        node.create_subscription(String, in_topic, lambda m: got.append(m.data), 100)
        writers = [ros_peer.writer(in_topic, _String, "std_msgs/msg/String", depth=100)
                   for _ in range(2)]
        ex = SingleThreadedExecutor(context=ctx)
        ex.add_node(node)
        assert _wait(lambda: len(transport.cache.publishers(in_topic)) == 2), bridge.stderr
        n = 0

        def warm() -> bool:
            nonlocal n
            n += 1
            RosPeer.write(writers[0], String(data=f"warm-{n}"))
            ex.spin_once(timeout_sec=0.05)
            return bool(got)

        assert _wait(warm), bridge.stderr
        for i in range(10):
            RosPeer.write(writers[i % 2], String(data=f"s-{i}"))
        end = time.monotonic() + 1.5
        while time.monotonic() < end:
            ex.spin_once(timeout_sec=0.05)
        assert sorted(s for s in got if s.startswith("s-")) == sorted(f"s-{i}" for i in range(10))
    finally:
        other_ctx.shutdown()


def test_our_client_calls_a_service_served_on_dds(
        ours: Any, ros_peer: RosPeer, bridge: Proc) -> None:
    """An rmw_cyclonedds server: requests on rq/<name>Request with {guid, seq} before the
    body, replies on rr/<name>Reply bearing them back; our client calls it as any service."""
    from eddiebot.msgs.std_srvs import SetBool
    from eddiebot.transport.keys import service_type_hash

    _ctx, node, transport = ours
    name = f"{PREFIX}/dds_led"
    header = {"rmw_request_guid": idl.uint64, "rmw_request_seq": idl.int64}
    req_t = make_idl_struct("SetBool_Request_", "std_srvs::srv::dds_::SetBool_Request_",
                            {**header, "data": bool})
    res_t = make_idl_struct("SetBool_Response_", "std_srvs::srv::dds_::SetBool_Response_",
                            {**header, "success": bool, "message": str})
    qos = Qos(Policy.Reliability.Reliable(max_blocking_time=100_000_000),
              Policy.History.KeepLast(10),
              Policy.DataRepresentation(use_cdrv0_representation=True),
              Policy.Userdata(f"typehash={service_type_hash('std_srvs/srv/SetBool')};".encode()))
    dds_name = name.lstrip("/")
    requests = DataReader(ros_peer.participant, Topic(
        ros_peer.participant, f"rq/{dds_name}Request", req_t), qos=qos)
    replies = DataWriter(ros_peer.participant, Topic(
        ros_peer.participant, f"rr/{dds_name}Reply", res_t), qos=qos)
    headers: list[tuple[int, int]] = []
    stop = threading.Event()

    def serve() -> None:
        while not stop.is_set():
            for data, info in ddspy_take(requests._ref, _ANY, 10):
                raw = bytes(data)
                if not info.valid_data:
                    continue
                guid, seq = struct.unpack_from("<Qq", raw, 4)
                headers.append((guid, seq))
                request = TYPESTORE.deserialize_cdr(raw[:4] + raw[20:],
                                                    "std_srvs/srv/SetBool_Request")
                body = serialize(SetBool.Response(success=bool(request.data),
                                                  message=f"dds led {request.data}"))
                ddspy_write(replies._ref, RosPeer.pad(body[:4] + raw[4:20] + body[4:]))
            time.sleep(0.005)

    server = threading.Thread(target=serve, daemon=True)
    server.start()
    try:
        client = node.create_client(SetBool, name)
        assert client.wait_for_service(timeout_sec=15), bridge.stderr
        [entity] = transport.cache.services(name)
        assert entity.type_name == "std_srvs/srv/SetBool"
        assert bridge.wait_for(f"bridged service {name} [std_srvs/srv/SetBool] <- dds", 5)
        first = client.call(SetBool.Request(data=True), timeout_sec=10)
        second = client.call(SetBool.Request(data=False), timeout_sec=10)
    finally:
        stop.set()
        server.join(2)
    assert (first.success, first.message) == (True, "dds led True")
    assert (second.success, second.message) == (False, "dds led False")
    # one client (the bridge's) calling in sequence
    assert [seq for _g, seq in headers] == [1, 2] and headers[0][0] == headers[1][0] != 0
    # the server goes: so does the service on our graph
    requests.__del__()
    replies.__del__()
    assert _wait(lambda: not transport.cache.services(name)), bridge.stderr
    assert not client.service_is_ready()


def test_a_service_of_ours_that_goes_leaves_dds(
        ours: Any, ros_peer: RosPeer, bridge: Proc) -> None:
    from eddiebot.msgs.std_srvs import Trigger

    _ctx, node, _t = ours
    srv = node.create_service(Trigger, f"{PREFIX}/short_lived",
                              lambda req, res: Trigger.Response(success=True))
    subscriptions = BuiltinDataReader(ros_peer.participant, BuiltinTopicDcpsSubscription)
    alive: dict[str, str] = {}

    def request_readers() -> set[str]:
        for sample in subscriptions.take(N=200):
            if sample.sample_info.instance_state == InstanceState.Alive:
                alive[str(sample.key)] = sample.topic_name
            else:
                alive.pop(str(sample.key), None)
        return {k for k, t in alive.items() if t == "rq/ddstest/short_livedRequest"}

    assert _wait(lambda: len(request_readers()) == 1), bridge.stderr
    node.destroy_service(srv)
    assert _wait(lambda: not request_readers()), bridge.stderr


def test_service_names_and_vendors() -> None:
    from eddiebot.transport.dds import service_names, vendor_of

    assert service_names("rq/eddie/set_ledRequest", "std_srvs::srv::dds_::SetBool_Request_") \
        == ("/eddie/set_led", "std_srvs/srv/SetBool", "request")
    assert service_names("rr/eddie/set_ledReply", "std_srvs::srv::dds_::SetBool_Response_") \
        == ("/eddie/set_led", "std_srvs/srv/SetBool", "reply")
    assert service_names("rt/chatter", "std_msgs::msg::dds_::String_") is None
    assert service_names("rq/xRequest", "std_msgs::msg::dds_::String_") is None
    assert vendor_of(bytes.fromhex("010f" + "00" * 14)) == "Fast DDS"
    assert vendor_of(bytes.fromhex("0110" + "00" * 14)) == "Cyclone DDS"


def test_a_call_of_a_fast_dds_server_says_why_it_cannot_work(zenoh_config: Any) -> None:
    """Fast DDS servers correlate in RTPS inline QoS: the bridge offers the service on our
    graph (so it is listed) and answers each call at once with the reason, in one line."""
    from eddiebot.msgs.std_srvs import SetBool
    from eddiebot.transport.dds import DdsBridge, DdsEndpoint
    from eddiebot.transport.errors import RemoteServiceError

    name = f"{PREFIX}/fast_led"
    bridge_ctx, client_ctx = Context(domain_id=0), Context(domain_id=0)
    transport = connect(bridge_ctx, zenoh_config, required=True)
    connect(client_ctx, zenoh_config, required=True)
    with _private_dds_domain() as domain:
        # this name only: the session's router may still list an earlier test's topics
        dds = DdsBridge(bridge_ctx, transport,
                        DdsBridgeConfig(domain_id=domain, allow=f"^{name}$"))
        try:
            fast_server = DdsEndpoint(
                bytes.fromhex("010f" + "ab" * 10 + "00000104"), bytes.fromhex("010f" + "ab" * 14),
                "rq/ddstest/fast_ledRequest", "std_srvs::srv::dds_::SetBool_Request_", None,
                "Fast DDS")
            dds.discovery.subscriptions = lambda: [fast_server]
            dds.step()
            assert [(r.topic, r.direction) for r in dds.routes()] == [
                (name, "unreachable_service")]
            client = Node("dds_fast_client", context=client_ctx).create_client(SetBool, name)
            assert client.wait_for_service(timeout_sec=15)
            with pytest.raises(RemoteServiceError) as err:
                client.call(SetBool.Request(data=True), timeout_sec=10)
            text = str(err.value)
            assert "Fast DDS" in text and name in text and "\n" not in text
            dds.discovery.subscriptions = list
            dds.step()
            assert dds.routes() == []
        finally:
            dds.close()
            bridge_ctx.shutdown()
            client_ctx.shutdown()


def test_our_action_client_drives_an_action_server_on_dds(
        ours: Any, ros_peer: RosPeer, bridge: Proc) -> None:
    """An action served on DDS is its three services and feedback topic: a goal from our
    ActionClient is accepted, its feedback arrives in order, its result comes back."""
    from eddiebot.core.action import ActionClient
    from eddiebot.msgs import get_action
    from eddiebot.transport.dds.types import service_dds_type

    ctx, node, transport = ours
    action = get_action("nav2_msgs/action/Wait")
    prefix = f"{PREFIX}/wait/_action"
    dds_prefix = prefix.lstrip("/")
    qos = Qos(Policy.Reliability.Reliable(max_blocking_time=100_000_000),
              Policy.History.KeepLast(10),
              Policy.DataRepresentation(use_cdrv0_representation=True))
    servers: dict[str, tuple[Any, Any, str]] = {}
    for srv, type_name in (("send_goal", "nav2_msgs/action/Wait_SendGoal"),
                           ("get_result", "nav2_msgs/action/Wait_GetResult"),
                           ("cancel_goal", "action_msgs/srv/CancelGoal")):
        req = Topic(ros_peer.participant, f"rq/{dds_prefix}/{srv}Request",
                    service_dds_type(type_name + "_Request"))
        res = Topic(ros_peer.participant, f"rr/{dds_prefix}/{srv}Reply",
                    service_dds_type(type_name + "_Response"))
        servers[srv] = (DataReader(ros_peer.participant, req, qos=qos),
                        DataWriter(ros_peer.participant, res, qos=qos), type_name)
    _Uuid = make_idl_struct("UUID_", "unique_identifier_msgs::msg::dds_::UUID_",
                            {"uuid": idl.array[idl.uint8, 16]})
    _Duration = make_idl_struct("Duration_", "builtin_interfaces::msg::dds_::Duration_",
                                {"sec": idl.int32, "nanosec": idl.uint32})
    _WaitFeedback = make_idl_struct("Wait_Feedback_", "nav2_msgs::action::dds_::Wait_Feedback_",
                                    {"time_left": _Duration})
    _FeedbackMessage = make_idl_struct(
        "Wait_FeedbackMessage_", "nav2_msgs::action::dds_::Wait_FeedbackMessage_",
        {"goal_id": _Uuid, "feedback": _WaitFeedback})
    feedback = ros_peer.writer(f"{prefix}/feedback", _FeedbackMessage,
                               "nav2_msgs/action/Wait_FeedbackMessage")
    stop = threading.Event()
    goals: list[bytes] = []

    def answer(srv: str, raw: bytes, response: Any) -> None:
        _reader, writer, type_name = servers[srv]
        body = serialize(response, type_name + "_Response")
        ddspy_write(writer._ref, RosPeer.pad(body[:4] + raw[4:20] + body[4:]))

    def serve() -> None:
        while not stop.is_set():
            for srv, (reader, _writer, type_name) in servers.items():
                for data, info in ddspy_take(reader._ref, _ANY, 10):
                    raw = bytes(data)
                    if not info.valid_data:
                        continue
                    request = TYPESTORE.deserialize_cdr(raw[:4] + raw[20:], type_name + "_Request")
                    if srv == "send_goal":
                        goals.append(bytes(request.goal_id.uuid))
                        answer(srv, raw, action.SendGoal.Response(accepted=True))
                        for left in (2, 1, 0):
                            msg = action.FeedbackMessage(goal_id=request.goal_id)
                            msg.feedback.time_left.sec = left
                            RosPeer.write(feedback, msg)
                    elif srv == "get_result":
                        response = action.GetResult.Response(status=4)
                        response.result.total_elapsed_time.sec = int(request.goal_id.uuid[0])
                        answer(srv, raw, response)
            time.sleep(0.005)

    server = threading.Thread(target=serve, daemon=True)
    server.start()
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    spinner = threading.Thread(target=ex.spin, daemon=True)
    try:
        client = ActionClient(node, action, f"{PREFIX}/wait")
        assert client.wait_for_server(timeout_sec=15), bridge.stderr
        assert _wait(lambda: bool(transport.cache.publishers(f"{prefix}/feedback"))), bridge.stderr
        spinner.start()
        left: list[int] = []
        goal = action.Goal()
        goal.time.sec = 3
        result = client.send_goal(goal, lambda m: left.append(int(m.feedback.time_left.sec)),
                                  timeout_sec=10)
    finally:
        stop.set()
        server.join(2)
        ex.shutdown()
    assert result is not None and int(result.status) == 4
    assert len(goals) == 1 and result.result.total_elapsed_time.sec == goals[0][0]
    assert left == [2, 1, 0]


# -- the bond across ------------------------------------------------------------------------
_Header = make_idl_struct("Header_", "std_msgs::msg::dds_::Header_", {
    "stamp": make_idl_struct("Time_", "builtin_interfaces::msg::dds_::Time_",
                             {"sec": idl.int32, "nanosec": idl.uint32}),
    "frame_id": str})
_Status = make_idl_struct("Status_", "bond::msg::dds_::Status_", {
    "header": _Header, "id": str, "instance_id": str, "active": bool,
    "heartbeat_timeout": idl.float32, "heartbeat_period": idl.float32})


class _DdsLifecycleNode:
    """A lifecycle node on DDS as rclcpp_lifecycle and bondcpp make one: ``get_state`` and
    ``change_state`` served the rmw_cyclonedds way, and, while active, ``bond/msg/Status``
    heartbeats on ``bond`` every 0.1 s (id: its name, an instance id of its own, bondcpp's
    4 s timeout) until :attr:`beating` is cleared."""

    def __init__(self, peer: RosPeer, namespace: str, name: str) -> None:
        from eddiebot.transport.dds.types import service_dds_type

        self.name, self.state, self.instance = name, 1, os.urandom(8).hex()
        self.beating = threading.Event()
        self.beating.set()
        self.seen: list[Any] = []  # the manager's heartbeats, as bondcpp's sister sees them
        qos = Qos(Policy.Reliability.Reliable(max_blocking_time=100_000_000),
                  Policy.History.KeepLast(10),
                  Policy.DataRepresentation(use_cdrv0_representation=True))
        self.servers = {}
        base = f"{namespace}/{name}".lstrip("/")
        for srv, type_name in (("get_state", "lifecycle_msgs/srv/GetState"),
                               ("change_state", "lifecycle_msgs/srv/ChangeState")):
            req = Topic(peer.participant, f"rq/{base}/{srv}Request",
                        service_dds_type(type_name + "_Request"))
            res = Topic(peer.participant, f"rr/{base}/{srv}Reply",
                        service_dds_type(type_name + "_Response"))
            self.servers[srv] = (DataReader(peer.participant, req, qos=qos),
                                 DataWriter(peer.participant, res, qos=qos), type_name)
        self.bond_writer = peer.writer(f"{namespace}/bond", _Status, "bond/msg/Status", depth=5)
        self.bond_reader = peer.reader(f"{namespace}/bond", _Status, "bond/msg/Status", depth=100)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _serve(self) -> None:
        from eddiebot.msgs.lifecycle_msgs import ChangeState, GetState, State

        labels = {1: "unconfigured", 2: "inactive", 3: "active"}
        goes = {(1, 1): 2, (2, 3): 3, (3, 4): 2, (2, 2): 1}  # (state, transition) → state
        for srv, (reader, writer, type_name) in self.servers.items():
            for data, info in ddspy_take(reader._ref, _ANY, 10):
                raw = bytes(data)
                if not info.valid_data:
                    continue
                request = TYPESTORE.deserialize_cdr(raw[:4] + raw[20:], type_name + "_Request")
                if srv == "get_state":
                    response: Any = GetState.Response(
                        current_state=State(id=self.state, label=labels[self.state]))
                else:
                    after = goes.get((self.state, int(request.transition.id)))
                    response = ChangeState.Response(success=after is not None)
                    self.state = after or self.state
                body = serialize(response, type_name + "_Response")
                ddspy_write(writer._ref, RosPeer.pad(body[:4] + raw[4:20] + body[4:]))

    def _run(self) -> None:
        from eddiebot.msgs.bond import Status

        next_beat = 0.0
        while not self._stop.is_set():
            self._serve()
            self.seen.extend(m for m in RosPeer.take(self.bond_reader, "bond/msg/Status")
                             if m.instance_id != self.instance)
            if self.state == 3 and self.beating.is_set() and time.monotonic() >= next_beat:
                next_beat = time.monotonic() + 0.1
                RosPeer.write(self.bond_writer, Status(
                    id=self.name, instance_id=self.instance, active=True,
                    heartbeat_timeout=4.0, heartbeat_period=0.1))
            time.sleep(0.005)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2)


def test_our_lifecycle_manager_keeps_a_bond_with_a_dds_node_while_it_beats(
        ours: Any, ros_peer: RosPeer, bridge: Proc) -> None:
    """bondcpp's protocol across the bridge: our manager brings a DDS lifecycle node up
    through its services, keeps the bond while ``bond/msg/Status`` heartbeats arrive from
    DDS, sees its own heartbeats reach the DDS side, and breaks the bond (taking the system
    down) once the DDS node stops beating for the bond timeout."""
    from eddiebot.core import MultiThreadedExecutor
    from eddiebot.core.lifecycle import LifecycleManager

    ctx, _node, transport = ours
    dds_node = _DdsLifecycleNode(ros_peer, PREFIX, "dds_camera")
    manager = LifecycleManager(
        "lifecycle_manager", namespace=PREFIX, context=ctx, parameter_overrides={
            "node_names": ["dds_camera"], "bond_timeout": 1.0,
            "attempt_respawn_reconnection": False})
    ex = MultiThreadedExecutor(context=ctx)
    ex.add_node(manager)
    spinner = threading.Thread(target=ex.spin, daemon=True)
    spinner.start()
    try:
        # the node's services and the DDS side of /ddstest/bond are on our graph
        assert _wait(lambda: bool(transport.cache.services(f"{PREFIX}/dds_camera/change_state"))
                     and bool(transport.cache.publishers(f"{PREFIX}/bond"))), bridge.stderr
        assert manager.startup(), (manager.last_error, bridge.stderr)
        assert dds_node.state == 3 and manager.system_active
        # 3 bond timeouts of heartbeats from DDS: the bond holds
        end = time.monotonic() + 3.0
        while time.monotonic() < end:
            assert manager.system_active, (manager.last_error, manager.dead_nodes)
            time.sleep(0.05)
        assert manager.dead_nodes == []
        # the manager's side of the bond reached the DDS node: its id, another instance
        ours_beats = [m for m in dds_node.seen if m.id == "dds_camera" and m.active]
        assert len(ours_beats) >= 10, len(ours_beats)
        assert {m.instance_id for m in ours_beats} == {ours_beats[0].instance_id}
        assert ours_beats[0].heartbeat_timeout == 1.0
        # the DDS node stops beating: the bond breaks and the manager takes the system down
        dds_node.beating.clear()
        assert _wait(lambda: not manager.system_active, 10.0), bridge.stderr
        assert manager.dead_nodes == ["dds_camera"]
        assert manager.last_error == "bond with dds_camera timed out"
    finally:
        ex.shutdown()
        spinner.join(2)
        manager.destroy_node()
        dds_node.close()
