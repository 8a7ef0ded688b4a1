"""The bond heartbeats of nav2_util and bondcpp: what a managed node and its manager publish
on ``bond`` so either side sees the other stop."""

from __future__ import annotations

from typing import Any

#: nav2_util's LifecycleNode: setHeartbeatTimeout(4.0); nav2's manager beats every 0.1 s
_NODE_BOND_TIMEOUT_S = 4.0
_MANAGER_BOND_PERIOD_S = 0.1


def _bond_id(node_name: str) -> str:
    """The bond id nav2 uses for a managed node: its name, without namespace."""
    return node_name.rstrip("/").rsplit("/", 1)[-1]


def bond_status(bond_id: str, instance_id: str, active: bool, stamp_ns: int,
                heartbeat_timeout_s: float, heartbeat_period_s: float) -> Any:
    """A ``bond/msg/Status`` heartbeat as bondcpp publishes it."""
    from eddiebot.msgs.bond import Status
    from eddiebot.msgs.builtin_interfaces import Time

    msg = Status(id=bond_id, instance_id=instance_id, active=active,
                 heartbeat_timeout=heartbeat_timeout_s, heartbeat_period=heartbeat_period_s)
    msg.header.stamp = Time(sec=stamp_ns // 1_000_000_000, nanosec=stamp_ns % 1_000_000_000)
    return msg
