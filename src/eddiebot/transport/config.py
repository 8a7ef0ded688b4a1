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
- ``ZENOH_SESSION_CONFIG_URI`` (alias ``EDDIE_ZENOH_CONFIG``) — a Zenoh JSON5 config file
  for sessions, used as is (then the settings above are not applied), as rmw_zenoh reads it;
- ``ZENOH_ROUTER_CONFIG_URI`` (alias ``EDDIE_ZENOH_ROUTER_CONFIG``) — the same for the
  router (``eddie daemon``);
- ``ZENOH_CONFIG_OVERRIDE`` — ``key=value`` pairs separated by ``;`` (values in JSON5, e.g.
  ``mode="client";connect/endpoints=["tcp/192.168.1.20:7447"]``), applied last to the
  session and router configs, whether from a file or from the settings above (rmw_zenoh's
  variable, same syntax);
- ``EDDIE_ROUTER_AUTOSTART=0`` — do not start a detached router when none is reachable;
- ``EDDIE_ZENOH_MODE`` — ``peer`` (default) or ``client`` (only a link to the router);
- ``EDDIE_ZENOH_CLOSE_TIMEOUT`` — seconds ``close`` waits for the session to shut down
  (default: as long as it takes; the ``eddie`` CLI sets 0.5).

When a ``ZENOH_*`` variable and its ``EDDIE_*`` alias are both set, the ``ZENOH_*`` one wins
(with a warning if they differ): one shell can then serve ROS 2 on rmw_zenoh and eddiebot.
"""

from __future__ import annotations

import json
import logging
import os
from dataclasses import dataclass, field
from typing import Any

__all__ = ["DEFAULT_ROUTER", "ZenohConfig", "normalize_endpoint", "parse_config_override"]

log = logging.getLogger("eddiebot.transport")

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


def parse_config_override(text: str, source: str = "ZENOH_CONFIG_OVERRIDE") -> list[tuple[str, str]]:
    """``key=value;key=value`` → [(key, JSON5 value)], as rmw_zenoh reads
    ``ZENOH_CONFIG_OVERRIDE``. A ``;`` inside brackets, braces or quotes does not split.
    Raises ``ValueError`` naming the item that is not ``key=value``."""
    items: list[str] = []
    depth, quote, start = 0, "", 0
    for i, ch in enumerate(text):
        if quote:
            if ch == quote and text[i - 1] != "\\":
                quote = ""
        elif ch in "\"'":
            quote = ch
        elif ch in "[{":
            depth += 1
        elif ch in "]}":
            depth -= 1
        elif ch == ";" and depth == 0:
            items.append(text[start:i])
            start = i + 1
    items.append(text[start:])
    pairs: list[tuple[str, str]] = []
    for n, item in enumerate(items, 1):
        if not item.strip():
            continue
        key, eq, value = item.partition("=")
        if not eq or not key.strip() or not value.strip():
            raise ValueError(f"{source}: item {n} ({item.strip()!r}) is not key=value "
                             "(e.g. mode=\"client\";connect/endpoints=[\"tcp/10.0.0.2:7447\"])")
        pairs.append((key.strip().strip("/"), value.strip()))
    return pairs


def _aliased(env: Any, name: str, alias: str) -> str | None:
    """``name`` (rmw_zenoh's variable) or else ``alias`` (ours); ``name`` wins."""
    value = (env.get(name) or "").strip() or None
    other = (env.get(alias) or "").strip() or None
    if value and other and value != other:
        log.warning("%s=%s and %s=%s are both set; using %s", name, value, alias, other, name)
    return value or other


@dataclass
class ZenohConfig:
    """How a process joins the graph (see the module docstring for the environment)."""

    router: str = DEFAULT_ROUTER
    network: str = "loopback"  # or "lan"
    connect: list[str] = field(default_factory=list)
    config_file: str | None = None
    router_config_file: str | None = None
    #: (key, JSON5 value) set last on both configs (``ZENOH_CONFIG_OVERRIDE``)
    overrides: list[tuple[str, str]] = field(default_factory=list)
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
            config_file=_aliased(e, "ZENOH_SESSION_CONFIG_URI", "EDDIE_ZENOH_CONFIG"),
            router_config_file=_aliased(e, "ZENOH_ROUTER_CONFIG_URI", "EDDIE_ZENOH_ROUTER_CONFIG"),
            overrides=parse_config_override(e.get("ZENOH_CONFIG_OVERRIDE", "")),
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

    @property
    def customised(self) -> bool:
        """A config file or overrides decide where this process connects and listens."""
        return self.config_file is not None or bool(self.overrides)

    def _build(self, settings: dict[str, Any], file: str | None, variable: str) -> Any:
        import zenoh

        if file:
            if not os.path.isfile(file):
                raise ValueError(f"{variable}: no Zenoh config file at {file}")
            try:
                cfg = zenoh.Config.from_file(file)
            except Exception as exc:
                raise ValueError(f"{variable}: {file} is not a valid Zenoh config: {exc}") from None
        else:
            cfg = zenoh.Config()
            for k, v in settings.items():
                cfg.insert_json5(k, json.dumps(v))
        for key, value in self.overrides:
            try:
                cfg.insert_json5(key, value)
            except Exception:
                raise ValueError(f"ZENOH_CONFIG_OVERRIDE: cannot set {key} to {value} (no such "
                                 "Zenoh config key, or a value that is not JSON5 of its "
                                 "type)") from None
        return cfg

    def effective_settings(self, router: bool = False) -> dict[str, Any]:
        """The settings a built-in config gets, overrides applied (values decoded when
        they are plain JSON; for reports and tests)."""
        settings = self.router_settings() if router else self.session_settings()
        for key, value in self.overrides:
            try:
                settings[key] = json.loads(value)
            except ValueError:
                settings[key] = value
        return settings

    def session_config(self) -> Any:
        """A ``zenoh.Config`` for a process's session."""
        return self._build(self.session_settings(), self.config_file, "ZENOH_SESSION_CONFIG_URI")

    def router_config(self) -> Any:
        """A ``zenoh.Config`` for the router (``eddie daemon``)."""
        return self._build(self.router_settings(), self.router_config_file,
                           "ZENOH_ROUTER_CONFIG_URI")
