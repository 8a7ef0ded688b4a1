"""What Nav2's action and service BT nodes share: the server they talk to, its timeouts,
and how a failure is reported.

Timeouts: a server that is not up fails the node after ``wait_for_service_timeout`` (ms);
an accepted goal's acknowledgement is awaited ``max(server_timeout,
wait_for_service_timeout)`` ms (the servers share the navigator's executor, so an
acknowledgement takes a few callbacks rather than Nav2's ``server_timeout`` of 20 ms).
"""

from __future__ import annotations

from typing import Any, ClassVar

from eddiebot.nav.bt.core import LeafNode, Port, input_port

_STATUS_SUCCEEDED, _STATUS_CANCELED, _STATUS_ABORTED = 4, 5, 6


def _nav2(name: str) -> Any:
    from eddiebot.msgs import nav2_msgs

    return getattr(nav2_msgs, name)


def _duration(seconds: float) -> Any:
    from eddiebot.core.time import Duration

    return Duration.from_seconds(float(seconds)).to_msg()


def _basic(server: bool = True) -> dict[str, Port]:
    name = "server_name" if server else "service_name"
    return {name: input_port(str, description="Action server name" if server else "Service name"),
            "server_timeout": input_port(int, description="Server timeout (ms)")}


class _Remote(LeafNode):
    """What action and service nodes share: server name, timeouts, failure messages."""

    DEFAULT_SERVER: ClassVar[str] = ""
    NAME_PORT: ClassVar[str] = "server_name"

    def server_name(self) -> str:
        return str(self.get_input(self.NAME_PORT) or self.DEFAULT_SERVER)

    def _timeouts_ns(self) -> tuple[int, int]:
        ctx = self.context
        wait = int(getattr(ctx, "wait_for_service_timeout_ms", 1000))
        server = self.get_input("server_timeout")
        server = int(server) if server is not None else int(getattr(ctx, "server_timeout_ms", 20))
        return wait * 1_000_000, max(server, wait) * 1_000_000

    def note_failure(self, msg: str) -> None:
        self.context.last_error_msg = f"{self.name}: {msg}"
        self.context.warn(self.context.last_error_msg)
