"""Helpers for the message tests: sample values per field type and deep comparison."""

from __future__ import annotations

from typing import Any

import numpy as np
from rosbags.interfaces import Nodetype

from eddiebot.msgs import TYPESTORE

NUMPY_DTYPES: dict[str, Any] = {
    "bool": np.bool_,
    "byte": np.int8,  # as the rosbags codec decodes it
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

# Non-default scalar samples, exactly representable in their wire type.
_SCALARS: dict[str, Any] = {
    "bool": True,
    "byte": -85,
    "char": 0x41,
    "int8": -7,
    "uint8": 200,
    "int16": -1234,
    "uint16": 54321,
    "int32": -123456,
    "uint32": 3_000_000_000,
    "int64": -(2**40) - 3,
    "uint64": 2**63 + 5,
    "float32": 1.5,
    "float64": -2.25,
}


def fields(typename: str) -> list[tuple[str, Any]]:
    return list(TYPESTORE.fielddefs[typename][1])


def constants(typename: str) -> list[tuple[str, str, Any]]:
    return list(TYPESTORE.fielddefs[typename][0])


def sample_message(typename: str, depth: int = 0) -> Any:
    """An instance of ``typename`` with every field set to a non-default value."""
    cls = TYPESTORE.types[typename]
    kwargs = {name: _sample(desc, depth) for name, desc in fields(typename)}
    return cls(**kwargs)


def _sample(desc: Any, depth: int) -> Any:
    kind, detail = desc
    if kind == Nodetype.BASE:
        typ, bound = detail
        if typ in ("string", "wstring"):
            text = "héllo" if typ == "wstring" else "hello/eddie"
            return text[:bound] if bound else text
        return _SCALARS[typ]
    if kind == Nodetype.NAME:
        return sample_message(detail, depth + 1)
    inner, size = detail
    n = size if kind == Nodetype.ARRAY else (min(2, size) if size else 2)
    if depth > 3 and kind == Nodetype.SEQUENCE:
        n = 0  # keep deeply nested sequences small
    inner_kind, inner_detail = inner
    if inner_kind == Nodetype.BASE and inner_detail[0] in NUMPY_DTYPES:
        dtype = NUMPY_DTYPES[inner_detail[0]]
        if dtype is np.bool_:
            return np.array([i % 2 == 0 for i in range(n)], dtype=dtype)
        return np.array([_SCALARS[inner_detail[0]]] * n, dtype=dtype) - np.arange(n, dtype=dtype)
    return [_sample(inner, depth + 1) for _ in range(n)]


def assert_equal(a: Any, b: Any, typename: str, path: str = "") -> None:
    """Field-by-field equality of two messages of ``typename`` (numpy arrays included)."""
    assert a.__msgtype__ == b.__msgtype__ == typename, path
    for name, desc in fields(typename):
        _assert_value(getattr(a, name), getattr(b, name), desc, f"{path}.{name}")


def _assert_value(x: Any, y: Any, desc: Any, path: str) -> None:
    kind, detail = desc
    if kind == Nodetype.BASE:
        assert type(x) is type(y) or {type(x), type(y)} <= {int, bool}, path
        assert x == y, f"{path}: {x!r} != {y!r}"
        return
    if kind == Nodetype.NAME:
        assert_equal(x, y, detail, path)
        return
    inner, _ = detail
    if isinstance(x, np.ndarray) or isinstance(y, np.ndarray):
        assert isinstance(x, np.ndarray), path
        assert isinstance(y, np.ndarray), path
        assert x.dtype == y.dtype, f"{path}: {x.dtype} != {y.dtype}"
        np.testing.assert_array_equal(x, y, err_msg=path)
        return
    assert len(x) == len(y), path
    for i, (xi, yi) in enumerate(zip(x, y)):
        _assert_value(xi, yi, inner, f"{path}[{i}]")
