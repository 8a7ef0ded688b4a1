"""tf2_ros's plumbing: the listener filling a buffer from ``/tf`` and ``/tf_static``, the
broadcasters, and TransformStamped messages built from numbers."""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import TYPE_CHECKING, Any

from eddiebot.core.qos import DurabilityPolicy, QoSProfile
from eddiebot.core.tf._cache import _strip
from eddiebot.core.tf.buffer import Buffer
from eddiebot.core.time import ns_to_stamp

if TYPE_CHECKING:
    from eddiebot.core.node import Node

#: /tf and /tf_static QoS as tf2_ros: depth 100, static ones transient-local.
TF_QOS = QoSProfile(depth=100)
TF_STATIC_QOS = QoSProfile(depth=100, durability=DurabilityPolicy.TRANSIENT_LOCAL)
TF_STATIC_BROADCASTER_QOS = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)


class TransformListener:
    """Fills a ``Buffer`` from ``/tf`` and ``/tf_static`` (tf2_ros.TransformListener)."""

    def __init__(
        self,
        buffer: Buffer,
        node: Node,
        *,
        qos: QoSProfile | int = TF_QOS,
        static_qos: QoSProfile | int = TF_STATIC_QOS,
        spin_thread: bool = False,
    ) -> None:
        from eddiebot.msgs.tf2_msgs import TFMessage

        del spin_thread  # the node's executor delivers; kept for the tf2_ros signature
        self.buffer = buffer
        self.node = node
        if buffer.node is None:
            buffer.set_node(node)
        self.tf_sub = node.create_subscription(TFMessage, "/tf", self._on_tf, qos)
        self.tf_static_sub = node.create_subscription(
            TFMessage, "/tf_static", self._on_tf_static, static_qos
        )

    def _on_tf(self, msg: Any) -> None:
        for t in msg.transforms:
            self.buffer.set_transform(t, "default_authority")

    def _on_tf_static(self, msg: Any) -> None:
        for t in msg.transforms:
            self.buffer.set_transform_static(t, "default_authority")

    def unregister(self) -> None:
        self.node.destroy_subscription(self.tf_sub)
        self.node.destroy_subscription(self.tf_static_sub)


def _as_list(transform: Any | Iterable[Any]) -> list[Any]:
    if hasattr(transform, "child_frame_id"):
        return [transform]
    return list(transform)


class TransformBroadcaster:
    """Publishes transforms on ``/tf`` (tf2_ros.TransformBroadcaster)."""

    def __init__(self, node: Node, qos: QoSProfile | int = TF_QOS) -> None:
        from eddiebot.msgs.tf2_msgs import TFMessage

        self._msg_type = TFMessage
        self.pub = node.create_publisher(TFMessage, "/tf", qos)

    def sendTransform(self, transform: Any | Iterable[Any]) -> None:
        """Publish one geometry_msgs/TransformStamped or a list of them."""
        self.pub.publish(self._msg_type(transforms=_as_list(transform)))

    send_transform = sendTransform


class StaticTransformBroadcaster:
    """Latches static transforms on ``/tf_static``; every call republishes all frames it
    was given so far in one TFMessage, as tf2_ros does."""

    def __init__(self, node: Node, qos: QoSProfile | int = TF_STATIC_BROADCASTER_QOS) -> None:
        from eddiebot.msgs.tf2_msgs import TFMessage

        self._msg_type = TFMessage
        self._frames: dict[str, Any] = {}
        self.pub = node.create_publisher(TFMessage, "/tf_static", qos)

    def sendTransform(self, transform: Any | Iterable[Any]) -> None:
        for t in _as_list(transform):
            self._frames[_strip(t.child_frame_id)] = t
        self.pub.publish(self._msg_type(transforms=list(self._frames.values())))

    send_transform = sendTransform


def make_transform(
    parent: str, child: str, stamp_ns: int, x: float = 0.0, y: float = 0.0, z: float = 0.0,
    qx: float = 0.0, qy: float = 0.0, qz: float = 0.0, qw: float = 1.0,
) -> Any:
    """A geometry_msgs/TransformStamped from numbers (child pose in the parent frame)."""
    from eddiebot.msgs.geometry_msgs import TransformStamped

    msg = TransformStamped()
    msg.header.stamp = ns_to_stamp(stamp_ns)
    msg.header.frame_id = parent
    msg.child_frame_id = child
    t, r = msg.transform.translation, msg.transform.rotation
    t.x, t.y, t.z = float(x), float(y), float(z)
    r.x, r.y, r.z, r.w = float(qx), float(qy), float(qz), float(qw)
    return msg


def make_transform_2d(parent: str, child: str, stamp_ns: int, x: float, y: float, yaw: float) -> Any:
    """A planar TransformStamped: child at (x, y) with heading ``yaw`` in the parent (m, rad)."""
    return make_transform(parent, child, stamp_ns, x, y, 0.0, 0.0, 0.0,
                          math.sin(yaw / 2.0), math.cos(yaw / 2.0))
