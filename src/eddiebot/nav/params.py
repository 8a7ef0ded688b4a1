"""Loading typed config dataclasses from ROS-style parameter dicts, with named errors.

Every config dataclass in ``eddiebot.nav`` carries upstream parameter names and the node's
code defaults. :func:`from_params` builds one from a ``ros__parameters`` dict (unknown keys are
ignored, as ROS 2 ignores undeclared overrides), coercing ints to floats and lists to tuples,
and raises :class:`~eddiebot.nav.errors.ParameterError` naming server, key and value.
"""

from __future__ import annotations

import dataclasses
import types
import typing
from collections.abc import Callable, Mapping
from typing import Any, TypeVar

from eddiebot.nav.errors import ParameterError

T = TypeVar("T")


def _coerce(server: str, key: str, value: Any, hint: Any) -> Any:
    origin = typing.get_origin(hint)
    args = typing.get_args(hint)
    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        for a in args:
            if a is type(None):
                continue
            try:
                return _coerce(server, key, value, a)
            except ParameterError:
                continue
        raise ParameterError(server, key, value, f"expected {hint}")
    if hint is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ParameterError(server, key, value, "expected a number")
        return float(value)
    if hint is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ParameterError(server, key, value, "expected an integer")
        return value
    if hint is bool:
        if not isinstance(value, bool):
            raise ParameterError(server, key, value, "expected true/false")
        return value
    if hint is str:
        if not isinstance(value, str):
            raise ParameterError(server, key, value, "expected a string")
        return value
    if origin is tuple:
        if not isinstance(value, (list, tuple)):
            raise ParameterError(server, key, value, "expected a list")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_coerce(server, key, v, args[0]) for v in value)
        if len(args) != len(value):
            raise ParameterError(server, key, value, f"expected {len(args)} entries")
        return tuple(_coerce(server, key, v, a) for v, a in zip(value, args))
    return value


def from_params(
    cls: type[T],
    params: Mapping[str, Any] | None = None,
    *,
    server: str = "",
    validate: Callable[[T, str], None] | None = None,
) -> T:
    """Build config dataclass ``cls`` from ``params``; missing keys keep their defaults."""
    params = params or {}
    hints = typing.get_type_hints(cls)
    kwargs: dict[str, Any] = {}
    for f in dataclasses.fields(cls):  # type: ignore[arg-type]
        if f.name in params:
            kwargs[f.name] = _coerce(server or cls.__name__, f.name, params[f.name], hints[f.name])
    obj = cls(**kwargs)
    check = validate or getattr(obj, "validate", None)
    if check is not None:
        if validate is not None:
            validate(obj, server or cls.__name__)
        else:
            obj.validate(server or cls.__name__)  # type: ignore[attr-defined]
    return obj


def require(cond: bool, server: str, key: str, value: Any, reason: str) -> None:
    """Raise :class:`ParameterError` unless ``cond``."""
    if not cond:
        raise ParameterError(server, key, value, reason)


__all__ = ["from_params", "require"]
