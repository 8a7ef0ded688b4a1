"""The server side of an action (rclpy.action.ActionServer): goals accepted or rejected,
executed as plain calls or coroutines, cancelled, their results kept for ``result_timeout``."""

from __future__ import annotations

import inspect
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from eddiebot.core.action._common import (
    _ACTIVE,
    FEEDBACK_QOS,
    STATUS_QOS,
    ActionStateError,
    CancelResponse,
    GoalResponse,
    GoalStatus,
    _action_prefix,
    _uuid_key,
)
from eddiebot.core.action._deferred import _create_deferred_service
from eddiebot.core.action._tasks import _run_as_task, _Step
from eddiebot.core.node import CallbackGroup
from eddiebot.core.time import NS_PER_S, stamp_to_ns

if TYPE_CHECKING:
    from eddiebot.core.node import Node
    from eddiebot.msgs import ActionType

class ServerGoalHandle:
    """One goal on the server side (rclpy.action.server.ServerGoalHandle)."""

    def __init__(self, server: ActionServer, goal_info: Any, request: Any) -> None:
        self._server = server
        self.goal_info = goal_info
        self.request = request
        self.status = GoalStatus.STATUS_ACCEPTED
        self._key = _uuid_key(goal_info.goal_id)

    @property
    def goal_id(self) -> Any:
        """unique_identifier_msgs/UUID of the goal."""
        return self.goal_info.goal_id

    @property
    def is_active(self) -> bool:
        return self.status in _ACTIVE

    @property
    def is_cancel_requested(self) -> bool:
        return self.status == GoalStatus.STATUS_CANCELING

    def _update(self, status: GoalStatus, allowed: tuple[GoalStatus, ...]) -> None:
        if self.status not in allowed:
            raise ActionStateError(
                f"goal {self._key.hex()} of action {self._server.action_name!r} cannot go "
                f"from {self.status.name} to {status.name}"
            )
        self.status = status
        self._server._publish_status()

    def execute(self, execute_callback: Callable[[ServerGoalHandle], Any] | None = None) -> None:
        """Start executing (what the default ``handle_accepted_callback`` does)."""
        self._server._execute(self, execute_callback or self._server.execute_callback)

    def publish_feedback(self, feedback: Any) -> None:
        """Send an ``X_Feedback`` message to the clients."""
        if not self.is_active:
            raise ActionStateError(f"feedback for goal {self._key.hex()} after it finished")
        self._server._publish_feedback(self, feedback)

    def succeed(self) -> None:
        self._update(GoalStatus.STATUS_SUCCEEDED, _ACTIVE)

    def abort(self) -> None:
        self._update(GoalStatus.STATUS_ABORTED, _ACTIVE)

    def canceled(self) -> None:
        self._update(GoalStatus.STATUS_CANCELED, (GoalStatus.STATUS_CANCELING,))

    def __repr__(self) -> str:
        return f"<ServerGoalHandle {self._key.hex()[:8]} {self.status.name}>"


def _accept_all(_goal: Any) -> GoalResponse:
    return GoalResponse.ACCEPT


def _reject_cancel(_handle: ServerGoalHandle) -> CancelResponse:
    return CancelResponse.REJECT


class ActionServer:
    """Serves one action (rclpy.action.ActionServer).

    ``goal_callback(goal) -> GoalResponse`` (default: accept), ``cancel_callback(handle) ->
    CancelResponse`` (default: reject, as rclpy), ``handle_accepted_callback(handle)``
    (default: ``handle.execute()``), ``execute_callback(handle) -> Result`` (function or
    coroutine; it calls ``handle.succeed()``/``abort()``/``canceled()``, else the goal is
    aborted). Results are kept ``result_timeout`` seconds of node time after the goal ends.
    """

    def __init__(
        self,
        node: Node,
        action_type: ActionType,
        action_name: str,
        execute_callback: Callable[[ServerGoalHandle], Any],
        *,
        callback_group: CallbackGroup | None = None,
        goal_callback: Callable[[Any], GoalResponse] | None = None,
        cancel_callback: Callable[[ServerGoalHandle], CancelResponse] | None = None,
        handle_accepted_callback: Callable[[ServerGoalHandle], None] | None = None,
        result_timeout: float = 900.0,
    ) -> None:
        from eddiebot.msgs import get_service
        from eddiebot.msgs.action_msgs import GoalStatusArray

        self.node = node
        self.action_type = action_type
        self.action_name = node.resolve_topic_name(action_name)
        self.execute_callback = execute_callback
        self.goal_callback = goal_callback or _accept_all
        self.cancel_callback = cancel_callback or _reject_cancel
        self.handle_accepted_callback = handle_accepted_callback
        self.result_timeout_ns = round(result_timeout * NS_PER_S)
        self._goals: dict[bytes, ServerGoalHandle] = {}
        self._results: dict[bytes, Any] = {}
        self._expires: dict[bytes, int] = {}
        self._waiting: dict[bytes, list[Callable[[Any, BaseException | None], None]]] = {}
        prefix = _action_prefix(node, action_name)
        self._send_goal_srv = node.create_service(
            action_type.SendGoal, f"{prefix}/send_goal", self._on_send_goal,
            callback_group=callback_group)
        self._cancel_srv = node.create_service(
            get_service("action_msgs/srv/CancelGoal"), f"{prefix}/cancel_goal", self._on_cancel,
            callback_group=callback_group)
        self._result_srv = _create_deferred_service(
            node, action_type.GetResult, f"{prefix}/get_result", self._on_get_result,
            callback_group)
        self._feedback_pub = node.create_publisher(
            action_type.FeedbackMessage, f"{prefix}/feedback", FEEDBACK_QOS)
        self._status_pub = node.create_publisher(GoalStatusArray, f"{prefix}/status", STATUS_QOS)
        self._status_array = GoalStatusArray

    # -- service handlers ---------------------------------------------------------------
    def _on_send_goal(self, request: Any, response: Any) -> Any:
        from eddiebot.msgs.action_msgs import GoalInfo

        self._expire_results()
        key = _uuid_key(request.goal_id)
        if key in self._goals:
            self.node.get_logger().error(f"action {self.action_name!r}: goal id {key.hex()} reused")
            response.accepted = False
            return response
        try:
            verdict = self.goal_callback(request.goal)
        except Exception as exc:
            self.node.get_logger().error(f"action {self.action_name!r} goal_callback raised {exc!r}")
            verdict = GoalResponse.REJECT
        now = self.node.now()
        response.stamp = now.to_msg()
        if verdict != GoalResponse.ACCEPT:
            response.accepted = False
            return response
        response.accepted = True
        handle = ServerGoalHandle(self, GoalInfo(goal_id=request.goal_id, stamp=now.to_msg()),
                                  request.goal)
        self._goals[key] = handle
        self._publish_status()
        # Start after the response went out, as rclpy.
        accepted = self.handle_accepted_callback or ServerGoalHandle.execute
        self.node._notify(_Step(self.node, lambda: self._call_accepted(accepted, handle)))
        return response

    def _call_accepted(self, accepted: Callable[[ServerGoalHandle], Any], handle: ServerGoalHandle) -> None:
        try:
            result = accepted(handle)
            if inspect.iscoroutine(result):
                _run_as_task(self.node, result)
        except Exception as exc:
            self.node.get_logger().error(
                f"action {self.action_name!r} handle_accepted_callback raised {exc!r}")

    def _on_cancel(self, request: Any, response: Any) -> Any:
        from eddiebot.msgs.action_msgs import CancelGoal

        codes = CancelGoal.Response
        key = _uuid_key(request.goal_info.goal_id)
        stamp = stamp_to_ns(request.goal_info.stamp)
        any_id = not any(key)
        candidates: list[ServerGoalHandle] = []
        if not any_id:
            handle = self._goals.get(key)
            if handle is None and stamp == 0:
                response.return_code = codes.ERROR_UNKNOWN_GOAL_ID
                return response
            if handle is not None:
                candidates.append(handle)
        if any_id or stamp != 0:
            for h in self._goals.values():
                if h not in candidates and (stamp == 0 or stamp_to_ns(h.goal_info.stamp) <= stamp):
                    candidates.append(h)
        canceling = []
        for h in candidates:
            if not h.is_active:
                continue
            if h.status != GoalStatus.STATUS_CANCELING:
                try:
                    verdict = self.cancel_callback(h)
                except Exception as exc:
                    self.node.get_logger().error(
                        f"action {self.action_name!r} cancel_callback raised {exc!r}")
                    verdict = CancelResponse.REJECT
                if verdict != CancelResponse.ACCEPT:
                    continue
                h._update(GoalStatus.STATUS_CANCELING, _ACTIVE)
            canceling.append(h.goal_info)
        response.goals_canceling = canceling
        if canceling:
            response.return_code = codes.ERROR_NONE
        elif candidates and not any(h.is_active for h in candidates):
            response.return_code = codes.ERROR_GOAL_TERMINATED
        else:
            response.return_code = codes.ERROR_REJECTED
        return response

    def _on_get_result(self, request: Any, done: Callable[[Any, BaseException | None], None]) -> None:
        self._expire_results()
        key = _uuid_key(request.goal_id)
        if key in self._results:
            done(self._results[key], None)
        elif key in self._goals:
            self._waiting.setdefault(key, []).append(done)
        else:
            done(self.action_type.GetResult.Response(status=int(GoalStatus.STATUS_UNKNOWN)), None)

    # -- execution ----------------------------------------------------------------------
    def _execute(self, handle: ServerGoalHandle, callback: Callable[[ServerGoalHandle], Any]) -> None:
        if handle.status == GoalStatus.STATUS_ACCEPTED:
            handle._update(GoalStatus.STATUS_EXECUTING, (GoalStatus.STATUS_ACCEPTED,))
        _run_as_task(self.node, self._run(handle, callback))

    async def _run(self, handle: ServerGoalHandle, callback: Callable[[ServerGoalHandle], Any]) -> None:
        log = self.node.get_logger()
        result: Any = None
        try:
            result = callback(handle)
            if inspect.isawaitable(result):
                result = await result
        except Exception as exc:
            log.error(f"action {self.action_name!r} execute callback raised "
                      f"{type(exc).__name__}: {exc}")
            result = None
            if handle.is_active:
                handle.abort()
        if handle.is_active:
            log.warning(f"action {self.action_name!r}: goal state not set by the execute "
                        f"callback, assuming aborted")
            handle.abort()
        if result is None:
            result = self.action_type.Result()
        self._finish(handle, result)

    def _finish(self, handle: ServerGoalHandle, result: Any) -> None:
        response = self.action_type.GetResult.Response(status=int(handle.status), result=result)
        key = handle._key
        self._results[key] = response
        self._expires[key] = self.node.now().nanoseconds + self.result_timeout_ns
        for done in self._waiting.pop(key, []):
            done(response, None)
        self._expire_results()

    def _expire_results(self) -> None:
        if not self._expires:
            return
        now = self.node.now().nanoseconds
        gone = [k for k, t in self._expires.items() if t <= now]
        for k in gone:
            del self._expires[k]
            self._results.pop(k, None)
            self._goals.pop(k, None)
        if gone:
            self._publish_status()

    def _publish_status(self) -> None:
        from eddiebot.msgs.action_msgs import GoalStatus as GoalStatusMsg

        self._status_pub.publish(self._status_array(status_list=[
            GoalStatusMsg(goal_info=h.goal_info, status=int(h.status)) for h in self._goals.values()
        ]))

    def _publish_feedback(self, handle: ServerGoalHandle, feedback: Any) -> None:
        self._feedback_pub.publish(
            self.action_type.FeedbackMessage(goal_id=handle.goal_id, feedback=feedback))

    @property
    def goal_handles(self) -> list[ServerGoalHandle]:
        return list(self._goals.values())

    def destroy(self) -> None:
        for srv in (self._send_goal_srv, self._cancel_srv, self._result_srv):
            self.node.destroy_service(srv)
        self.node.destroy_publisher(self._feedback_pub)
        self.node.destroy_publisher(self._status_pub)
