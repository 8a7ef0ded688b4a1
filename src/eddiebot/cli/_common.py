"""Shared helpers of the introspection commands (topic, node, param, service, action).

- :func:`message_from_yaml` — ``"{data: hi}"`` (YAML, as ``ros2 topic pub``) → a message;
- :func:`message_to_yaml` — a message → the YAML text ``ros2 topic echo`` prints;
- :func:`cli_session` — a context with a hidden node, joined to the graph;
- graph queries that merge this process's entities with the remote ones.
"""

from __future__ import annotations

import contextlib
import os
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np
import yaml

from eddiebot.msgs import TYPESTORE, normalize_type_name

__all__ = [
    "CliSession",
    "cli_session",
    "get_field",
    "message_from_yaml",
    "message_to_dict",
    "message_to_yaml",
    "set_fields",
]

_NUMPY = {
    "bool": np.bool_, "byte": np.int8, "char": np.uint8, "int8": np.int8, "uint8": np.uint8,
    "int16": np.int16, "uint16": np.uint16, "int32": np.int32, "uint32": np.uint32,
    "int64": np.int64, "uint64": np.uint64, "float32": np.float32, "float64": np.float64,
}


# -- YAML → message ------------------------------------------------------------------
def message_from_yaml(type_name: str, text: str | None) -> Any:
    """A message of ``type_name`` with the fields given as YAML (``"{data: hi}"``)."""
    from eddiebot.msgs import get_message

    return fill_from_yaml(get_message(type_name)(), text)


def fill_from_yaml(msg: Any, text: str | None) -> Any:
    """Set ``msg``'s fields from YAML text (a mapping); ValueError names what is wrong."""
    try:
        values = yaml.safe_load(text) if text and text.strip() else None
    except yaml.YAMLError as exc:
        raise ValueError(f"malformed YAML {text!r}: {exc}") from exc
    if values is None:
        return msg
    if not isinstance(values, dict):
        raise ValueError(f"the values must be a YAML mapping, got {text!r}")
    set_fields(msg, values)
    return msg


def _fields(type_name: str) -> dict[str, Any]:
    return dict(TYPESTORE.fielddefs[normalize_type_name(type_name)][1])


def set_fields(msg: Any, values: dict[str, Any]) -> None:
    """Set ``msg``'s fields from a dict (nested dicts for nested messages)."""
    from rosbags.interfaces import Nodetype

    fields = _fields(msg.__msgtype__)
    for name, value in values.items():
        if name not in fields:
            raise ValueError(
                f"{msg.__msgtype__} has no field {name!r} (fields: {', '.join(fields)})")
        kind, detail = fields[name]
        current = getattr(msg, name)
        if kind == Nodetype.NAME:
            if not isinstance(value, dict):
                raise ValueError(f"field {name!r} of {msg.__msgtype__} is a {detail}: give a mapping")
            set_fields(current, value)
        elif kind == Nodetype.BASE:
            setattr(msg, name, _convert_base(detail[0], value, name))
        else:
            inner, _size = detail
            seq = value if isinstance(value, list) else [value]
            if inner[0] == Nodetype.BASE and inner[1][0] in _NUMPY:
                setattr(msg, name, np.asarray(seq, dtype=_NUMPY[inner[1][0]]))
            elif inner[0] == Nodetype.NAME:
                from eddiebot.msgs import get_message

                items = []
                for item in seq:
                    m = get_message(inner[1])()
                    set_fields(m, item or {})
                    items.append(m)
                setattr(msg, name, items)
            else:
                setattr(msg, name, [str(v) for v in seq])


def _convert_base(typ: str, value: Any, name: str) -> Any:
    if typ in ("string", "wstring"):
        return "" if value is None else str(value)
    if typ == "bool":
        if not isinstance(value, bool):
            raise ValueError(f"field {name!r} is a bool, got {value!r}")
        return value
    if typ.startswith("float"):
        return float(value)
    if isinstance(value, bool) or not isinstance(value, int):
        raise ValueError(f"field {name!r} is an {typ}, got {value!r}")
    return int(value)


# -- message → YAML ------------------------------------------------------------------
def message_to_dict(msg: Any, truncate: int | None = 128, no_arr: bool = False) -> Any:
    """Plain Python data of a message (nested dicts, lists), as ``ros2 topic echo`` shows."""
    if hasattr(msg, "__msgtype__"):
        out = {}
        for name in _fields(msg.__msgtype__):
            out[name] = message_to_dict(getattr(msg, name), truncate, no_arr)
        return out
    if isinstance(msg, np.ndarray):
        if no_arr:
            return f"<array type: {msg.dtype}[{len(msg)}]>"
        values = msg.tolist()
        if truncate is not None and len(values) > truncate:
            return [*values[:truncate], "..."]
        return values
    if isinstance(msg, (list, tuple)):
        if no_arr:
            return f"<sequence length: {len(msg)}>"
        items = [message_to_dict(m, truncate, no_arr) for m in msg]
        if truncate is not None and len(items) > truncate:
            return [*items[:truncate], "..."]
        return items
    if isinstance(msg, np.generic):
        return msg.item()
    if isinstance(msg, str) and truncate is not None and len(msg) > truncate:
        return msg[:truncate] + "..."
    return msg


def get_field(msg: Any, path: str | None) -> Any:
    """``linear.x`` of a message (``--field``)."""
    if not path:
        return msg
    for part in path.split("."):
        if not hasattr(msg, part):
            raise ValueError(f"no field {part!r} in {getattr(msg, '__msgtype__', type(msg).__name__)}")
        msg = getattr(msg, part)
    return msg


def message_to_yaml(msg: Any, *, truncate: int | None = 128, no_arr: bool = False,
                    flow_style: bool = False) -> str:
    """YAML text of a message (or of one field of it)."""
    data = message_to_dict(msg, truncate, no_arr)
    if not isinstance(data, (dict, list)):
        return yaml.safe_dump(data, default_flow_style=flow_style).removesuffix("...\n").rstrip("\n")
    return yaml.safe_dump(data, default_flow_style=flow_style, sort_keys=False,
                          allow_unicode=True).rstrip("\n")


# -- a CLI process in the graph --------------------------------------------------------
@dataclass
class CliSession:
    """A context with one hidden node, linked to the graph."""

    context: Any
    node: Any
    transport: Any

    def remote(self) -> Any:
        """The transport's ``GraphCache`` (None without a transport)."""
        return None if self.transport is None else self.transport.cache

    def wait(self, seconds: float) -> None:
        """Let discovery settle for ``seconds`` of wall time."""
        time.sleep(max(0.0, seconds))

    # merged graph queries (this process's own hidden node excluded)
    def topic_types(self) -> dict[str, set[str]]:
        out: dict[str, set[str]] = {}
        cache = self.remote()
        if cache is not None:
            for name, types in cache.topic_types().items():
                out.setdefault(name, set()).update(types)
        for name, entry in self.context.topics.items():
            ends = [e for e in (*entry.publishers, *entry.subscriptions) if e.node is not self.node]
            if ends and entry.type_name:
                out.setdefault(name, set()).add(entry.type_name)
        return out

    def service_types(self) -> dict[str, set[str]]:
        out: dict[str, set[str]] = {}
        cache = self.remote()
        if cache is not None:
            for name, types in cache.service_types().items():
                out.setdefault(name, set()).update(types)
        for name, srv in self.context.services.items():
            if srv.node is not self.node:
                out.setdefault(name, set()).add(srv.srv_type.name)
        return out

    def node_names(self, include_hidden: bool = False) -> list[str]:
        names: set[str] = set()
        cache = self.remote()
        if cache is not None:
            names.update(e.node for e in cache.nodes())
        names.update(n.fully_qualified_name for n in self.context.nodes if n is not self.node)
        if not include_hidden:
            names = {n for n in names if not n.rsplit("/", 1)[-1].startswith("_")}
        return sorted(names)

    def wait_for_topic_type(self, topic: str, timeout_s: float | None) -> str | None:
        """The type of ``topic`` once some publisher (or subscriber) announces it."""
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        while True:
            types = self.topic_types().get(topic)
            if types:
                return sorted(types)[0]
            if deadline is not None and time.monotonic() >= deadline:
                return None
            time.sleep(0.02)


def cli_transport_config() -> Any:
    """The Zenoh settings of a short-lived CLI process: a *client* of the router.

    A peer opens a link to every process the router names, and closing the session waits
    for links still being opened; one peer that does not answer (a stopped or stalled
    process) held every ``eddie node list`` for Zenoh's 10 s handshake timeout, deaf to
    Ctrl-C. A client has one link, to the router, and the router forwards everything a CLI
    command needs. ``EDDIE_ZENOH_MODE`` or ``EDDIE_ZENOH_CONFIG`` still decide when set.
    """
    from eddiebot.transport import ZenohConfig

    config = ZenohConfig.from_env()
    if config.config_file is None and not os.environ.get("EDDIE_ZENOH_MODE"):
        config.mode = "client"
    return config


@contextlib.contextmanager
def cli_session(command: str, *, use_transport: bool = True) -> Iterator[CliSession]:
    """A fresh context with a hidden node ``_eddie_<command>_<pid>``, joined to the graph
    as a client of the router (`cli_transport_config`)."""
    from eddiebot.core import Context, Node

    context = Context()
    try:
        node = Node(f"_eddie_{command}_{os.getpid()}", context=context,
                    start_parameter_services=False)
        transport = None
        if use_transport:
            from eddiebot.transport import connect, transport_enabled

            transport = connect(context, cli_transport_config())
            if transport is None:
                why = ("EDDIE_TRANSPORT=none" if not transport_enabled()
                       else "the Zenoh router cannot be reached")
                print(f"eddie {command}: no transport ({why}): only this process is visible",
                      file=sys.stderr)
        yield CliSession(context, node, transport)
    finally:
        context.shutdown()


def parse_type(type_name: str) -> str:
    """``std_msgs/String`` → ``std_msgs/msg/String`` (as the ros2 CLI accepts both)."""
    return normalize_type_name(type_name)


def discovery_wait_s() -> float:
    """How long list commands let the graph settle (``EDDIE_DISCOVERY_WAIT``, default 0.3 s)."""
    try:
        return float(os.environ.get("EDDIE_DISCOVERY_WAIT", "0.3"))
    except ValueError:
        return 0.3


def connect_transport(context: Any) -> bool:
    """Join the graph of other processes (Zenoh, unless ``EDDIE_TRANSPORT=none``); whether a
    transport is attached. Node log lines then go out on ``/rosout`` too."""
    from eddiebot.transport import connect

    return connect(context) is not None
