"""What the action server and client share: the goal responses and states of rclpy and
action_msgs, the QoS of the status and feedback topics, goal ids and the wire prefix."""

from __future__ import annotations

import enum
import os
from typing import TYPE_CHECKING, Any

import numpy as np

from eddiebot.core.qos import DurabilityPolicy, QoSProfile

if TYPE_CHECKING:
    from eddiebot.core.node import Node

#: rcl_action's status topic QoS: the latest status array reaches late joiners.
STATUS_QOS = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
FEEDBACK_QOS = QoSProfile(depth=10)


class GoalResponse(enum.IntEnum):
    """What ``goal_callback`` answers (rclpy.action.GoalResponse)."""

    REJECT = 1
    ACCEPT = 2


class CancelResponse(enum.IntEnum):
    """What ``cancel_callback`` answers (rclpy.action.CancelResponse)."""

    REJECT = 1
    ACCEPT = 2


class GoalStatus(enum.IntEnum):
    """action_msgs/GoalStatus values."""

    STATUS_UNKNOWN = 0
    STATUS_ACCEPTED = 1
    STATUS_EXECUTING = 2
    STATUS_CANCELING = 3
    STATUS_SUCCEEDED = 4
    STATUS_CANCELED = 5
    STATUS_ABORTED = 6


_ACTIVE = (GoalStatus.STATUS_ACCEPTED, GoalStatus.STATUS_EXECUTING, GoalStatus.STATUS_CANCELING)


class ActionStateError(RuntimeError):
    """A goal-state transition that action_msgs' state machine does not allow."""


def _uuid_key(uuid_msg: Any) -> bytes:
    return bytes(np.asarray(uuid_msg.uuid, dtype=np.uint8).tobytes())


def _new_uuid() -> Any:
    from eddiebot.msgs.unique_identifier_msgs import UUID

    return UUID(uuid=np.frombuffer(os.urandom(16), dtype=np.uint8).copy())


def _action_prefix(node: Node, name: str) -> str:
    return f"{node.resolve_topic_name(name)}/_action"
