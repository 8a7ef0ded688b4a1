"""Service servers and clients (rclpy's ``Service`` and ``Client``).

A server runs its callback on its node's executor; a callback that raises is logged with
the node and service name and the call fails while the server goes on serving. A client
calls a server in this process directly, or one in another process through a transport.
"""

from __future__ import annotations

import threading
from collections import deque
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from eddiebot.core.callback_groups import CallbackGroup
from eddiebot.core.entities import Entity
from eddiebot.core.errors import (
    ServiceCallTimeoutError,
    ServiceUnavailableError,
    TopicTypeMismatchError,
)
from eddiebot.core.task import Future
from eddiebot.msgs import ServiceType

if TYPE_CHECKING:
    from eddiebot.core.node import Node

__all__ = ["Client", "Service"]


class Service(Entity):
    """Answers requests with ``callback(request, response) -> response``."""

    def __init__(
        self,
        node: Node,
        srv_type: ServiceType,
        name: str,
        callback: Callable[[Any, Any], Any],
        group: CallbackGroup,
    ) -> None:
        self.node = node
        self.srv_type = srv_type
        self.srv_name = name
        self.callback = callback
        self.callback_group = group
        self._queue: deque[tuple[Any, Callable[[Any, BaseException | None], None]]] = deque()
        self._lock = threading.Lock()
        self._destroyed = False

    @property
    def service_name(self) -> str:
        return self.srv_name

    def handle(self, request: Any) -> Any:
        """Run the callback now and return the response (raises what the callback raises)."""
        if getattr(request, "__msgtype__", None) != self.srv_type.Request.__msgtype__:
            raise TopicTypeMismatchError(
                self.srv_name,
                self.srv_type.Request.__msgtype__,
                getattr(request, "__msgtype__", type(request).__name__),
            )
        response = self.callback(request, self.srv_type.Response())
        if response is None:
            raise TypeError(f"service {self.srv_name!r} callback returned None, not a response")
        return response

    def handle_async(self, request: Any, done: Callable[[Any, BaseException | None], None]) -> None:
        """Answer through ``done(response, error)``; a subclass may answer later (actions).

        A callback that raises is logged with the node and service name and answered with
        the error (our clients raise it at once; a ROS client, which has no error reply,
        times out as it would against rclpy); the server goes on serving."""
        try:
            response = self.handle(request)
        except Exception as exc:
            self.log_failure(exc)
            done(None, exc)
            return
        done(response, None)

    def log_failure(self, exc: BaseException) -> None:
        """One log line for a callback that raised: node, service, exception."""
        self.node.get_logger().error(
            f"node {self.node.fully_qualified_name}: service {self.srv_name} callback raised "
            f"{type(exc).__name__}: {exc}; the call fails, the service goes on serving")

    def enqueue(self, request: Any, done: Callable[[Any, BaseException | None], None]) -> None:
        """Queue a request; ``done(response, error)`` is called after the callback ran."""
        with self._lock:
            self._queue.append((request, done))
        self._notify()

    def execute(self) -> None:
        with self._lock:
            if not self._queue:
                return
            request, done = self._queue.popleft()
        self.handle_async(request, done)

    def destroy(self) -> None:
        if not self._destroyed:
            self._destroyed = True
            self.node.context.remove_service(self)


class Client:
    """Calls a service in this process or, through the transport, in another."""

    def __init__(self, node: Node, srv_type: ServiceType, name: str, group: CallbackGroup) -> None:
        self.node = node
        self.srv_type = srv_type
        self.srv_name = name
        self.callback_group = group

    def service_is_ready(self) -> bool:
        if self.srv_name in self.node.context.services:
            return True
        return any(t.service_is_ready(self.srv_name) for t in self.node.context.transports)

    def wait_for_service(self, timeout_sec: float | None = None) -> bool:
        """Wait (wall time) until a server exists; True if it does."""
        import time as _t

        deadline = None if timeout_sec is None else _t.monotonic() + timeout_sec
        while not self.service_is_ready():
            if deadline is not None and _t.monotonic() >= deadline:
                return False
            _t.sleep(0.01)
        return True

    def call_async(self, request: Any) -> Future:
        """Send ``request``; the future completes with the response (or the error)."""
        future = Future()

        def done(response: Any, error: BaseException | None) -> None:
            if error is not None:
                future.set_exception(error)
            else:
                future.set_result(response)
            self.node._future_done(future)

        local = self.node.context.services.get(self.srv_name)
        if local is not None:
            executor = local.node.executor
            if executor is None or not executor.is_spinning() or executor.is_current_thread_spinning():
                # Nobody else will run it (or we would deadlock waiting): answer inline.
                local.handle_async(request, done)
            else:
                local.enqueue(request, done)
            return future
        for t in self.node.context.transports:
            if t.call_service(self.srv_name, self.srv_type, request, done, client=self):
                return future
        future.set_exception(ServiceUnavailableError(f"service {self.srv_name!r} is not available"))
        return future

    def call(self, request: Any, timeout_sec: float | None = 5.0) -> Any:
        """Blocking call; raises ``ServiceUnavailableError`` or ``ServiceCallTimeoutError``."""
        future = self.call_async(request)
        if not future.done():
            executor = self.node.executor
            if executor is not None and executor.is_current_thread_spinning():
                executor.spin_until_future_complete(future, timeout_sec=timeout_sec)
            else:
                future.wait(timeout_sec)
        if not future.done():
            raise ServiceCallTimeoutError(
                f"service {self.srv_name!r} did not answer within {timeout_sec} s"
            )
        return future.result()

    def destroy(self) -> None:
        return None
