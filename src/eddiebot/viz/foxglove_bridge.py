"""Foxglove bridge: the graph as a Foxglove WebSocket server, as ROS 2's foxglove_bridge shows it.

Every topic of the graph (this process and, through the transport, the others) is advertised
with its ROS 2 schema — encoding ``ros2msg``, the full message definition with its
dependencies (as rosbag2 stores it) — and ``cdr`` messages, so Foxglove's 3D, Image, Plot,
Raw Messages and Teleop panels decode it as they would a ROS 2 robot's. The bridge
subscribes to a topic only while some Foxglove client subscribes to it.

- Transient-local topics (``/tf_static``, ``/map``, ``/robot_description``, ...) are held
  from the start and replayed to every late subscriber.
- Services of the graph are callable from Foxglove's Service Call panel (CDR).
- Parameters of every node on the graph are listed and settable (``/node.param``, as ROS 2's
  foxglove_bridge names them): this process's nodes directly, the others through their
  parameter services (``list_parameters``, ``get_parameters``, ``set_parameters``).
- Client-published topics are accepted (CDR or JSON); ``/cmd_vel`` from a client goes to
  ``/cmd_vel_teleop`` so the Teleop panel drives through the twist mux like every other
  source.

The ROS distribution (``ROS_DISTRO``: jazzy, that of our message definitions) is announced in
the server's metadata, as ROS 2's foxglove_bridge does, when the SDK's ``start_server`` takes
``server_info``; the Foxglove app enables the 3D panel's click-to-publish ("Publish point /
pose / pose estimate") only for such servers. foxglove-sdk 0.30's Python ``start_server``
has no such argument (its Rust core has, unexposed), so with it those buttons stay greyed
out: use the Teleop panel, the Publish panel or the eddie web dashboard for goals and
initial poses.
"""

from __future__ import annotations

import inspect
import json
import threading
import time
from dataclasses import dataclass, field
from typing import Any

from eddiebot.bag.writer import ROS_DISTRO
from eddiebot.core.context import Context
from eddiebot.core.executors import SingleThreadedExecutor
from eddiebot.core.node import Node, Subscription
from eddiebot.core.param_services import ParameterClient
from eddiebot.core.parameters import Parameter, value_from_msg
from eddiebot.core.qos import DurabilityPolicy, QoSProfile
from eddiebot.msgs import (
    SERVICES,
    TYPESTORE,
    deserialize,
    get_message,
    message_definition,
    normalize_type_name,
    serialize,
)

__all__ = ["DEFAULT_REMAP", "LATCHED_TOPICS", "ROS_DISTRO", "BridgeConfig", "FoxgloveBridge",
           "msg_from_dict", "split_parameter_name"]

#: Topics whose last messages a late subscriber receives (transient-local in ROS 2).
LATCHED_TOPICS = ("/tf_static", "/map", "/robot_description", "/map_metadata",
                  "/global_costmap/costmap", "/local_costmap/costmap")
#: Client-published topic → graph topic.
DEFAULT_REMAP = {"/cmd_vel": "/cmd_vel_teleop"}
_LATCHED_QOS = QoSProfile(depth=10, durability=DurabilityPolicy.TRANSIENT_LOCAL)


@dataclass
class BridgeConfig:
    """Where the bridge serves and what it carries."""

    host: str = "127.0.0.1"
    port: int = 8765
    name: str = "eddiebot"
    latched_topics: tuple[str, ...] = LATCHED_TOPICS
    client_remap: dict[str, str] = field(default_factory=lambda: dict(DEFAULT_REMAP))
    #: seconds between graph scans for new topics and services
    discovery_period_s: float = 1.0
    service_timeout_s: float = 5.0
    #: seconds a parameter request waits for other processes' nodes to answer
    param_timeout_s: float = 5.0


def split_parameter_name(full: str) -> tuple[str, str]:
    """``/controller_server.FollowPath.max_vel_x`` → (``/controller_server``,
    ``FollowPath.max_vel_x``): the node is everything up to the first dot after its last
    slash (node names have no dots; parameter names may)."""
    slash = full.rfind("/")
    dot = full.find(".", slash + 1)
    if slash < 0 or dot < 0:
        return "", full
    return full[:dot], full[dot + 1:]


def _server_metadata(start_server: Any) -> dict[str, Any]:
    """The keyword that announces ``ROS_DISTRO``, if this SDK's ``start_server`` has one."""
    try:
        params = inspect.signature(start_server).parameters
    except (TypeError, ValueError):
        return {}
    return {"server_info": {"ROS_DISTRO": ROS_DISTRO}} if "server_info" in params else {}


def msg_from_dict(type_name: str, values: dict[str, Any]) -> Any:
    """A message of ``type_name`` with fields from a JSON-like dict (nested dicts, lists)."""
    import numpy as np
    from rosbags.interfaces import Nodetype

    cls = get_message(type_name)
    msg = cls()
    fields: dict[str, Any] = dict(TYPESTORE.fielddefs[normalize_type_name(type_name)][1])
    for name, value in values.items():
        if name not in fields:
            raise ValueError(f"{type_name} has no field {name!r}")
        kind, detail = fields[name]
        current = getattr(msg, name)
        if kind == Nodetype.NAME:
            setattr(msg, name, msg_from_dict(detail, value or {}))
        elif kind == Nodetype.BASE:
            setattr(msg, name, type(current)(value))
        else:
            inner = detail[0]
            if inner[0] == Nodetype.NAME:
                setattr(msg, name, [msg_from_dict(inner[1], v or {}) for v in value])
            elif isinstance(current, np.ndarray):
                setattr(msg, name, np.asarray(value, dtype=current.dtype))
            else:
                setattr(msg, name, list(value))
    return msg


class _Topic:
    """One advertised topic: its Foxglove channel, bus subscription and latched messages."""

    def __init__(self, name: str, type_name: str, channel: Any) -> None:
        self.name = name
        self.type_name = type_name
        self.channel = channel
        self.subscribers = 0
        self.subscription: Subscription | None = None
        self.latched: list[bytes] = []


class FoxgloveBridge:
    """Serves ``context``'s graph to Foxglove; ``stop()`` ends it (the context stays)."""

    def __init__(self, context: Context, config: BridgeConfig | None = None) -> None:
        import foxglove
        from foxglove.websocket import Capability

        self._fg = foxglove
        self.config = cfg = config or BridgeConfig()
        self.context = context
        self.node = Node("eddie_foxglove_bridge", context=context, start_parameter_services=False)
        self._lock = threading.RLock()
        self._topics: dict[str, _Topic] = {}
        self._by_channel: dict[int, _Topic] = {}
        self._services: dict[str, Any] = {}
        self._client_channels: dict[tuple[int, int], tuple[Any, str, str]] = {}
        self._publishers: dict[str, Any] = {}
        self._clients: dict[str, Any] = {}
        self._param_clients: dict[str, ParameterClient] = {}
        self._fg_context = foxglove.Context()
        self.server = foxglove.start_server(
            name=cfg.name, host=cfg.host, port=cfg.port,
            capabilities=[Capability.ClientPublish, Capability.Services, Capability.Parameters],
            server_listener=self,  # type: ignore[arg-type]
            supported_encodings=["cdr", "json"],
            context=self._fg_context,
            **_server_metadata(foxglove.start_server))
        self.executor = SingleThreadedExecutor(context=context, drive_sim_time=False)
        self.executor.add_node(self.node)
        self.discover()
        self.node.create_timer(cfg.discovery_period_s, self.discover, clock=context.system_clock)
        self._thread = threading.Thread(target=self.executor.spin, name="eddie-foxglove", daemon=True)
        self._thread.start()

    @property
    def port(self) -> int:
        return int(self.server.port)

    @property
    def url(self) -> str:
        return f"ws://{self.config.host}:{self.port}"

    # -- graph -------------------------------------------------------------------------------
    def _graph_topics(self) -> dict[str, str]:
        out: dict[str, str] = {}
        for t in self.context.transports:
            cache = getattr(t, "cache", None)
            if cache is not None:
                for name, types in cache.topic_types().items():
                    out[name] = sorted(types)[0]
        for name, entry in list(self.context.topics.items()):
            if entry.type_name and any(p.node is not self.node for p in entry.publishers):
                out[name] = entry.type_name
        return out

    def _graph_services(self) -> dict[str, str]:
        out: dict[str, str] = {}
        for t in self.context.transports:
            cache = getattr(t, "cache", None)
            if cache is not None:
                for name, types in cache.service_types().items():
                    out[name] = sorted(types)[0]
        for name, srv in list(self.context.services.items()):
            if srv.node is not self.node:
                out[name] = srv.srv_type.name
        return out

    def discover(self) -> None:
        """Advertise topics and services that appeared since the last scan."""
        graph = self._graph_topics()
        for name, type_name in graph.items():
            if name not in self._topics:
                self._advertise(name, normalize_type_name(type_name))
        with self._lock:
            gone = [t for n, t in self._topics.items() if n not in graph and t.subscribers == 0
                    and n not in self.config.latched_topics]
            for topic in gone:  # the last publisher left: withdraw the channel
                del self._topics[topic.name]
                self._by_channel.pop(topic.channel.id(), None)
                if topic.subscription is not None:
                    self.node.destroy_subscription(topic.subscription)
                topic.channel.close()
        new_services = []
        for name, type_name in self._graph_services().items():
            if name not in self._services and type_name in SERVICES:
                svc = self._service(name, type_name)
                if svc is not None:
                    new_services.append(svc)
        if new_services:
            try:
                self.server.add_services(new_services)
            except Exception as exc:  # a name the SDK refuses must not stop discovery
                self.node.get_logger().warning(f"foxglove: cannot add services: {exc}")

    def _schema(self, type_name: str) -> Any:
        return self._fg.Schema(name=type_name, encoding="ros2msg",
                               data=message_definition(type_name).encode())

    def _advertise(self, name: str, type_name: str) -> None:
        try:
            schema = self._schema(type_name)
        except Exception as exc:  # a type missing from the store
            self.node.get_logger().warning(f"foxglove: cannot advertise {name} ({type_name}): {exc}")
            return
        channel = self._fg.Channel(name, schema=schema, message_encoding="cdr", context=self._fg_context)
        topic = _Topic(name, type_name, channel)
        with self._lock:
            self._topics[name] = topic
            self._by_channel[channel.id()] = topic
        if name in self.config.latched_topics:
            self._subscribe(topic, latched=True)

    def _subscribe(self, topic: _Topic, latched: bool = False) -> None:
        if topic.subscription is not None:
            return
        cls = get_message(topic.type_name)
        keep = latched or topic.name in self.config.latched_topics

        def forward(msg: Any) -> None:
            data = serialize(msg, topic.type_name)
            if keep:
                with self._lock:
                    topic.latched.append(data)
                    del topic.latched[:-10]
            if topic.subscribers > 0:
                topic.channel.log(data, log_time=time.time_ns())

        qos = _LATCHED_QOS if keep else QoSProfile(depth=10)
        topic.subscription = self.node.create_subscription(cls, topic.name, forward, qos)

    # -- ServerListener ---------------------------------------------------------------------
    def on_subscribe(self, client: Any, channel: Any) -> None:
        with self._lock:
            topic = self._by_channel.get(channel.id)
            if topic is None:
                return
            topic.subscribers += 1
            replay = list(topic.latched)
        self._subscribe(topic)
        for data in replay:  # transient-local: the late subscriber gets the last messages
            topic.channel.log(data, log_time=time.time_ns())

    def on_unsubscribe(self, client: Any, channel: Any) -> None:
        with self._lock:
            topic = self._by_channel.get(channel.id)
            if topic is None:
                return
            topic.subscribers = max(0, topic.subscribers - 1)
            if (topic.subscribers == 0 and topic.subscription is not None
                    and topic.name not in self.config.latched_topics):
                self.node.destroy_subscription(topic.subscription)
                topic.subscription = None

    def on_client_advertise(self, client: Any, channel: Any) -> None:
        target = self.config.client_remap.get(channel.topic, channel.topic)
        type_name = normalize_type_name(channel.schema_name or "")
        try:
            cls = get_message(type_name)
        except Exception:
            self.server.publish_status(
                f"cannot publish {channel.topic}: unknown type {channel.schema_name!r}",
                self._fg.StatusLevel.Warning)
            return
        with self._lock:
            pub = self._publishers.get(target)
            if pub is None:
                pub = self._publishers[target] = self.node.create_publisher(cls, target, 10)
            self._client_channels[(client.id, channel.id)] = (pub, type_name, channel.encoding)

    def on_client_unadvertise(self, client: Any, client_channel_id: int) -> None:
        with self._lock:
            self._client_channels.pop((client.id, client_channel_id), None)

    def on_message_data(self, client: Any, client_channel_id: int, data: bytes) -> None:
        with self._lock:
            entry = self._client_channels.get((client.id, client_channel_id))
        if entry is None:
            return
        pub, type_name, encoding = entry
        try:
            if encoding == "json":
                msg = msg_from_dict(type_name, json.loads(data))
            else:
                msg = deserialize(data, type_name)
            pub.publish(msg)
        except Exception as exc:
            self.server.publish_status(f"dropped a {type_name} from a client: {exc}",
                                       self._fg.StatusLevel.Warning)

    # -- services -------------------------------------------------------------------------------
    def _service(self, name: str, type_name: str) -> Any:
        fg = self._fg
        srv_type = SERVICES[type_name]
        req_t, res_t = srv_type.Request.__msgtype__, srv_type.Response.__msgtype__
        schema = fg.ServiceSchema(
            name=type_name,
            request=fg.MessageSchema(encoding="cdr", schema=self._schema(req_t)),
            response=fg.MessageSchema(encoding="cdr", schema=self._schema(res_t)))
        client = self.node.create_client(srv_type, name)

        def handler(request: Any) -> bytes:
            req = deserialize(request.payload, req_t)
            res = client.call(req, timeout_sec=self.config.service_timeout_s)
            return serialize(res, res_t)

        svc = fg.Service(name=name, schema=schema, handler=handler)
        self._services[name] = svc
        return svc

    # -- parameters (every node on the graph) ---------------------------------------------------
    def _local_nodes(self) -> list[Node]:
        return [n for n in list(self.context.nodes) if n is not self.node]

    def _remote_nodes(self) -> list[str]:
        """Fully qualified names of the other processes' nodes that serve parameters."""
        local = {n.fully_qualified_name for n in self.context.nodes}
        out: set[str] = set()
        for t in self.context.transports:
            cache = getattr(t, "cache", None)
            if cache is None:
                continue
            for e in cache.nodes():
                name = e.node
                if (name not in local and not e.node_name.startswith("_")
                        and cache.has_service(f"{name}/list_parameters")
                        and cache.has_service(f"{name}/get_parameters")):
                    out.add(name)
        return sorted(out)

    def _param_client(self, node_name: str) -> ParameterClient:
        with self._lock:
            client = self._param_clients.get(node_name)
            if client is None:
                client = self._param_clients[node_name] = ParameterClient(
                    self.node, node_name, timeout_sec=self.config.param_timeout_s)
            return client

    def _remote_values(self, wanted: dict[str, list[str]]) -> list[tuple[str, Any]]:
        """(``/node.param``, value) of remote nodes: ``wanted`` maps a node to the names
        asked for (empty: all its parameters). Every node is asked at once; one that does
        not answer within ``param_timeout_s`` is left out, as foxglove_bridge does."""
        deadline = time.monotonic() + self.config.param_timeout_s

        def remaining() -> float:
            return max(0.0, deadline - time.monotonic())

        listings = {n: self._param_client(n).list_parameters_async([], 0)
                    for n, names in wanted.items() if not names}
        names = {n: list(ns) for n, ns in wanted.items() if ns}
        for n, future in listings.items():
            if future.wait(remaining()) and future.exception() is None:
                names[n] = list(future.result().result.names)
        gets = {n: self._param_client(n).get_parameters_async(ns)
                for n, ns in names.items() if ns}
        out: list[tuple[str, Any]] = []
        for n, future in gets.items():
            if not future.wait(remaining()) or future.exception() is not None:
                self.node.get_logger().warning(f"foxglove: no parameters from {n}")
                continue
            for pname, value in zip(names[n], future.result().values, strict=False):
                out.append((f"{n}.{pname}", value_from_msg(value)))
        return out

    def _fg_parameters(self, values: list[tuple[str, Any]]) -> list[Any]:
        out = []
        for full, value in values:
            if value is None or (isinstance(value, list) and not value):
                continue
            try:
                out.append(self._fg.Parameter(full, value=value))
            except Exception:  # a value the SDK cannot carry
                continue
        return out

    def on_get_parameters(self, client: Any, param_names: list[str],
                          request_id: str | None = None) -> list[Any]:
        asked: dict[str, list[str]] = {}
        for full in param_names:
            node_name, pname = split_parameter_name(full)
            asked.setdefault(node_name, []).append(pname)
        values: list[tuple[str, Any]] = []
        for node in self._local_nodes():
            fq = node.fully_qualified_name
            if param_names and fq not in asked:
                continue
            for pname, p in node.parameters.items():
                if not param_names or pname in asked[fq]:
                    values.append((f"{fq}.{pname}", p.value))
        remote = self._remote_nodes()
        wanted = {n: [] for n in remote} if not param_names else {
            n: names for n, names in asked.items() if n in remote}
        if wanted:
            values.extend(self._remote_values(wanted))
        return self._fg_parameters(values)

    def on_set_parameters(self, client: Any, parameters: list[Any],
                          request_id: str | None = None) -> list[Any]:
        local = {n.fully_qualified_name: n for n in self._local_nodes()}
        remote: dict[str, list[Parameter]] = {}
        for p in parameters:
            node_name, pname = split_parameter_name(p.name)
            value = p.get_value() if hasattr(p, "get_value") else p.value
            node = local.get(node_name)
            if node is None:
                remote.setdefault(node_name, []).append(Parameter(pname, value))
                continue
            if not node.has_parameter(pname):
                continue
            result = node.set_parameter(pname, value)
            if not result.successful:
                self.server.publish_status(f"{p.name}: {result.reason}", self._fg.StatusLevel.Warning)
        known = set(self._remote_nodes())
        futures = {n: self._param_client(n).set_parameters_async(ps)
                   for n, ps in remote.items() if n in known}
        deadline = time.monotonic() + self.config.param_timeout_s
        for n, future in futures.items():
            if not future.wait(max(0.0, deadline - time.monotonic())) \
                    or future.exception() is not None:
                self.server.publish_status(f"{n}: parameters not set (no answer)",
                                           self._fg.StatusLevel.Warning)
                continue
            for p, r in zip(remote[n], future.result().results, strict=False):
                if not r.successful:
                    self.server.publish_status(f"{n}.{p.name}: {r.reason}",
                                               self._fg.StatusLevel.Warning)
        return self.on_get_parameters(client, [p.name for p in parameters], request_id)

    # -- life ------------------------------------------------------------------------------------
    def stop(self) -> None:
        self.server.stop()
        self.executor.shutdown()
        self._thread.join(5)
        self.node.destroy_node()

    def __enter__(self) -> FoxgloveBridge:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()
