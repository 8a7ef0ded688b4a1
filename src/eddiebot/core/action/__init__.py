"""Actions (goal, feedback, result, cancel) with rclpy's API, laid out on the wire as ROS 2.

An action ``<name>`` is three services and two topics, exactly as rcl_action names them,
so a server and a client in different processes meet through any transport that carries
services and topics:

- ``<name>/_action/send_goal``   (``X_SendGoal``): goal id + goal → accepted, stamp;
- ``<name>/_action/cancel_goal`` (action_msgs/srv/CancelGoal);
- ``<name>/_action/get_result``  (``X_GetResult``): answered when the goal ends;
- ``<name>/_action/feedback``    (``X_FeedbackMessage``);
- ``<name>/_action/status``      (action_msgs/msg/GoalStatusArray, transient-local).

``execute_callback(goal_handle)`` may be a plain function or an ``async def`` coroutine.
A coroutine runs as a task on the node's executor: ``await future`` suspends it and
``await sleep(node, seconds)`` waits on the node clock, so a long-running server shares a
single-threaded executor with everything else and, on sim time, ten simulated seconds of
work take no wall time.
"""

from eddiebot.core.action._common import (
    FEEDBACK_QOS,
    STATUS_QOS,
    ActionStateError,
    CancelResponse,
    GoalResponse,
    GoalStatus,
)
from eddiebot.core.action._deferred import _create_deferred_service as _create_deferred_service
from eddiebot.core.action._tasks import sleep
from eddiebot.core.action.client import ActionClient, ClientGoalHandle
from eddiebot.core.action.server import ActionServer, ServerGoalHandle

__all__ = [
    "FEEDBACK_QOS",
    "STATUS_QOS",
    "ActionClient",
    "ActionServer",
    "ActionStateError",
    "CancelResponse",
    "ClientGoalHandle",
    "GoalResponse",
    "GoalStatus",
    "ServerGoalHandle",
    "sleep",
]
