import pytest

from eddiebot.core import (
    Context,
    Node,
    ParameterDescriptor,
    SetParametersResult,
    SingleThreadedExecutor,
)
from eddiebot.core.param_services import ParameterClient, list_parameter_names
from eddiebot.core.parameters import ParameterType
from eddiebot.msgs.rcl_interfaces import ParameterEvent


@pytest.fixture
def graph():
    ctx = Context(use_sim_time=True)
    ex = SingleThreadedExecutor(context=ctx)
    server = Node("controller_server", namespace="robot", context=ctx)
    server.declare_parameter("controller_frequency", 20.0)
    server.declare_parameter("FollowPath.desired_linear_vel", 0.5)
    server.declare_parameter("FollowPath.lookahead.min", 0.3)
    server.declare_parameter("odom_topic", "odom")
    server.declare_parameter("max_speed", 1.0, ParameterDescriptor(range=(0.0, 2.0),
                                                                   description="m/s"))
    client_node = Node("eddie_param", context=ctx, start_parameter_services=False)
    ex.add_node(server)
    ex.add_node(client_node)
    yield ctx, ex, server, ParameterClient(client_node, "/robot/controller_server")
    ctx.shutdown()


def test_every_node_serves_parameters(graph):
    ctx, _, _, _ = graph
    assert "/robot/controller_server/list_parameters" in ctx.services
    assert "/robot/controller_server/set_parameters_atomically" in ctx.services
    assert "/eddie_param/get_parameters" not in ctx.services


def test_get_and_types(graph):
    _, _, _, client = graph
    assert client.services_are_ready()
    assert client.get_parameters(["controller_frequency", "odom_topic", "missing"]) == [
        20.0, "odom", None]
    assert client.get_parameter_types(["controller_frequency", "odom_topic", "missing"]) == [
        ParameterType.DOUBLE, ParameterType.STRING, ParameterType.NOT_SET]
    (desc,) = client.describe_parameters(["max_speed"])
    assert desc.description == "m/s"
    assert desc.floating_point_range[0].to_value == 2.0


def test_set_parameters_validates_and_publishes_events(graph):
    ctx, ex, server, client = graph
    events = []
    listener = Node("listener", context=ctx, start_parameter_services=False)
    listener.create_subscription(ParameterEvent, "/parameter_events", events.append, 10)
    ex.add_node(listener)
    results = client.set_parameters({"controller_frequency": 10, "max_speed": 5.0,
                                     "odom_topic": 3, "nope": 1})
    assert [r.successful for r in results] == [True, False, False, False]
    assert "outside" in results[1].reason
    assert "string" in results[2].reason
    assert "not declared" in results[3].reason
    assert server.get_parameter("controller_frequency").value == 10.0
    ex.spin_until_idle()
    assert len(events) == 1
    assert events[0].node == "/robot/controller_server"
    assert events[0].changed_parameters[0].name == "controller_frequency"
    assert events[0].changed_parameters[0].value.double_value == 10.0


def test_rejecting_on_set_callback_and_atomic_all_or_nothing(graph):
    _, _, server, client = graph

    def no_slow_controllers(params):
        for p in params:
            if p.name == "controller_frequency" and p.value < 5.0:
                return SetParametersResult(False, "controller_frequency must be >= 5 Hz")
        return SetParametersResult(True)

    server.add_on_set_parameters_callback(no_slow_controllers)
    result = client.set_parameters_atomically({"odom_topic": "wheel_odom", "controller_frequency": 1.0})
    assert not result.successful and "5 Hz" in result.reason
    assert server.get_parameter("odom_topic").value == "odom"  # nothing applied
    assert client.set_parameters_atomically({"odom_topic": "wheel_odom",
                                             "controller_frequency": 8.0}).successful
    assert client.get_parameters(["odom_topic", "controller_frequency"]) == ["wheel_odom", 8.0]


def test_list_parameters_prefixes_and_depth(graph):
    _, _, _, client = graph
    names = client.list_parameters()
    assert set(names) == {"use_sim_time", "controller_frequency", "FollowPath.desired_linear_vel",
                          "FollowPath.lookahead.min", "odom_topic", "max_speed"}
    assert client.list_parameters(depth=1) == [
        "use_sim_time", "controller_frequency", "odom_topic", "max_speed"]
    assert client.list_parameters(["FollowPath"]) == [
        "FollowPath.desired_linear_vel", "FollowPath.lookahead.min"]
    assert client.list_parameters(["FollowPath"], depth=2) == ["FollowPath.desired_linear_vel"]


def test_list_parameter_names_prefixes_as_rclpy():
    names, prefixes = list_parameter_names(["a", "b.c", "b.d.e", "bb"], ["b"], 0)
    assert names == ["bb", "b.c", "b.d.e"]  # plain names match by string prefix, as rclpy
    assert prefixes == ["b", "b.d"]
    names, prefixes = list_parameter_names(["a", "b.c", "b.d.e"], [], 0)
    assert (names, prefixes) == (["a", "b.c", "b.d.e"], ["b", "b.d"])


def test_client_call_from_a_spinning_callback(graph):
    ctx, ex, _, client = graph
    seen = []
    client.node.create_timer(0.5, lambda: seen.append(client.get_parameter("odom_topic")),
                             oneshot=True)
    ex.spin_for(1.0)
    assert seen == ["odom"]
