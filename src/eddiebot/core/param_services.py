"""The rcl_interfaces parameter services every node offers, and a client for them.

``ParameterService(node)`` (attached by ``Node.__init__`` unless
``start_parameter_services=False``) serves ``<node>/describe_parameters``,
``get_parameters``, ``get_parameter_types``, ``list_parameters``, ``set_parameters`` and
``set_parameters_atomically`` exactly as rclpy does, through the node's own parameter API
(type checks, ranges, read-only flags and on-set callbacks that may reject), and publishes
rcl_interfaces/ParameterEvent on ``/parameter_events`` after every successful change.

``ParameterClient(node, "remote_node")`` calls those services on another node, here or in
another process (``eddie param get/set/list``).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from eddiebot.core.parameters import (
    Parameter,
    ParameterDescriptor,
    ParameterType,
    SetParametersResult,
    value_from_msg,
    value_to_msg,
)
from eddiebot.core.qos import QoSProfile
from eddiebot.core.task import Future

if TYPE_CHECKING:
    from eddiebot.core.node import Client, Node, Service

__all__ = ["PARAMETER_SEPARATOR", "ParameterClient", "ParameterService", "descriptor_to_msg"]

PARAMETER_SEPARATOR = "."
#: rclpy's qos_profile_parameter_events.
PARAMETER_EVENTS_QOS = QoSProfile(depth=1000)

_SERVICES = (
    "describe_parameters",
    "get_parameters",
    "get_parameter_types",
    "list_parameters",
    "set_parameters",
    "set_parameters_atomically",
)
_SRV_TYPES = {
    "describe_parameters": "rcl_interfaces/srv/DescribeParameters",
    "get_parameters": "rcl_interfaces/srv/GetParameters",
    "get_parameter_types": "rcl_interfaces/srv/GetParameterTypes",
    "list_parameters": "rcl_interfaces/srv/ListParameters",
    "set_parameters": "rcl_interfaces/srv/SetParameters",
    "set_parameters_atomically": "rcl_interfaces/srv/SetParametersAtomically",
}


def descriptor_to_msg(name: str, ptype: ParameterType, desc: ParameterDescriptor) -> Any:
    """A ``ParameterDescriptor`` → rcl_interfaces/ParameterDescriptor."""
    from eddiebot.msgs.rcl_interfaces import FloatingPointRange, IntegerRange
    from eddiebot.msgs.rcl_interfaces import ParameterDescriptor as DescriptorMsg

    msg = DescriptorMsg(
        name=name,
        type=int(ptype),
        description=desc.description,
        additional_constraints=desc.additional_constraints,
        read_only=desc.read_only,
        dynamic_typing=desc.dynamic_typing,
    )
    if desc.range is not None:
        lo, hi = desc.range
        if ptype == ParameterType.INTEGER:
            msg.integer_range = [IntegerRange(from_value=int(lo), to_value=int(hi), step=0)]
        else:
            msg.floating_point_range = [
                FloatingPointRange(from_value=float(lo), to_value=float(hi), step=0.0)
            ]
    return msg


def _result_msg(result: SetParametersResult) -> Any:
    from eddiebot.msgs.rcl_interfaces import SetParametersResult as ResultMsg

    return ResultMsg(successful=bool(result.successful), reason=result.reason)


def list_parameter_names(names: Sequence[str], prefixes: Sequence[str], depth: int) -> tuple[list[str], list[str]]:
    """(names, prefixes) answering ListParameters as rclpy does (depth 0: recursive)."""
    out_names: list[str] = []
    out_prefixes: list[str] = []
    with_sep: list[str] = []
    for name in names:
        if PARAMETER_SEPARATOR in name:
            with_sep.append(name)
        elif prefixes:
            out_names.extend(name for p in prefixes if name.startswith(p))
        else:
            out_names.append(name)
    if depth == 1:
        return out_names, out_prefixes
    if depth != 0:
        with_sep = [n for n in with_sep if n.count(PARAMETER_SEPARATOR) < depth]
    for name in with_sep:
        full_prefix = PARAMETER_SEPARATOR.join(name.split(PARAMETER_SEPARATOR)[:-1])
        if prefixes:
            for p in prefixes:
                if name.startswith(p + PARAMETER_SEPARATOR):
                    out_names.append(name)
                    if full_prefix not in out_prefixes:
                        out_prefixes.append(full_prefix)
                    if p not in out_prefixes:
                        out_prefixes.append(p)
        else:
            if full_prefix not in out_prefixes:
                out_prefixes.append(full_prefix)
            out_names.append(name)
    return out_names, out_prefixes


class ParameterService:
    """Serves a node's parameters over the rcl_interfaces services."""

    def __init__(self, node: Node) -> None:
        from eddiebot.msgs import get_service
        from eddiebot.msgs.rcl_interfaces import ParameterEvent

        self.node = node
        self._event_type = ParameterEvent
        self.services: list[Service] = []
        callbacks = {
            "describe_parameters": self._describe,
            "get_parameters": self._get,
            "get_parameter_types": self._get_types,
            "list_parameters": self._list,
            "set_parameters": self._set,
            "set_parameters_atomically": self._set_atomically,
        }
        try:
            for name in _SERVICES:
                self.services.append(
                    node.create_service(get_service(_SRV_TYPES[name]), f"~/{name}", callbacks[name])
                )
        except ValueError as exc:
            # Two nodes of one name in a process (ROS allows it, with a warning): the first
            # one keeps the services.
            for srv in self.services:
                node.destroy_service(srv)
            self.services = []
            node.get_logger().warning(f"parameter services not started: {exc}")
        self.events_pub = node.create_publisher(ParameterEvent, "/parameter_events",
                                                PARAMETER_EVENTS_QOS)
        node.add_post_set_parameters_callback(self._publish_event)

    def destroy(self) -> None:
        for srv in self.services:
            self.node.destroy_service(srv)
        self.services = []
        self.node.destroy_publisher(self.events_pub)

    def _publish_event(self, parameters: list[Parameter]) -> None:
        if self.node.context.local_subscription_count(self.events_pub.topic_name) == 0 and not \
                self.node.context.transports:
            return  # nobody can hear it: skip building the message
        event = self._event_type(
            stamp=self.node.now().to_msg(),
            node=self.node.fully_qualified_name,
            changed_parameters=[p.to_msg() for p in parameters],
        )
        self.events_pub.publish(event)

    # -- callbacks ------------------------------------------------------------------------
    def _describe(self, request: Any, response: Any) -> Any:
        node = self.node
        for name in request.names:
            if not node.has_parameter(name) and not node.allow_undeclared_parameters:
                # rclpy raises ParameterNotDeclaredException: answer with an empty list
                response.descriptors = []
                return response
            response.descriptors.append(
                descriptor_to_msg(name, node.get_parameter(name).type, node.describe_parameter(name))
            )
        return response

    def _get(self, request: Any, response: Any) -> Any:
        from eddiebot.msgs.rcl_interfaces import ParameterValue

        node = self.node
        for name in request.names:
            if node.has_parameter(name):
                response.values.append(value_to_msg(node.get_parameter(name).value))
            else:
                response.values.append(ParameterValue())
        return response

    def _get_types(self, request: Any, response: Any) -> Any:
        node = self.node
        response.types = [
            int(node.get_parameter(n).type) if node.has_parameter(n) else 0 for n in request.names
        ]
        return response

    def _list(self, request: Any, response: Any) -> Any:
        names, prefixes = list_parameter_names(
            list(self.node.parameters), list(request.prefixes), int(request.depth)
        )
        response.result.names = names
        response.result.prefixes = prefixes
        return response

    def _set(self, request: Any, response: Any) -> Any:
        response.results = [
            _result_msg(self._set_one([p])) for p in request.parameters
        ]
        return response

    def _set_atomically(self, request: Any, response: Any) -> Any:
        response.result = _result_msg(self._set_one(list(request.parameters)))
        return response

    def _set_one(self, msgs: list[Any]) -> SetParametersResult:
        params = []
        for m in msgs:
            if int(m.value.type) == ParameterType.NOT_SET:
                return SetParametersResult(False, f"parameter {m.name!r}: undeclaring is not supported")
            params.append(Parameter(m.name, value_from_msg(m.value)))
        return self.node.set_parameters_atomically(params)


class ParameterClient:
    """Reads and writes another node's parameters through its services (rclpy's
    ``AsyncParameterClient`` plus blocking helpers)."""

    def __init__(self, node: Node, remote_node_name: str, *, timeout_sec: float = 5.0) -> None:
        from eddiebot.msgs import get_service

        self.node = node
        self.remote_node_name = remote_node_name if remote_node_name.startswith("/") \
            else "/" + remote_node_name
        self.timeout_sec = timeout_sec
        self._clients: dict[str, Client] = {
            name: node.create_client(get_service(_SRV_TYPES[name]),
                                     f"{self.remote_node_name}/{name}")
            for name in _SERVICES
        }

    def services_are_ready(self) -> bool:
        return all(c.service_is_ready() for c in self._clients.values())

    def wait_for_services(self, timeout_sec: float | None = None) -> bool:
        return all(c.wait_for_service(timeout_sec) for c in self._clients.values())

    # -- async (futures of the raw responses) -------------------------------------------------
    def _request(self, name: str, **fields: Any) -> Any:
        return self._clients[name].srv_type.Request(**fields)

    def get_parameters_async(self, names: Sequence[str]) -> Future:
        return self._clients["get_parameters"].call_async(
            self._request("get_parameters", names=list(names)))

    def get_parameter_types_async(self, names: Sequence[str]) -> Future:
        return self._clients["get_parameter_types"].call_async(
            self._request("get_parameter_types", names=list(names)))

    def describe_parameters_async(self, names: Sequence[str]) -> Future:
        return self._clients["describe_parameters"].call_async(
            self._request("describe_parameters", names=list(names)))

    def list_parameters_async(self, prefixes: Sequence[str] | None = None, depth: int = 0) -> Future:
        return self._clients["list_parameters"].call_async(
            self._request("list_parameters", prefixes=list(prefixes or []), depth=int(depth)))

    def set_parameters_async(self, parameters: Sequence[Parameter] | dict[str, Any]) -> Future:
        return self._clients["set_parameters"].call_async(
            self._request("set_parameters", parameters=_param_msgs(parameters)))

    def set_parameters_atomically_async(self, parameters: Sequence[Parameter] | dict[str, Any]) -> Future:
        return self._clients["set_parameters_atomically"].call_async(
            self._request("set_parameters_atomically", parameters=_param_msgs(parameters)))

    # -- blocking ----------------------------------------------------------------------
    def _call(self, name: str, request: Any) -> Any:
        return self._clients[name].call(request, timeout_sec=self.timeout_sec)

    def get_parameters(self, names: Sequence[str]) -> list[Any]:
        """Values of ``names`` (None for a parameter the node does not have)."""
        response = self._call("get_parameters", self._request("get_parameters", names=list(names)))
        return [value_from_msg(v) for v in response.values]

    def get_parameter(self, name: str) -> Any:
        return self.get_parameters([name])[0]

    def get_parameter_types(self, names: Sequence[str]) -> list[ParameterType]:
        response = self._call("get_parameter_types",
                              self._request("get_parameter_types", names=list(names)))
        return [ParameterType(int(t)) for t in response.types]

    def describe_parameters(self, names: Sequence[str]) -> list[Any]:
        """rcl_interfaces/ParameterDescriptor messages."""
        response = self._call("describe_parameters",
                              self._request("describe_parameters", names=list(names)))
        return list(response.descriptors)

    def list_parameters(self, prefixes: Sequence[str] | None = None, depth: int = 0) -> list[str]:
        """Names of the remote node's parameters (depth 0: all levels)."""
        response = self._call("list_parameters", self._request(
            "list_parameters", prefixes=list(prefixes or []), depth=int(depth)))
        return list(response.result.names)

    def set_parameters(self, parameters: Sequence[Parameter] | dict[str, Any]) -> list[SetParametersResult]:
        """Set each parameter on its own; one result per parameter."""
        response = self._call("set_parameters", self._request(
            "set_parameters", parameters=_param_msgs(parameters)))
        return [SetParametersResult(bool(r.successful), str(r.reason)) for r in response.results]

    def set_parameters_atomically(self, parameters: Sequence[Parameter] | dict[str, Any]) -> SetParametersResult:
        response = self._call("set_parameters_atomically", self._request(
            "set_parameters_atomically", parameters=_param_msgs(parameters)))
        return SetParametersResult(bool(response.result.successful), str(response.result.reason))

    def destroy(self) -> None:
        for c in self._clients.values():
            self.node.destroy_client(c)


def _param_msgs(parameters: Sequence[Parameter] | dict[str, Any]) -> list[Any]:
    if isinstance(parameters, dict):
        parameters = [Parameter(k, v) for k, v in parameters.items()]
    return [p.to_msg() for p in parameters]
