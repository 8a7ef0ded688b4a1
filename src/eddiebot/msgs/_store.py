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

import ast
import hashlib
import json
import os
import re
import threading
from dataclasses import dataclass
from importlib import resources
from typing import Any

import numpy as np
from rosbags.interfaces import Nodetype
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import TIDMAP, Typestore

from eddiebot.msgs._paths import INTERFACE_PATH_ENV, find_interface_file, searched_description
from eddiebot.msgs.errors import UnknownTypeError

# "byte" is int8 because that is what the rosbags CDR codec decodes it to (numpy "byte").
_NUMPY_DTYPES = {
    "bool": np.bool_,
    "byte": np.int8,
    "char": np.uint8,
    "int8": np.int8,
    "uint8": np.uint8,
    "int16": np.int16,
    "uint16": np.uint16,
    "int32": np.int32,
    "uint32": np.uint32,
    "int64": np.int64,
    "uint64": np.uint64,
    "float32": np.float32,
    "float64": np.float64,
}
_PY_DEFAULTS: dict[str, Any] = {"bool": False, "string": "", "wstring": ""}


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


def _split_srv(text: str) -> tuple[str, str]:
    parts = _sections(text)
    if len(parts) != 2:
        raise ValueError(f"a .srv needs exactly one '---' separator, found {len(parts) - 1}")
    return parts[0], parts[1]


def _sections(text: str) -> list[str]:
    out: list[list[str]] = [[]]
    for line in text.splitlines():
        if line.strip() == "---":
            out.append([])
        else:
            out[-1].append(line)
    return ["\n".join(lines) + "\n" for lines in out]


def _interface_files() -> list[tuple[str, str, str, str]]:
    """(package, kind, name, text) of every shipped interface file."""
    root = resources.files("eddiebot.msgs") / "interfaces"
    found = []
    for pkg in sorted(root.iterdir(), key=lambda p: p.name):
        if not pkg.is_dir():
            continue
        for kind in ("msg", "srv", "action"):
            folder = pkg / kind
            if not folder.is_dir():
                continue
            for f in sorted(folder.iterdir(), key=lambda p: p.name):
                if f.name.endswith(f".{kind}"):
                    found.append((pkg.name, kind, f.name[: -len(kind) - 1], f.read_text()))
    return found


def _parse_interface(
    pkg: str, kind: str, name: str, text: str
) -> tuple[dict[str, Any], str | None, str | None]:
    """The message types of one interface file (services and actions split as rosidl does),
    with the service or action name it defines (if any)."""
    full = f"{pkg}/{kind}/{name}"
    typs: dict[str, Any] = {}
    if kind == "msg":
        typs.update(get_types_from_msg(text, full))
        _FILE_DEFAULTS[full] = _field_defaults(text)
    elif kind == "srv":
        req, res = _split_srv(text)
        typs.update(get_types_from_msg(req, f"{full}_Request"))
        typs.update(get_types_from_msg(res, f"{full}_Response"))
        _FILE_DEFAULTS[f"{full}_Request"] = _field_defaults(req)
        _FILE_DEFAULTS[f"{full}_Response"] = _field_defaults(res)
    else:
        sections = _sections(text)
        if len(sections) != 3:
            raise ValueError(f"{full}.action needs two '---' separators")
        goal, result, feedback = sections
        for suffix, part in zip(("_Goal", "_Result", "_Feedback"), sections):
            _FILE_DEFAULTS[f"{full}{suffix}"] = _field_defaults(part)
        typs.update(get_types_from_msg(goal, f"{full}_Goal"))
        typs.update(get_types_from_msg(result, f"{full}_Result"))
        typs.update(get_types_from_msg(feedback, f"{full}_Feedback"))
        uuid = "unique_identifier_msgs/UUID goal_id\n"
        typs.update(
            get_types_from_msg(uuid + f"{pkg}/{name}_Goal goal\n", f"{full}_SendGoal_Request")
        )
        typs.update(
            get_types_from_msg(
                "bool accepted\nbuiltin_interfaces/Time stamp\n", f"{full}_SendGoal_Response"
            )
        )
        typs.update(get_types_from_msg(uuid, f"{full}_GetResult_Request"))
        typs.update(
            get_types_from_msg(
                f"int8 status\n{pkg}/{name}_Result result\n", f"{full}_GetResult_Response"
            )
        )
        typs.update(
            get_types_from_msg(
                uuid + f"{pkg}/{name}_Feedback feedback\n", f"{full}_FeedbackMessage"
            )
        )
    # get_types_from_msg resolves "pkg/Name" references as pkg/msg/Name; action sub-types live
    # under pkg/action/, so point those references at the right names.
    # get_types_from_msg also files pkg/srv/X_Request under pkg/srv/msg/; undo that.
    typs = {k.replace("/srv/msg/", "/srv/"): _fix_action_refs(v) for k, v in typs.items()}
    return typs, full if kind == "srv" else None, full if kind == "action" else None


#: Default values written in interface files: type name → field → value (primitives only).
_FILE_DEFAULTS: dict[str, dict[str, Any]] = {}

_DEFAULT_LINE = re.compile(
    r"^\s*(?P<type>[A-Za-z][\w/]*)\s+(?P<field>[a-z]\w*)\s+(?P<value>[^#=\s][^#]*?)\s*(#.*)?$"
)


def _field_defaults(text: str) -> dict[str, Any]:
    """``field → value`` for the primitive fields of one message text that give a default
    (``bool include_type_sources true``); arrays and nested messages keep theirs."""
    out: dict[str, Any] = {}
    for line in text.splitlines():
        m = _DEFAULT_LINE.match(line)
        if m is None:
            continue
        typ, literal = m.group("type"), m.group("value").strip()
        if typ == "bool":
            value: Any = {"true": True, "false": False, "1": True, "0": False}.get(literal.lower())
        elif typ in ("string", "wstring") or typ.startswith(("string<", "wstring<")):
            value = ast.literal_eval(literal) if literal[:1] in "'\"" else literal
        elif typ.startswith("float"):
            value = float(literal)
        elif typ in _NUMPY_DTYPES:
            value = int(literal, 0)
        else:
            continue
        if value is not None:
            out[m.group("field")] = value
    return out


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


def _fix_action_refs(entry: Any) -> Any:
    consts, fields = entry

    def fix(desc: Any) -> Any:
        kind, detail = desc
        if kind == Nodetype.NAME:
            # A bare "Name" inside pkg/srv/X or pkg/action/X comes back as pkg/srv/msg/Name or
            # pkg/action/Name; rosidl resolves it as pkg/msg/Name.
            head, _, name = detail.rpartition("/")
            pkg = head.split("/", 1)[0]
            if name.endswith(("_Goal", "_Result", "_Feedback")):
                return (kind, f"{pkg}/action/{name}")
            return (kind, f"{pkg}/msg/{name}")
        if kind in (Nodetype.ARRAY, Nodetype.SEQUENCE):
            inner, size = detail
            return (kind, (fix(inner), size))
        return desc

    return (consts, [(fname, fix(desc)) for fname, desc in fields])


def _default_factory(store: Typestore, desc: Any) -> Any:
    kind, detail = desc
    if kind == Nodetype.BASE:
        typ = detail[0]
        if typ in _PY_DEFAULTS:
            value = _PY_DEFAULTS[typ]
            return lambda: value
        if typ.startswith("float"):
            return float
        return int
    if kind == Nodetype.NAME:
        return lambda: store.types[detail]()
    inner, size = detail
    inner_kind, inner_detail = inner
    if inner_kind == Nodetype.BASE and inner_detail[0] in _NUMPY_DTYPES:
        dtype = _NUMPY_DTYPES[inner_detail[0]]
        n = size if kind == Nodetype.ARRAY else 0
        return lambda: np.zeros(n, dtype=dtype)
    if kind == Nodetype.ARRAY:
        elem = _default_factory(store, inner)
        return lambda: [elem() for _ in range(size)]
    return list


def _immutable_default(desc: Any) -> tuple[bool, Any]:
    """(True, value) when a field's default is an immutable constant (numbers, strings)."""
    kind, detail = desc
    if kind != Nodetype.BASE:
        return False, None
    typ = detail[0]
    if typ in _PY_DEFAULTS:
        return True, _PY_DEFAULTS[typ]
    return True, 0.0 if typ.startswith("float") else 0


_MISSING = object()


def _add_defaults(store: Typestore, cls: Any) -> None:
    """Give ``cls.__init__`` a default for every field.

    A specialised ``__init__`` is generated per class: constants go straight into the
    signature and only mutable defaults (nested messages, arrays) call a factory, so a
    default-filled ``Twist()`` costs about as much as the plain dataclass call.
    """
    if getattr(cls, "_eddie_defaults", False):
        return
    name = cls.__msgtype__
    _, fields = store.fielddefs[name]
    if not fields:
        cls._eddie_defaults = True
        return
    namespace: dict[str, Any] = {"_orig": cls.__init__, "_M": _MISSING}
    params, args = [], []
    written = _FILE_DEFAULTS.get(name, {})
    for i, (fname, desc) in enumerate(fields):
        constant, value = _immutable_default(desc)
        if constant and fname in written:
            value = written[fname]
        if constant:
            namespace[f"_c{i}"] = value
            params.append(f"{fname}=_c{i}")
            args.append(fname)
        else:
            namespace[f"_f{i}"] = _default_factory(store, desc)
            params.append(f"{fname}=_M")
            args.append(f"_f{i}() if {fname} is _M else {fname}")
    code = (
        f"def __init__(self, {', '.join(params)}):\n"
        f"    _orig(self, {', '.join(args)})\n"
    )
    exec(code, namespace)
    init = namespace["__init__"]
    init.__qualname__ = f"{cls.__name__}.__init__"
    init.__doc__ = cls.__init__.__doc__
    cls.__init__ = init
    cls._eddie_defaults = True


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


# -- types described by a publisher (REP-2016 TypeDescription, ~/get_type_description) ------
#: FieldType ids (type_description_interfaces/msg/FieldType) → rosbags base type names
_FIELD_TYPES = {tid: name for name, tid in TIDMAP.items() if not name.startswith("bounded_")}
_FIELD_TYPES[14], _FIELD_TYPES[18] = "wchar", "wstring"
_EMPTY_MEMBER = "structure_needs_at_least_one_member"


def _field_desc(where: str, ft: Any) -> Any:
    """The rosbags field description of one ``FieldType``."""
    group, base = divmod(int(ft.type_id), 48)
    if base == 1:
        if not ft.nested_type_name:
            raise ValueError(f"{where}: a nested field without nested_type_name")
        inner: Any = (Nodetype.NAME, normalize_type_name(str(ft.nested_type_name)))
    elif base in (21, 22):
        inner = (Nodetype.BASE, ("string" if base == 21 else "wstring", int(ft.string_capacity)))
    elif base in _FIELD_TYPES and group < 4:
        inner = (Nodetype.BASE, (_FIELD_TYPES[base], 0))
    else:
        raise ValueError(f"{where}: unsupported field type id {ft.type_id}")
    if group == 0:
        return inner
    if group == 1:
        return (Nodetype.ARRAY, (inner, int(ft.capacity)))
    return (Nodetype.SEQUENCE, (inner, int(ft.capacity) if group == 2 else 0))


def _fields_of(individual: Any) -> Any:
    """``(constants, fields)`` of one ``IndividualTypeDescription`` (it carries no constants)."""
    fields = [(str(f.name), _field_desc(f"{individual.type_name}.{f.name}", f.type))
              for f in individual.fields]
    if [name for name, _ in fields] == [_EMPTY_MEMBER]:
        fields = []  # REP-2016 gives an empty message this one placeholder member
    return ([], fields)


def _description_hash(description: Any) -> str:
    """The RIHS01 hash of a ``TypeDescription`` message as it was received (REP-2016: the
    JSON of its type names and fields, referenced types sorted by name)."""
    def struct(s: Any) -> dict[str, Any]:
        return {"type_name": str(s.type_name), "fields": [
            {"name": str(f.name), "type": {
                "type_id": int(f.type.type_id), "capacity": int(f.type.capacity),
                "string_capacity": int(f.type.string_capacity),
                "nested_type_name": str(f.type.nested_type_name)}}
            for f in s.fields]}

    refs = sorted(description.referenced_type_descriptions, key=lambda s: str(s.type_name))
    data = {"type_description": struct(description.type_description),
            "referenced_type_descriptions": [struct(s) for s in refs]}
    return f"RIHS01_{hashlib.sha256(json.dumps(data).encode()).hexdigest()}"


def _definitions(description: Any, texts: dict[str, str]
                 ) -> tuple[dict[str, Any], dict[str, dict[str, Any]]]:
    """Parsed definitions (and file defaults) of the description's types this store lacks:
    from their ``msg`` source in ``texts`` when it parses, else from the description."""
    typs: dict[str, Any] = {}
    defaults: dict[str, dict[str, Any]] = {}
    for individual in (description.type_description, *description.referenced_type_descriptions):
        name = normalize_type_name(str(individual.type_name))
        if name in TYPESTORE.fielddefs or name in typs:
            continue
        parsed: dict[str, Any] = {}
        if name in texts:
            try:
                parsed = get_types_from_msg(texts[name], name)
            except Exception:  # the description's fields describe it too
                parsed = {}
        if len(parsed) == 1:
            typs[name] = _fix_action_refs(next(iter(parsed.values())))
            defaults[name] = _field_defaults(texts[name])
        else:
            typs[name] = _fields_of(individual)
    return typs, defaults


def _hash_with(typs: dict[str, Any], full: str) -> str:
    """The RIHS01 hash of ``full`` were ``typs`` registered (nothing is registered)."""
    scratch = Typestore()
    scratch.fielddefs.update(TYPESTORE.fielddefs)
    scratch.fielddefs.update(typs)
    try:
        return scratch.hash_rihs01(full)
    except KeyError as exc:
        raise ValueError(f"the description of {full} does not describe {exc}") from None


def register_type_description(type_name: str, rihs01: str, description: Any,
                              sources: Any = ()) -> list[str]:
    """Register message type ``type_name`` and the types it uses from a REP-2016 description,
    as a publisher's ``~/get_type_description`` answers it, and return the names registered.

    ``description`` is a ``type_description_interfaces/msg/TypeDescription``; ``sources``
    its ``TypeSource`` list: a type with an ``msg`` source is read from that text (so its
    constants and default values come too), any other from the description's fields, and
    all from the fields when the sources do not hash as the description does. Types this
    store already has keep their definition. The description, and the definitions
    about to be registered, must both hash to ``rihs01`` (the hash the publisher announces),
    else ``ValueError`` says which does not and nothing is registered. A type already known
    under another hash is refused the same way.
    """
    full = normalize_type_name(type_name)
    top = normalize_type_name(str(description.type_description.type_name))
    if top != full:
        raise ValueError(f"the description is of {top}, not of {full}")
    got = _description_hash(description)
    if got != rihs01:
        raise ValueError(f"the description of {full} hashes to {got}, not to the "
                         f"publisher's {rihs01}")
    with _LOAD_LOCK:
        if _known(full):
            have = TYPESTORE.hash_rihs01(full)
            if have != rihs01:
                raise ValueError(f"{full} is known here as {have}, not as the publisher's "
                                 f"{rihs01}")
            return []
        texts = {normalize_type_name(str(s.type_name)): str(s.raw_file_contents)
                 for s in sources if str(s.encoding) == "msg"}
        typs, defaults = _definitions(description, texts)
        ours = _hash_with(typs, full)
        if ours != rihs01 and texts:
            # sources another parser reads otherwise (a .msg ``char`` is IDL uint8 to rosidl,
            # not rosbags' char): the hashed description's fields alone still decode
            typs, defaults = _definitions(description, {})
            if _hash_with(typs, full) == rihs01:
                ours = rihs01
        if ours != rihs01:
            differ = [str(i.type_name) for i in description.referenced_type_descriptions
                      if normalize_type_name(str(i.type_name)) in TYPESTORE.fielddefs
                      and _fields_of(i)[1] != TYPESTORE.fielddefs[
                          normalize_type_name(str(i.type_name))][1]]
            if differ:
                raise ValueError(f"{full} uses {', '.join(differ)} of another definition than "
                                 f"the one known here")
            raise ValueError(f"the definitions given for {full} hash to {ours}, not to the "
                             f"publisher's {rihs01}")
        try:
            TYPESTORE.register(typs)
        except Exception as exc:
            raise ValueError(f"cannot register {full}: {exc}") from None
        _FILE_DEFAULTS.update(defaults)
        for name in typs:
            _add_defaults(TYPESTORE, TYPESTORE.types[name])
        return sorted(typs)


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
