"""The Zenoh transport between real processes on loopback (a private router per session)."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from typing import Any

import pytest

from eddiebot.core import Context, Node, SingleThreadedExecutor, qos_profile_latched
from eddiebot.msgs.std_msgs import Int32, String
from eddiebot.transport import connect


@pytest.fixture
def local(zenoh_config: Any) -> Iterator[Callable[[str], tuple[Context, Node, Any]]]:
    """``local(name)``: a context of this test process joined to the session's graph."""
    made: list[Context] = []

    def make(name: str) -> tuple[Context, Node, Any]:
        ctx = Context()
        made.append(ctx)
        node = Node(name, context=ctx)
        transport = connect(ctx, zenoh_config, required=True)
        return ctx, node, transport

    yield make
    for ctx in made:
        ctx.shutdown()


def _spin_until(ex: SingleThreadedExecutor, cond: Callable[[], bool], timeout: float = 10.0) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        ex.spin_once(timeout_sec=0.05)
        if cond():
            return True
    return False


def _wait(cond: Callable[[], bool], timeout: float = 10.0) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if cond():
            return True
        time.sleep(0.01)
    return False


def test_string_reaches_another_process(spawn: Any) -> None:
    listener = spawn("listener", "/chatter", "1")
    assert listener.wait_for("READY")
    talker = spawn("talker", "/chatter", "hello from A")
    assert listener.finish(timeout=20) == 0, listener.stderr
    assert "GOT hello from A" in listener.lines
    assert talker.finish(timeout=10) == 0, talker.stderr


def test_publisher_sees_remote_subscription_and_sends_only_then(spawn: Any, local: Any) -> None:
    ctx, node, transport = local("counter")
    pub = node.create_publisher(String, "/counted", 10)
    assert pub.get_subscription_count() == 0
    listener = spawn("listener", "/counted", "1")
    assert listener.wait_for("READY")
    assert _wait(lambda: pub.get_subscription_count() == 1)
    pub.publish(String(data="now"))
    assert listener.finish(timeout=20) == 0, listener.stderr
    assert _wait(lambda: pub.get_subscription_count() == 0)
    graph = transport.graph()
    assert graph["remote_subscriptions"].get("/counted", 0) == 0


def test_in_process_delivery_stays_by_reference(local: Any) -> None:
    ctx, node, _transport = local("zero_copy")
    got: list[Any] = []
    node.create_subscription(String, "/local_only", got.append, 10)
    pub = node.create_publisher(String, "/local_only", 10)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    msg = String(data="same object")
    pub.publish(msg)
    assert _spin_until(ex, lambda: bool(got), 2.0)
    assert got[0] is msg


def test_string_from_this_process_reaches_the_hub(hub: Any, local: Any) -> None:
    _ctx, node, _t = local("chatty")
    pub = node.create_publisher(String, "/chatter", 10)
    assert _wait(lambda: pub.get_subscription_count() == 1)
    pub.publish(String(data="hello hub"))
    assert hub.wait_for("GOT /chatter hello hub", timeout=10)


def test_service_call_across_processes(hub: Any, local: Any) -> None:
    from eddiebot.msgs.std_srvs import Trigger

    _ctx, node, _t = local("caller")
    client = node.create_client(Trigger, "/ping")
    assert client.wait_for_service(timeout_sec=10)
    response = client.call(Trigger.Request(), timeout_sec=10)
    assert response.success
    assert response.message == f"pong from {hub.popen.pid}"


def test_service_of_another_type_is_refused(hub: Any, local: Any) -> None:
    from eddiebot.msgs.std_srvs import SetBool

    _ctx, node, _t = local("wrong_caller")
    client = node.create_client(SetBool, "/ping")
    assert client.wait_for_service(timeout_sec=10)
    with pytest.raises(TypeError, match="Trigger"):
        client.call(SetBool.Request(), timeout_sec=10)


def test_parameters_across_processes(hub: Any, local: Any) -> None:
    from eddiebot.core.param_services import ParameterClient

    _ctx, node, _t = local("param_caller")
    params = ParameterClient(node, "/hub", timeout_sec=10)
    assert params.wait_for_services(timeout_sec=10)
    assert params.get_parameter("label") == "eddie"
    assert "speed" in params.list_parameters()
    assert params.set_parameters({"speed": 1.25})[0].successful
    assert params.get_parameter("speed") == pytest.approx(1.25)
    assert not params.set_parameters({"speed": "fast"})[0].successful
    assert params.set_parameters({"speed": 0.5})[0].successful


def test_transient_local_late_joiner_across_processes(hub: Any, local: Any) -> None:
    # the hub published /latched_map when it started, before this subscription existed
    ctx, node, _t = local("late")
    got: list[str] = []
    node.create_subscription(String, "/latched_map", lambda m: got.append(m.data),
                             qos_profile_latched)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    assert _spin_until(ex, lambda: bool(got), 10.0)
    assert got == ["the map"]


def test_a_later_transient_local_subscription_in_the_process_gets_the_history(
        hub: Any, local: Any) -> None:
    # one Zenoh subscriber per topic and process fetches the publishers' history once: a
    # second node's subscription (every node's /tf_static listener) must get it too
    ctx, node, _t = local("first")
    first: list[str] = []
    second: list[str] = []
    node.create_subscription(String, "/latched_map", lambda m: first.append(m.data),
                             qos_profile_latched)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    assert _spin_until(ex, lambda: bool(first), 10.0)
    later = Node("later", context=ctx)
    later.create_subscription(String, "/latched_map", lambda m: second.append(m.data),
                              qos_profile_latched)
    ex.add_node(later)
    assert _spin_until(ex, lambda: bool(second), 5.0)
    assert first == ["the map"] and second == ["the map"]


def test_type_mismatch_is_reported_with_both_types(hub: Any, local: Any) -> None:
    _ctx, node, _t = local("int_pub")
    pub = node.create_publisher(Int32, "/mixed", 10)
    assert _wait(lambda: pub.get_subscription_count() == 1)
    deadline = time.monotonic() + 10
    while "type mismatch" not in hub.stderr and time.monotonic() < deadline:
        pub.publish(Int32(data=7))
        time.sleep(0.05)
    for _ in range(5):
        pub.publish(Int32(data=8))
    time.sleep(0.3)
    err = hub.stderr
    line = next(x for x in err.splitlines() if "type mismatch" in x)
    assert "/mixed" in line
    assert "std_msgs/msg/String" in line
    assert "std_msgs/msg/Int32" in line
    assert err.count("type mismatch") == 1  # logged once
    assert not any(x.startswith("GOT /mixed") for x in hub.lines)  # samples dropped


def test_action_across_processes(hub: Any, local: Any) -> None:
    pytest.importorskip("eddiebot.core.action", reason="needs core.action")
    from eddiebot.core.action import ActionClient
    from eddiebot.msgs.nav2_msgs import Wait

    ctx, node, _t = local("action_caller")
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    client = ActionClient(node, Wait, "/wait_here")
    assert client.wait_for_server(timeout_sec=10)
    time.sleep(0.3)  # the server learns of our feedback subscription
    feedback: list[Any] = []
    goal = Wait.Goal()
    goal.time.sec = 3
    send = client.send_goal_async(goal, feedback_callback=feedback.append)
    assert _spin_until(ex, send.done, 10.0)
    handle = send.result()
    assert handle.accepted
    result = handle.get_result_async()
    assert _spin_until(ex, result.done, 10.0)
    res = result.result()
    assert res.status == 4  # SUCCEEDED
    assert res.result.total_elapsed_time.sec == 3
    assert res.result.error_msg == "done"
    assert _spin_until(ex, lambda: bool(feedback), 3.0)


def test_raw_subscription_gets_cdr_bytes(hub: Any, local: Any) -> None:
    from eddiebot.msgs import deserialize

    ctx, node, _t = local("raw_reader")
    got: list[Any] = []
    node.create_subscription(String, "/latched_map", got.append, qos_profile_latched, raw=True)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    assert _spin_until(ex, lambda: bool(got), 10.0)
    assert isinstance(got[0], bytes)
    assert deserialize(got[0], "std_msgs/msg/String").data == "the map"


def test_transport_can_be_disabled(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("EDDIE_TRANSPORT", "none")
    ctx = Context()
    try:
        assert connect(ctx) is None
        assert ctx.transports == []
    finally:
        ctx.shutdown()
