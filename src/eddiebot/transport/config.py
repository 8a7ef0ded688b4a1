"""Where processes meet: the router endpoint, loopback or LAN, and the Zenoh configs built from it.

Environment (all optional):

- ``EDDIE_TRANSPORT=none`` — no inter-process transport at all (``connect`` returns None);
- ``EDDIE_ZENOH_ROUTER`` — the router endpoint (default ``tcp/127.0.0.1:7447``; a bare port
  number means ``tcp/127.0.0.1:<port>``);
- ``EDDIE_NETWORK=lan`` — open to the LAN: the router listens on every interface and
  routers/peers find each other by UDP multicast scouting (default ``loopback``: loopback
  only, scouting off);
- ``EDDIE_ZENOH_CONNECT`` — extra endpoints to connect to, comma separated (another
  machine's router when multicast does not cross the network, e.g. ``tcp/192.168.1.20:7447``);
- ``EDDIE_ZENOH_CONFIG`` — a Zenoh JSON5 config file for sessions, used as is (then the
  settings above are not applied);
- ``EDDIE_ZENOH_ROUTER_CONFIG`` — the same for the router (``eddie daemon``);
- ``EDDIE_ROUTER_AUTOSTART=0`` — do not start a detached router when none is reachable;
- ``EDDIE_ZENOH_MODE`` — ``peer`` (default) or ``client`` (only a link to the router);
- ``EDDIE_ZENOH_CLOSE_TIMEOUT`` — seconds ``close`` waits for the session to shut down
  (default: as long as it takes; the ``eddie`` CLI sets 0.5).
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from typing import Any

__all__ = ["DEFAULT_ROUTER", "ZenohConfig", "normalize_endpoint"]

DEFAULT_ROUTER = "tcp/127.0.0.1:7447"


def normalize_endpoint(text: str) -> str:
    """``17447`` → ``tcp/127.0.0.1:17447``; ``host:port`` → ``tcp/host:port``."""
    text = text.strip()
    if text.isdigit():
        return f"tcp/127.0.0.1:{text}"
    if "/" not in text:
        return f"tcp/{text}"
    return text


def _seconds(env: Any, key: str) -> float | None:
    text = (env.get(key) or "").strip()
    if not text:
        return None
    try:
        value = float(text)
    except ValueError:
        raise ValueError(f"{key} must be a number of seconds, got {text!r}") from None
    return max(0.0, value)


@dataclass
class ZenohConfig:
    """How a process joins the graph (see the module docstring for the environment)."""

    router: str = DEFAULT_ROUTER
    network: str = "loopback"  # or "lan"
    connect: list[str] = field(default_factory=list)
    config_file: str | None = None
    router_config_file: str | None = None
    autostart_router: bool = True
    mode: str = "peer"
    #: Remote service calls give up after this (action results: ``result_timeout_s``).
    service_timeout_s: float = 60.0
    result_timeout_s: float = 24 * 3600.0
    #: How long a new session waits to link up with the router before going on without.
    router_wait_s: float = 2.0
    #: How long ``close`` waits for the session to shut down; None: as long as it takes.
    #: Closing waits for links still being opened, up to Zenoh's 10 s handshake timeout
    #: when a peer in the graph does not answer (a stopped or stalled process).
    close_timeout_s: float | None = None

    @classmethod
    def from_env(cls, env: dict[str, str] | None = None) -> ZenohConfig:
        e = os.environ if env is None else env
        network = e.get("EDDIE_NETWORK", "loopback").strip().lower() or "loopback"
        if network not in ("loopback", "lan"):
            raise ValueError(f"EDDIE_NETWORK must be 'loopback' or 'lan', got {network!r}")
        return cls(
            router=normalize_endpoint(e.get("EDDIE_ZENOH_ROUTER", DEFAULT_ROUTER) or DEFAULT_ROUTER),
            network=network,
            connect=[normalize_endpoint(x) for x in e.get("EDDIE_ZENOH_CONNECT", "").split(",")
                     if x.strip()],
            config_file=e.get("EDDIE_ZENOH_CONFIG") or None,
            router_config_file=e.get("EDDIE_ZENOH_ROUTER_CONFIG") or None,
            autostart_router=e.get("EDDIE_ROUTER_AUTOSTART", "1").strip().lower()
            not in ("0", "false", "no", "off"),
            mode=e.get("EDDIE_ZENOH_MODE", "peer"),
            close_timeout_s=_seconds(e, "EDDIE_ZENOH_CLOSE_TIMEOUT"),
        )

    @property
    def lan(self) -> bool:
        return self.network == "lan"

    def router_host_port(self) -> tuple[str, int] | None:
        """(host, port) of a ``tcp/`` router endpoint, else None."""
        if not self.router.startswith("tcp/"):
            return None
        hostport = self.router[4:].split("#", 1)[0]
        host, _, port = hostport.rpartition(":")
        try:
            return host.strip("[]") or "127.0.0.1", int(port)
        except ValueError:
            return None

    # -- zenoh configs ---------------------------------------------------------------
    def session_settings(self) -> dict[str, Any]:
        """Settings of a process's session: a peer that meets the others at the router."""
        listen = "tcp/0.0.0.0:0" if self.lan else "tcp/127.0.0.1:0"
        return {
            "mode": self.mode,
            "connect/endpoints": [self.router, *self.connect],
            "listen/endpoints": [listen] if self.mode == "peer" else [],
            "scouting/multicast/enabled": self.lan,
            "scouting/gossip/enabled": True,
            "timestamping/enabled": True,
        }

    def router_settings(self) -> dict[str, Any]:
        hp = self.router_host_port()
        port = hp[1] if hp else 7447
        listen = f"tcp/[::]:{port}" if self.lan else (self.router if hp else f"tcp/127.0.0.1:{port}")
        settings: dict[str, Any] = {
            "mode": "router",
            "listen/endpoints": [listen],
            "connect/endpoints": list(self.connect),
            "scouting/multicast/enabled": self.lan,
            "scouting/gossip/enabled": True,
            "timestamping/enabled": True,
        }
        if self.lan:
            # routers of two machines find and join each other
            settings["scouting/multicast/autoconnect"] = {"router": ["router", "peer"],
                                                          "peer": ["router", "peer"]}
        return settings

    def _build(self, settings: dict[str, Any], file: str | None) -> Any:
        import zenoh

        if file:
            return zenoh.Config.from_file(file)
        cfg = zenoh.Config()
        for k, v in settings.items():
            cfg.insert_json5(k, json.dumps(v))
        return cfg

    def session_config(self) -> Any:
        """A ``zenoh.Config`` for a process's session."""
        return self._build(self.session_settings(), self.config_file)

    def router_config(self) -> Any:
        """A ``zenoh.Config`` for the router (``eddie daemon``)."""
        return self._build(self.router_settings(), self.router_config_file)
