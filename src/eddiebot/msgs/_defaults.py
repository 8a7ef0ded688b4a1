"""Default field values of the generated message classes: zero numbers, empty strings,
zero-filled fixed arrays, empty sequences, default nested messages, and the primitive
defaults written in interface files (``bool include_type_sources true``)."""

from __future__ import annotations

import ast
import re
from typing import Any

import numpy as np
from rosbags.interfaces import Nodetype
from rosbags.typesys.store import Typestore

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
