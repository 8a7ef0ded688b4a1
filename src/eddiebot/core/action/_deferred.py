"""A service that may answer later: the action server's ``get_result`` is answered when the
goal ends, not when the request arrives."""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from eddiebot.core.node import CallbackGroup, Service

if TYPE_CHECKING:
    from eddiebot.core.node import Node

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
