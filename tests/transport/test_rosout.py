"""A process on the transport publishes every node's log lines on /rosout, as rcl does."""

from __future__ import annotations

from typing import Any

from eddiebot.core import Context, Node, SingleThreadedExecutor
from eddiebot.msgs.rcl_interfaces import Log
from eddiebot.transport import connect


def test_a_process_on_the_transport_publishes_rosout(zenoh_config: Any) -> None:
    ctx = Context()
    try:
        assert connect(ctx, zenoh_config, required=True) is not None
        talker = Node("talker", context=ctx)
        viewer = Node("viewer", context=ctx)
        got: list[Any] = []
        viewer.create_subscription(Log, "/rosout", got.append, 10)
        talker.get_logger().warning("wheels slipping")
        ex = SingleThreadedExecutor(context=ctx)
        ex.add_node(talker)
        ex.add_node(viewer)
        ex.spin_until_idle()
        assert [(m.name, m.msg, m.level) for m in got] == [("talker", "wheels slipping", 30)]
    finally:
        ctx.shutdown()
