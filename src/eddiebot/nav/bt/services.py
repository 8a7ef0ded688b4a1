"""Nav2's service nodes (``BtServiceNode`` and its plugins): one request per run, polled
until its response; each talks to the service named by its ``service_name`` port, or
Nav2's default.
"""

from __future__ import annotations

from typing import Any, ClassVar

from eddiebot.nav.bt.core import Port, Status, input_port
from eddiebot.nav.bt.remote import _basic, _nav2, _Remote

__all__ = [
    "BtServiceNode", "ClearCostmapAroundRobot", "ClearCostmapExceptRegion",
    "ClearEntireCostmap", "IsPathValid", "ReinitializeGlobalLocalization",
]

S, F, R = Status.SUCCESS, Status.FAILURE, Status.RUNNING


class BtServiceNode(_Remote):
    """Nav2's ``BtServiceNode``: one request per run, polled until its response."""

    SERVICE: ClassVar[str] = ""
    NAME_PORT = "service_name"

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self._future: Any = None
        self._client: Any = None
        self._since = 0
        if getattr(self.context, "node", None) is not None:
            self._client = self.context.service_client(self.srv_type(), self.server_name())

    def srv_type(self) -> Any:
        return _nav2(self.SERVICE)

    def make_request(self) -> Any:
        return self.srv_type().Request()

    def on_completion(self, response: Any) -> Status:
        return S

    def tick(self) -> Status:
        ctx = self.context
        now = ctx.now_ns()
        if self.status != R:
            self._client = ctx.service_client(self.srv_type(), self.server_name())
            if self._client is None:
                self.note_failure("no node to reach the service")
                return F
            self._future = None
            self._since = now
        wait_ns, ack_ns = self._timeouts_ns()
        if self._future is None:
            if not self._client.service_is_ready():
                if now - self._since > wait_ns:
                    self.note_failure(f"service {self.server_name()} not available")
                    return F
                return R
            self._future = self._client.call_async(self.make_request())
            self._since = now
        if not self._future.done():
            if now - self._since > ack_ns:
                self.note_failure(f"service {self.server_name()} timed out")
                self._future = None
                return F
            return R
        future, self._future = self._future, None
        if future.exception() is not None:
            self.note_failure(str(future.exception()))
            return F
        return self.on_completion(future.result())

    def halt(self) -> None:
        self._future = None


class ReinitializeGlobalLocalization(BtServiceNode):
    """Calls AMCL's ``reinitialize_global_localization`` (std_srvs/Empty)."""

    DEFAULT_SERVER = "reinitialize_global_localization"
    PORTS: ClassVar[dict[str, Port]] = _basic(server=False)

    def srv_type(self) -> Any:
        from eddiebot.msgs.std_srvs import Empty

        return Empty


class ClearEntireCostmap(BtServiceNode):
    SERVICE = "ClearEntireCostmap"
    PORTS: ClassVar[dict[str, Port]] = _basic(server=False)


class ClearCostmapAroundRobot(BtServiceNode):
    SERVICE = "ClearCostmapAroundRobot"
    PORTS: ClassVar[dict[str, Port]] = {
        **_basic(server=False),
        "reset_distance": input_port(float, 1.0, "Distance from the robot under which "
                                     "obstacles are cleared")}

    def make_request(self) -> Any:
        req = super().make_request()
        req.reset_distance = float(self.get_input("reset_distance"))
        return req


class ClearCostmapExceptRegion(ClearCostmapAroundRobot):
    SERVICE = "ClearCostmapExceptRegion"


class IsPathValid(BtServiceNode):
    """SUCCESS when the planner server's ``is_path_valid`` finds ``path`` collision-free;
    FAILURE when it does not, or when the service does not answer."""

    SERVICE = "IsPathValid"
    DEFAULT_SERVER = "is_path_valid"
    PORTS: ClassVar[dict[str, Port]] = {
        "path": input_port(object, description="Path to Check"),
        "server_timeout": input_port(int, description="Server timeout (ms)"),
    }

    def server_name(self) -> str:
        return self.DEFAULT_SERVER

    def note_failure(self, msg: str) -> None:
        self.context.warn(f"{self.name}: {msg}")

    def make_request(self) -> Any:
        req = super().make_request()
        path = self.get_input("path")
        if path is not None:
            req.path = path
        return req

    def on_completion(self, response: Any) -> Status:
        return S if bool(response.is_valid) else F
