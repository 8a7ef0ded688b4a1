"""``talker`` and ``listener``, as ROS 2's demo_nodes: the smallest complete nodes."""

from __future__ import annotations

from typing import Any

from eddiebot.core.node import Node
from eddiebot.msgs.std_msgs import String


class Talker(Node):
    """Publishes ``Hello World: N`` on ``chatter`` every ``period`` seconds."""

    default_node_name = "talker"

    def __init__(self, node_name: str = default_node_name, **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        self.declare_parameter("period", 1.0)
        self.declare_parameter("text", "Hello World")
        self.count = 0
        self.pub = self.create_publisher(String, "chatter", 10)
        self.create_timer(self.get_parameter("period").value, self._tick)

    def _tick(self) -> None:
        self.count += 1
        msg = String(data=f"{self.get_parameter('text').value}: {self.count}")
        self.get_logger().info(f'Publishing: "{msg.data}"')
        self.pub.publish(msg)


class Listener(Node):
    """Logs what arrives on ``chatter``."""

    default_node_name = "listener"

    def __init__(self, node_name: str = default_node_name, **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        self.received: list[str] = []
        self.create_subscription(String, "chatter", self._on_msg, 10)

    def _on_msg(self, msg: Any) -> None:
        self.received.append(msg.data)
        self.get_logger().info(f'I heard: "{msg.data}"')
