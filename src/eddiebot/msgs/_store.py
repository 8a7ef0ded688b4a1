"""The one type store: ROS 2 Jazzy messages from rosbags plus the interfaces shipped here.

Services and actions are split into plain messages as rosidl does, so that every
request, response, goal, result and feedback serializes exactly as in ROS 2:

- ``pkg/srv/X`` → ``pkg/srv/X_Request`` and ``pkg/srv/X_Response``;
- ``pkg/action/X`` → ``X_Goal``, ``X_Result``, ``X_Feedback``, ``X_SendGoal_Request``,
  ``X_SendGoal_Response``, ``X_GetResult_Request``, ``X_GetResult_Response`` and
  ``X_FeedbackMessage``.

Every generated class is given defaults for every field (zero numbers, empty strings,
zero-filled fixed arrays, empty sequences, default nested messages), so ``Twist()`` or
``Odometry(child_frame_id="base_footprint")`` is a complete message. A primitive field with a
default value in its interface file (``bool include_type_sources true``) takes that value,
as rosidl's generated classes do.
"""

from __future__ import annotations

import os
import threading
from dataclasses import dataclass
from typing import Any

from rosbags.interfaces import Nodetype
from rosbags.typesys import Stores, get_typestore
from rosbags.typesys.store import Typestore

from eddiebot.msgs._defaults import _add_defaults
from eddiebot.msgs._interfaces import _interface_files, _parse_interface
from eddiebot.msgs._paths import INTERFACE_PATH_ENV, find_interface_file, searched_description
from eddiebot.msgs.errors import UnknownTypeError


@dataclass(frozen=True)
class ServiceType:
    """A service interface: ``name`` is ``pkg/srv/X``; ``Request``/``Response`` are classes."""

    name: str
    Request: Any
    Response: Any

    def __repr__(self) -> str:
        return f"ServiceType({self.name})"


@dataclass(frozen=True)
class ActionType:
    """An action interface with rosidl's generated sub-types."""

    name: str
    Goal: Any
    Result: Any
    Feedback: Any
    SendGoal: ServiceType
    GetResult: ServiceType
    FeedbackMessage: Any

    def __repr__(self) -> str:
        return f"ActionType({self.name})"


def _service_type(store: Typestore, n: str) -> ServiceType:
    return ServiceType(n, store.types[f"{n}_Request"], store.types[f"{n}_Response"])


def _action_type(store: Typestore, n: str) -> ActionType:
    return ActionType(
        n,
        store.types[f"{n}_Goal"],
        store.types[f"{n}_Result"],
        store.types[f"{n}_Feedback"],
        ServiceType(
            f"{n}_SendGoal",
            store.types[f"{n}_SendGoal_Request"],
            store.types[f"{n}_SendGoal_Response"],
        ),
        ServiceType(
            f"{n}_GetResult",
            store.types[f"{n}_GetResult_Request"],
            store.types[f"{n}_GetResult_Response"],
        ),
        store.types[f"{n}_FeedbackMessage"],
    )


def _build() -> tuple[Typestore, dict[str, ServiceType], dict[str, ActionType]]:
    store = get_typestore(Stores.ROS2_JAZZY)
    typs: dict[str, Any] = {}
    srv_names: list[str] = []
    action_names: list[str] = []
    for pkg, kind, name, text in _interface_files():
        found, srv, action = _parse_interface(pkg, kind, name, text)
        typs.update(found)
        srv_names += [srv] if srv else []
        action_names += [action] if action else []
    store.register(typs)
    for cls in store.types.values():
        _add_defaults(store, cls)
    services = {n: _service_type(store, n) for n in srv_names}
    actions = {n: _action_type(store, n) for n in action_names}
    return store, services, actions


TYPESTORE, SERVICES, ACTIONS = _build()

# -- types described by interface files on the search path (see _paths) -------------------
_ACTION_SUFFIXES = (
    "_SendGoal_Request", "_SendGoal_Response", "_GetResult_Request", "_GetResult_Response",
    "_FeedbackMessage", "_SendGoal", "_GetResult", "_Goal", "_Result", "_Feedback",
)
_SRV_SUFFIXES = ("_Request", "_Response")
_LOAD_LOCK = threading.RLock()
#: (type, search path) → the error of a look-up that found nothing (no repeated walks).
_MISSES: dict[tuple[str, str], UnknownTypeError] = {}


def _interface_of(full: str) -> tuple[str, str, str] | None:
    """(pkg, kind, file name) of the interface file describing message type ``full``."""
    parts = full.split("/")
    if len(parts) != 3 or not all(parts):
        return None
    pkg, kind, name = parts
    suffixes = {"srv": _SRV_SUFFIXES, "action": _ACTION_SUFFIXES}.get(kind, ())
    if kind not in ("msg", "srv", "action"):
        return None
    for suffix in suffixes:
        if name.endswith(suffix) and len(name) > len(suffix):
            return pkg, kind, name[: -len(suffix)]
    return pkg, kind, name


def _references(entry: Any) -> list[str]:
    """Names of the message types the fields of one parsed type refer to."""
    out = []
    for _, desc in entry[1]:
        kind, detail = desc
        while kind in (Nodetype.ARRAY, Nodetype.SEQUENCE):
            kind, detail = detail[0]
        if kind == Nodetype.NAME:
            out.append(detail)
    return out


def _search_key() -> str:
    return os.environ.get(INTERFACE_PATH_ENV, "") + "\0" + os.environ.get("AMENT_PREFIX_PATH", "")


def _known(full: str) -> bool:
    # a message, a service, an action, or an action's SendGoal/GetResult service
    return (full in TYPESTORE.fielddefs or full in SERVICES or full in ACTIONS
            or f"{full}_Request" in TYPESTORE.fielddefs)


def load_type(full: str, kind: str = "message") -> None:
    """Register the interface describing ``full`` (``pkg/msg/X``, ``pkg/srv/X[_Request]``,
    ``pkg/action/X[_Goal]``, ...) and everything it uses, from the interface files on the
    search path (``EDDIE_INTERFACE_PATH``, ``AMENT_PREFIX_PATH``). A no-op for a known type.

    Raises ``UnknownTypeError`` (saying where it looked and how to add the type) when no
    file describes it or one of the types it uses.
    """
    if _known(full):
        return
    with _LOAD_LOCK:
        if _known(full):
            return
        key = (full, _search_key())
        if key in _MISSES:
            raise _MISSES[key]
        try:
            _load_locked(full, kind)
        except UnknownTypeError as exc:
            _MISSES[key] = exc
            raise


def _load_locked(full: str, kind: str) -> None:
    typs: dict[str, Any] = {}
    services: list[str] = []
    actions: list[str] = []
    loaded: set[tuple[str, str, str]] = set()
    pending = [full]
    while pending:
        wanted = pending.pop()
        if wanted in TYPESTORE.fielddefs or wanted in typs:
            continue
        iface = _interface_of(wanted)
        path = find_interface_file(*iface) if iface is not None else None
        if iface is None or path is None:
            what = f"{iface[0]}/{iface[1]}/{iface[2]}.{iface[1]}" if iface else wanted
            used = "" if wanted == full else f"it uses {wanted}, and "
            raise UnknownTypeError(full, kind, (
                f"{used}no {what} found ({searched_description()}); add a folder holding "
                f"{what} to {INTERFACE_PATH_ENV}"
            ))
        if iface in loaded:  # read already, and it does not define this name
            raise UnknownTypeError(full, kind, f"{path} does not define {wanted}")
        loaded.add(iface)
        try:
            found, srv, action = _parse_interface(*iface, path.read_text())
        except Exception as exc:
            raise UnknownTypeError(full, kind, f"{path} does not parse: {exc}") from None
        if wanted not in found and wanted not in (srv, action) and f"{wanted}_Request" not in found:
            raise UnknownTypeError(full, kind, f"{path} does not define {wanted}")
        typs.update(found)
        services += [srv] if srv else []
        actions += [action] if action else []
        for entry in found.values():
            pending += [r for r in _references(entry)
                        if r not in TYPESTORE.fielddefs and r not in typs]
    try:
        TYPESTORE.register(typs)
    except Exception as exc:
        raise UnknownTypeError(full, kind, f"cannot register its definition: {exc}") from None
    for name in typs:
        _add_defaults(TYPESTORE, TYPESTORE.types[name])
    for n in services:
        SERVICES[n] = _service_type(TYPESTORE, n)
    for n in actions:
        ACTIONS[n] = _action_type(TYPESTORE, n)


def raw_message_type(name: str, rihs01: str | None = None) -> type:
    """A stand-in class for message type ``name`` that nothing here describes.

    It names the type (and ``rihs01``, the hash its publishers announce) so that a *raw*
    subscription can take its samples as CDR bytes (``hz``, ``bw``, ``record``); it has no
    fields and cannot be serialized or decoded.
    """
    full = normalize_type_name(name)
    return type(full.rsplit("/", 1)[-1], (), {
        "__msgtype__": full, "__rihs01__": rihs01, "__doc__": f"{full}, undescribed here",
    })


def get_message(name: str) -> Any:
    """The class of message type ``pkg/msg/Name`` (also accepts ``pkg/Name``)."""
    full = normalize_type_name(name)
    try:
        return TYPESTORE.types[full]
    except KeyError:
        load_type(full)
        return TYPESTORE.types[full]


def get_service(name: str) -> ServiceType:
    """The service type ``pkg/srv/Name`` (also ``pkg/Name``)."""
    full = name if "/srv/" in name else name.replace("/", "/srv/", 1)
    try:
        return SERVICES[full]
    except KeyError:
        load_type(full, "service")
    if full not in SERVICES:  # pkg/srv/X_Request: a message of the service, not one
        raise UnknownTypeError(name, "service")
    return SERVICES[full]


def get_action(name: str) -> ActionType:
    """The action type ``pkg/action/Name`` (also ``pkg/Name``)."""
    full = name if "/action/" in name else name.replace("/", "/action/", 1)
    try:
        return ACTIONS[full]
    except KeyError:
        load_type(full, "action")
    if full not in ACTIONS:
        raise UnknownTypeError(name, "action")
    return ACTIONS[full]


def normalize_type_name(name: str) -> str:
    """``pkg/Name`` → ``pkg/msg/Name``; full names are returned unchanged."""
    if name.count("/") == 1:
        pkg, base = name.split("/")
        return f"{pkg}/msg/{base}"
    return name


def type_name(msg_or_cls: Any) -> str:
    """The ROS 2 type name of a message instance or class, e.g. ``geometry_msgs/msg/Twist``."""
    try:
        return str(msg_or_cls.__msgtype__)
    except AttributeError:
        raise TypeError(f"{type(msg_or_cls).__name__} is not a ROS 2 message type") from None


def serialize(msg: Any, typename: str | None = None) -> bytes:
    """ROS 2 CDR (little-endian, with encapsulation header) of ``msg``."""
    full = typename or type_name(msg)
    load_type(full)
    return bytes(TYPESTORE.serialize_cdr(msg, full))


def deserialize(data: bytes | memoryview, typename: str) -> Any:
    """Decode ROS 2 CDR bytes as ``typename``."""
    full = normalize_type_name(typename)
    load_type(full)
    return TYPESTORE.deserialize_cdr(data, full)


def type_hash(typename: str) -> str:
    """The RIHS01 type hash of a message type, as ROS 2 Iron+ and rmw_zenoh use it."""
    full = normalize_type_name(typename)
    load_type(full)
    return TYPESTORE.hash_rihs01(full)


def message_definition(typename: str) -> str:
    """The full .msg text of a type with its dependencies, as rosbag2 stores it."""
    full = normalize_type_name(typename)
    load_type(full)
    text, _ = TYPESTORE.generate_msgdef(full, ros_version=2)
    return text


def package_namespace(pkg: str) -> dict[str, Any]:
    """Every message, service and action class of ``pkg`` under its short name."""
    out: dict[str, Any] = {}
    for full, cls in TYPESTORE.types.items():
        p, kind, name = full.split("/", 2)
        if p == pkg and kind == "msg":
            out[name] = cls
    for full, srv in SERVICES.items():
        if full.startswith(f"{pkg}/"):
            out[full.rsplit("/", 1)[1]] = srv
    for full, act in ACTIONS.items():
        if full.startswith(f"{pkg}/"):
            out[full.rsplit("/", 1)[1]] = act
    return out
