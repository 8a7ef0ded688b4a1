"""The client side of an action (rclpy.action.ActionClient): goals sent, feedback and
status followed, results and cancels as futures."""

from __future__ import annotations

import inspect
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from eddiebot.core.action._common import (
    FEEDBACK_QOS,
    STATUS_QOS,
    GoalStatus,
    _action_prefix,
    _new_uuid,
    _uuid_key,
)
from eddiebot.core.action._tasks import _run_as_task
from eddiebot.core.node import CallbackGroup
from eddiebot.core.task import Future

if TYPE_CHECKING:
    from eddiebot.core.node import Node
    from eddiebot.msgs import ActionType

class ClientGoalHandle:
    """A goal sent by an ``ActionClient`` (rclpy.action.client.ClientGoalHandle)."""

    def __init__(self, client: ActionClient, goal_id: Any, response: Any) -> None:
        self._client = client
        self.goal_id = goal_id
        self.stamp = response.stamp
        self.accepted = bool(response.accepted)
        self.status = GoalStatus.STATUS_ACCEPTED if self.accepted else GoalStatus.STATUS_UNKNOWN
        self._result_future: Future | None = None

    def get_result_async(self) -> Future:
        """Future of the ``X_GetResult`` response (``.status``, ``.result``)."""
        if self._result_future is None:
            self._result_future = self._client._get_result_async(self)
        return self._result_future

    def cancel_goal_async(self) -> Future:
        """Future of the action_msgs/CancelGoal response."""
        return self._client._cancel_goal_async(self)

    def __repr__(self) -> str:
        return f"<ClientGoalHandle {_uuid_key(self.goal_id).hex()[:8]} {self.status.name}>"


class ActionClient:
    """Sends goals to an action server (rclpy.action.ActionClient)."""

    def __init__(
        self,
        node: Node,
        action_type: ActionType,
        action_name: str,
        *,
        callback_group: CallbackGroup | None = None,
    ) -> None:
        from eddiebot.msgs import get_service
        from eddiebot.msgs.action_msgs import GoalStatusArray

        self.node = node
        self.action_type = action_type
        self.action_name = node.resolve_topic_name(action_name)
        prefix = _action_prefix(node, action_name)
        self._send_goal = node.create_client(action_type.SendGoal, f"{prefix}/send_goal",
                                             callback_group=callback_group)
        self._cancel = node.create_client(get_service("action_msgs/srv/CancelGoal"),
                                          f"{prefix}/cancel_goal", callback_group=callback_group)
        self._get_result = node.create_client(action_type.GetResult, f"{prefix}/get_result",
                                              callback_group=callback_group)
        self._feedback_sub = node.create_subscription(
            action_type.FeedbackMessage, f"{prefix}/feedback", self._on_feedback, FEEDBACK_QOS,
            callback_group=callback_group)
        self._status_sub = node.create_subscription(
            GoalStatusArray, f"{prefix}/status", self._on_status, STATUS_QOS,
            callback_group=callback_group)
        self._handles: dict[bytes, ClientGoalHandle] = {}
        self._feedback_callbacks: dict[bytes, Callable[[Any], Any]] = {}

    def server_is_ready(self) -> bool:
        return all(c.service_is_ready() for c in (self._send_goal, self._cancel, self._get_result))

    def wait_for_server(self, timeout_sec: float | None = None) -> bool:
        """Wait (wall time) until the server's services exist; True if they do."""
        return all(c.wait_for_service(timeout_sec)
                   for c in (self._send_goal, self._cancel, self._get_result))

    def send_goal_async(
        self,
        goal: Any,
        feedback_callback: Callable[[Any], Any] | None = None,
        goal_uuid: Any = None,
    ) -> Future:
        """Future of a ``ClientGoalHandle`` (check ``.accepted``). ``feedback_callback``
        receives ``X_FeedbackMessage`` (``.feedback`` holds the feedback)."""
        goal_id = goal_uuid if goal_uuid is not None else _new_uuid()
        key = _uuid_key(goal_id)
        if feedback_callback is not None:
            self._feedback_callbacks[key] = feedback_callback
        future = Future()
        request = self.action_type.SendGoal.Request(goal_id=goal_id, goal=goal)

        def on_response(call: Future) -> None:
            error = call.exception()
            if error is not None:
                self._feedback_callbacks.pop(key, None)
                future.set_exception(error)
                return
            handle = ClientGoalHandle(self, goal_id, call.result())
            if handle.accepted:
                self._handles[key] = handle
            else:
                self._feedback_callbacks.pop(key, None)
            future.set_result(handle)

        self._send_goal.call_async(request).add_done_callback(on_response)
        return future

    def send_goal(self, goal: Any, feedback_callback: Callable[[Any], Any] | None = None,
                  timeout_sec: float | None = None) -> Any:
        """Send ``goal`` and block until its result; the ``X_GetResult`` response, or None
        if the goal was rejected. Spins the node's executor when nobody else does."""
        handle = self._wait(self.send_goal_async(goal, feedback_callback), timeout_sec)
        if not handle.accepted:
            return None
        return self._wait(handle.get_result_async(), timeout_sec)

    def _wait(self, future: Future, timeout_sec: float | None) -> Any:
        executor = self.node.executor
        if not future.done():
            if executor is not None and (executor.is_current_thread_spinning()
                                         or not executor.is_spinning()):
                executor.spin_until_future_complete(future, timeout_sec=timeout_sec)
            else:
                future.wait(timeout_sec)
        if not future.done():
            raise TimeoutError(f"action {self.action_name!r} did not answer within {timeout_sec} s")
        return future.result()

    def _get_result_async(self, handle: ClientGoalHandle) -> Future:
        key = _uuid_key(handle.goal_id)
        future = Future()

        def on_response(call: Future) -> None:
            # Feedback published before the result is still queued: deliver it first.
            while (queued := self._feedback_sub.take()) is not None:
                self._on_feedback(queued)
            self._feedback_callbacks.pop(key, None)
            self._handles.pop(key, None)
            error = call.exception()
            if error is not None:
                future.set_exception(error)
                return
            response = call.result()
            handle.status = GoalStatus(int(response.status))
            future.set_result(response)

        self._get_result.call_async(
            self.action_type.GetResult.Request(goal_id=handle.goal_id)
        ).add_done_callback(on_response)
        return future

    def _cancel_goal_async(self, handle: ClientGoalHandle) -> Future:
        from eddiebot.msgs.action_msgs import CancelGoal, GoalInfo

        return self._cancel.call_async(
            CancelGoal.Request(goal_info=GoalInfo(goal_id=handle.goal_id)))

    def cancel_all_goals_async(self) -> Future:
        """Ask the server to cancel every goal (a zero goal id and stamp)."""
        from eddiebot.msgs.action_msgs import CancelGoal

        return self._cancel.call_async(CancelGoal.Request())

    def _on_feedback(self, msg: Any) -> None:
        callback = self._feedback_callbacks.get(_uuid_key(msg.goal_id))
        if callback is not None:
            result = callback(msg)
            if inspect.iscoroutine(result):
                _run_as_task(self.node, result)

    def _on_status(self, msg: Any) -> None:
        for s in msg.status_list:
            handle = self._handles.get(_uuid_key(s.goal_info.goal_id))
            if handle is not None:
                handle.status = GoalStatus(int(s.status))

    def destroy(self) -> None:
        for c in (self._send_goal, self._cancel, self._get_result):
            self.node.destroy_client(c)
        self.node.destroy_subscription(self._feedback_sub)
        self.node.destroy_subscription(self._status_sub)
