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

from __future__ import annotations

import enum
import inspect
import os
from collections.abc import Callable, Coroutine
from typing import TYPE_CHECKING, Any

import numpy as np

from eddiebot.core.node import CallbackGroup, Service
from eddiebot.core.qos import DurabilityPolicy, QoSProfile
from eddiebot.core.task import Future, Task
from eddiebot.core.time import NS_PER_S, stamp_to_ns

if TYPE_CHECKING:
    from eddiebot.core.node import Node
    from eddiebot.msgs import ActionType

__all__ = [
    "ActionClient",
    "ActionServer",
    "CancelResponse",
    "ClientGoalHandle",
    "GoalResponse",
    "GoalStatus",
    "ServerGoalHandle",
    "sleep",
]

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


class _Step:
    """Executor work item: one step of a task, or one call."""

    __slots__ = ("callback_group", "fn", "node")

    def __init__(self, node: Node, fn: Callable[[], Any]) -> None:
        self.node = node
        self.fn = fn
        self.callback_group = None

    def execute(self) -> None:
        self.fn()


def _run_as_task(node: Node, coro: Coroutine[Any, Any, Any]) -> Task:
    """Drive ``coro`` on whatever executor ``node`` is (or will be) added to."""

    def reschedule(task: Task) -> None:
        node._notify(_Step(node, task.step))

    task = Task(coro, reschedule)
    reschedule(task)
    return task


async def sleep(node: Node, seconds: float) -> None:
    """Wait ``seconds`` on ``node``'s clock (sim or wall) inside a coroutine callback."""
    if seconds <= 0:
        return
    done = Future()
    timers: list[Any] = []

    def fire() -> None:
        node.destroy_timer(timers[0])
        done.set_result(None)

    timers.append(node.create_timer(seconds, fire, oneshot=True))
    await done


class _DeferredService(Service):
    """A service whose responder may answer later: ``responder(request, done)``."""

    def __init__(
        self,
        node: Node,
        srv_type: Any,
        name: str,
        responder: Callable[[Any, Callable[[Any, BaseException | None], None]], None],
        group: CallbackGroup,
    ) -> None:
        super().__init__(node, srv_type, name, self._no_sync, group)
        self._responder = responder

    def _no_sync(self, request: Any, response: Any) -> Any:
        raise RuntimeError(f"service {self.srv_name!r} answers asynchronously")

    def handle(self, request: Any) -> Any:
        box: list[tuple[Any, BaseException | None]] = []
        self.handle_async(request, lambda r, e: box.append((r, e)))
        if not box:
            raise RuntimeError(f"service {self.srv_name!r} cannot answer yet; use handle_async")
        response, error = box[0]
        if error is not None:
            raise error
        return response

    def handle_async(self, request: Any, done: Callable[[Any, BaseException | None], None]) -> None:
        if getattr(request, "__msgtype__", None) != self.srv_type.Request.__msgtype__:
            done(None, TypeError(f"service {self.srv_name!r} takes {self.srv_type.Request.__msgtype__}"))
            return
        try:
            self._responder(request, done)
        except Exception as exc:
            self.log_failure(exc)
            done(None, exc)

    def execute(self) -> None:
        with self._lock:
            if not self._queue:
                return
            request, done = self._queue.popleft()
        self.handle_async(request, done)


def _create_deferred_service(node: Node, srv_type: Any, name: str, responder: Any,
                             group: CallbackGroup | None) -> Service:
    srv = _DeferredService(node, srv_type, node.resolve_service_name(name), responder,
                           group or node._default_group)
    node.context.add_service(srv)
    node.services.append(srv)
    return srv


# -- server ---------------------------------------------------------------------------------
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


# -- client -----------------------------------------------------------------------------------
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

