"""The node graph API sees the other processes of the graph (through liveliness tokens)."""

from __future__ import annotations

import time
from typing import Any

from eddiebot.core import Context, Node, QoSProfile
from eddiebot.core.qos import DurabilityPolicy
from eddiebot.msgs.std_msgs import String
from eddiebot.transport import connect
from eddiebot.transport.keys import entity_gid


def _wait(cond: Any, timeout: float = 10.0) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if cond():
            return True
        time.sleep(0.01)
    return cond()


def test_graph_queries_include_remote_entities_with_their_gids(zenoh_config: Any) -> None:
    here, there = Context(), Context()
    try:
        me = Node("observer", context=here, start_parameter_services=False)
        connect(here, zenoh_config, required=True)
        talker = Node("talker", namespace="/far", context=there, start_parameter_services=False)
        t_there = connect(there, zenoh_config, required=True)
        assert t_there is not None
        pub = talker.create_publisher(String, "chatter", QoSProfile(
            depth=7, durability=DurabilityPolicy.TRANSIENT_LOCAL))
        me.create_subscription(String, "/far/chatter", lambda m: None, 3)

        assert _wait(lambda: me.count_publishers("/far/chatter") == 1)
        assert ("talker", "/far") in me.get_node_names_and_namespaces()
        assert ("/far/chatter", ["std_msgs/msg/String"]) in me.get_topic_names_and_types()
        info = me.get_publishers_info_by_topic("/far/chatter")[0]
        assert (info.node_name, info.node_namespace) == ("talker", "/far")
        assert info.qos_profile.depth == 7
        assert info.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL
        # the GID the other process computed for its own publisher, as rmw_zenoh does
        assert info.endpoint_gid == t_there.entity_gid_of(pub)
        assert info.endpoint_gid == entity_gid(t_there._token_keys[id(pub)])
        assert me.count_subscribers("/far/chatter") == 1  # our own, locally

        talker.destroy_publisher(pub)
        assert _wait(lambda: me.count_publishers("/far/chatter") == 0)
    finally:
        there.shutdown()
        here.shutdown()
