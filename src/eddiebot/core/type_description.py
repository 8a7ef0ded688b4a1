"""Type descriptions (REP-2016) and every node's ``~/get_type_description`` service.

:func:`describe` builds the ``type_description_interfaces/TypeDescription`` of a message or
service type from its field definitions, the same structure whose JSON the RIHS01 hash is
taken of (so :func:`rihs01` of a description equals the type's hash). A service type is
described as rosidl does: ``request_message``, ``response_message`` and ``event_message``
(``service_msgs/ServiceEventInfo info``, ``Request[<=1] request``, ``Response[<=1]
response``).

``TypeDescriptionService(node)`` answers ``~/get_type_description`` as rclpy's does: the
request names a type by its RIHS01 hash; the node answers for the types it uses (its
publishers', subscriptions', services' and clients'), else ``successful = false`` with
rcl's reason.
"""

from __future__ import annotations

import hashlib
import json
import re
from typing import TYPE_CHECKING, Any

from rosbags.interfaces import Nodetype

from eddiebot.msgs import TYPESTORE, get_message, get_service, load_type, message_definition

if TYPE_CHECKING:
    from eddiebot.core.node import Node, Service

__all__ = [
    "TypeDescriptionService",
    "describe",
    "rihs01",
    "service_fielddefs",
    "to_message",
]

#: FieldType ids of the base types (type_description_interfaces/msg/FieldType)
_TID = {
    "int8": 2, "uint8": 3, "int16": 4, "uint16": 5, "int32": 6, "uint32": 7, "int64": 8,
    "uint64": 9, "float32": 10, "float64": 11, "float128": 12, "char": 13, "wchar": 14,
    "bool": 15, "byte": 16, "octet": 16, "string": 17, "wstring": 18,
    "bounded_string": 21, "bounded_wstring": 22,
}
_SERVICE_EVENT_INFO = "service_msgs/msg/ServiceEventInfo"
_HASH_RE = re.compile(r"^RIHS01_[0-9a-f]{64}$")
SERVICE_NAME = "~/get_type_description"


def service_fielddefs(fielddefs: Any, srv_type: str) -> dict[str, Any]:
    """``fielddefs`` plus the entries that describe service ``srv_type`` as rosidl does
    (``<srv>``, ``<srv>_Event``; ``ServiceEventInfo.client_gid`` as ``uint8[16]``)."""
    defs = dict(fielddefs)
    req, res, event = f"{srv_type}_Request", f"{srv_type}_Response", f"{srv_type}_Event"
    if _SERVICE_EVENT_INFO in defs:
        consts, fields = defs[_SERVICE_EVENT_INFO]
        defs[_SERVICE_EVENT_INFO] = (consts, [
            (n, (Nodetype.ARRAY, ((Nodetype.BASE, ("uint8", 0)), 16)))
            if n == "client_gid" else (n, d) for n, d in fields
        ])
    defs[event] = ([], [
        ("info", (Nodetype.NAME, _SERVICE_EVENT_INFO)),
        ("request", (Nodetype.SEQUENCE, ((Nodetype.NAME, req), 1))),
        ("response", (Nodetype.SEQUENCE, ((Nodetype.NAME, res), 1))),
    ])
    defs[srv_type] = ([], [
        ("request_message", (Nodetype.NAME, req)),
        ("response_message", (Nodetype.NAME, res)),
        ("event_message", (Nodetype.NAME, event)),
    ])
    return defs


def describe(fielddefs: Any, type_name: str) -> dict[str, Any]:
    """The TypeDescription of ``type_name`` as plain data (REP-2016's hashed form).

    Raises ``KeyError`` naming a type the definitions do not hold."""
    structs: dict[str, dict[str, Any]] = {}

    def field(name: str, desc: Any) -> dict[str, Any]:
        increment = capacity = string_capacity = 0
        nested = ""
        if desc[0] == Nodetype.ARRAY:
            increment, capacity = 48, desc[1][1]
            kind, rest = desc[1][0]
        elif desc[0] == Nodetype.SEQUENCE:
            bound = desc[1][1]
            increment, capacity = (96, bound) if bound else (144, 0)
            kind, rest = desc[1][0]
        else:
            kind, rest = desc
        if kind == Nodetype.NAME:
            tid, nested = increment + 1, rest
            struct(rest)
        elif rest[0] in ("string", "wstring") and rest[1]:
            string_capacity = rest[1]
            tid = increment + _TID[f"bounded_{rest[0]}"]
        else:
            tid = increment + _TID[rest[0]]
        return {"name": name, "type": {"type_id": tid, "capacity": capacity,
                                       "string_capacity": string_capacity,
                                       "nested_type_name": nested}}

    def struct(name: str) -> dict[str, Any]:
        if name not in structs:
            structs[name] = {}  # placeholder against recursion
            fields = fielddefs[name][1] or [
                ("structure_needs_at_least_one_member", (Nodetype.BASE, ("uint8", 0)))]
            structs[name] = {"type_name": name, "fields": [field(n, d) for n, d in fields]}
        return structs[name]

    top = struct(type_name)
    return {
        "type_description": top,
        "referenced_type_descriptions": [s for n, s in sorted(structs.items()) if n != type_name],
    }


def rihs01(description: dict[str, Any]) -> str:
    """The RIHS01 hash of a description from :func:`describe`."""
    return f"RIHS01_{hashlib.sha256(json.dumps(description).encode()).hexdigest()}"


def to_message(description: dict[str, Any]) -> Any:
    """A ``type_description_interfaces/msg/TypeDescription`` of a :func:`describe` result."""
    ns = "type_description_interfaces/msg/"
    td_cls, itd_cls = get_message(ns + "TypeDescription"), get_message(ns + "IndividualTypeDescription")
    field_cls, ft_cls = get_message(ns + "Field"), get_message(ns + "FieldType")

    def individual(s: dict[str, Any]) -> Any:
        return itd_cls(type_name=s["type_name"], fields=[
            field_cls(name=f["name"], type=ft_cls(**f["type"]), default_value="")
            for f in s["fields"]])

    return td_cls(type_description=individual(description["type_description"]),
                  referenced_type_descriptions=[
                      individual(s) for s in description["referenced_type_descriptions"]])


def _sources(type_name: str, service: bool) -> list[Any]:
    """TypeSource entries (encoding ``msg``) for the type and the messages it uses."""
    source_cls = get_message("type_description_interfaces/msg/TypeSource")
    names = [f"{type_name}_Request", f"{type_name}_Response"] if service else [type_name]
    out: list[Any] = []
    seen: set[str] = set()
    for name in names:
        blocks = message_definition(name).split("=" * 80 + "\n")
        for i, block in enumerate(blocks):
            if i == 0:
                full, text = name, block
            else:
                head, _, text = block.partition("\n")
                pkg, _, short = head.removeprefix("MSG: ").partition("/")
                full = f"{pkg}/msg/{short}"
            if full not in seen:
                seen.add(full)
                out.append(source_cls(type_name=full, encoding="msg", raw_file_contents=text))
    return out


class TypeDescriptionService:
    """``~/get_type_description`` (type_description_interfaces/srv/GetTypeDescription)."""

    def __init__(self, node: Node) -> None:
        self.node = node
        self.srv_type = get_service("type_description_interfaces/srv/GetTypeDescription")
        self.service: Service = node.create_service(self.srv_type, SERVICE_NAME, self._answer)

    def types_in_use(self) -> dict[str, bool]:
        """Type name → is a service type, of every entity of the node."""
        node = self.node
        used = {p.type_name: False for p in node.publishers}
        used.update({s.type_name: False for s in node.subscriptions})
        used.update({s.srv_type.name: True for s in node.services})
        used.update({c.srv_type.name: True for c in node.clients})
        return used

    def _describe(self, type_name: str, service: bool) -> dict[str, Any]:
        load_type(type_name, "service" if service else "message")
        defs = service_fielddefs(TYPESTORE.fielddefs, type_name) if service else TYPESTORE.fielddefs
        return describe(defs, type_name)

    def _answer(self, request: Any, response: Any) -> Any:
        if not _HASH_RE.match(request.type_hash):
            response.successful = False
            response.failure_reason = "Failed to parse type hash"
            return response
        for type_name, service in self.types_in_use().items():
            try:
                description = self._describe(type_name, service)
            except Exception:  # a raw subscription of a type nothing here describes
                continue
            if rihs01(description) != request.type_hash:
                continue
            response.successful = True
            response.type_description = to_message(description)
            if request.include_type_sources:
                response.type_sources = _sources(type_name, service)
            return response
        response.successful = False
        response.failure_reason = "Type not currently in use by this node"
        return response
