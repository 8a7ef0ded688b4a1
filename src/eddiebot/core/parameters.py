"""Typed parameters and ROS 2 parameter files.

A parameter's type is fixed by its declaration (as rclpy without dynamic typing), except
that an integer is accepted for a double parameter. Parameter files are ROS 2 YAML::

    /**:                      # every node
      ros__parameters: {use_sim_time: true}
    controller_server:        # a node by name (or /ns/name)
      ros__parameters:
        FollowPath: {desired_linear_vel: 0.4}   # nested keys become FollowPath.desired_linear_vel

Every value read from a file remembers ``file:line`` so errors can say where it came from.
"""

from __future__ import annotations

import enum
import fnmatch
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from eddiebot.core.errors import InvalidParameterTypeError, ParameterFileError


class ParameterType(enum.IntEnum):
    """rcl_interfaces/ParameterType values."""

    NOT_SET = 0
    BOOL = 1
    INTEGER = 2
    DOUBLE = 3
    STRING = 4
    BYTE_ARRAY = 5
    BOOL_ARRAY = 6
    INTEGER_ARRAY = 7
    DOUBLE_ARRAY = 8
    STRING_ARRAY = 9

    @classmethod
    def of(cls, value: Any) -> ParameterType:
        """The type a Python value maps to."""
        if value is None:
            return cls.NOT_SET
        if isinstance(value, bool):
            return cls.BOOL
        if isinstance(value, int):
            return cls.INTEGER
        if isinstance(value, float):
            return cls.DOUBLE
        if isinstance(value, str):
            return cls.STRING
        if isinstance(value, (bytes, bytearray)):
            return cls.BYTE_ARRAY
        if isinstance(value, (list, tuple)):
            if not value:
                return cls.STRING_ARRAY  # empty list: typed by its declaration
            if all(isinstance(v, bool) for v in value):
                return cls.BOOL_ARRAY
            if all(isinstance(v, int) and not isinstance(v, bool) for v in value):
                return cls.INTEGER_ARRAY
            if all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value):
                return cls.DOUBLE_ARRAY
            if all(isinstance(v, str) for v in value):
                return cls.STRING_ARRAY
        raise InvalidParameterTypeError(f"unsupported parameter value {value!r}")


_ARRAY_TYPES = {
    ParameterType.BOOL_ARRAY,
    ParameterType.INTEGER_ARRAY,
    ParameterType.DOUBLE_ARRAY,
    ParameterType.STRING_ARRAY,
    ParameterType.BYTE_ARRAY,
}


def coerce(value: Any, declared: ParameterType, *, name: str, where: str = "") -> Any:
    """``value`` converted to ``declared`` where ROS would accept it, else a typed error."""
    got = ParameterType.of(value)
    if declared == ParameterType.NOT_SET or got == declared:
        return list(value) if isinstance(value, tuple) else value
    if declared == ParameterType.DOUBLE and got == ParameterType.INTEGER:
        return float(value)
    if declared == ParameterType.DOUBLE_ARRAY and got == ParameterType.INTEGER_ARRAY:
        return [float(v) for v in value]
    if declared in _ARRAY_TYPES and isinstance(value, (list, tuple)) and not value:
        return []
    raise InvalidParameterTypeError(
        f"parameter {name!r} is declared {declared.name.lower()}, got {got.name.lower()} {value!r}",
        where=where,
    )


@dataclass(frozen=True)
class Parameter:
    """A named, typed value (rclpy's ``Parameter``)."""

    name: str
    value: Any = None
    type_: ParameterType | None = None

    @property
    def type(self) -> ParameterType:
        return self.type_ if self.type_ is not None else ParameterType.of(self.value)

    def to_msg(self) -> Any:
        from eddiebot.msgs.rcl_interfaces import Parameter as ParameterMsg

        return ParameterMsg(name=self.name, value=value_to_msg(self.value))


def value_to_msg(value: Any) -> Any:
    """Python value → rcl_interfaces/ParameterValue."""
    import numpy as np

    from eddiebot.msgs.rcl_interfaces import ParameterValue

    t = ParameterType.of(value)
    msg = ParameterValue(type=int(t))
    if t == ParameterType.BOOL:
        msg.bool_value = value
    elif t == ParameterType.INTEGER:
        msg.integer_value = value
    elif t == ParameterType.DOUBLE:
        msg.double_value = value
    elif t == ParameterType.STRING:
        msg.string_value = value
    elif t == ParameterType.BYTE_ARRAY:
        msg.byte_array_value = np.frombuffer(bytes(value), dtype=np.uint8).copy()
    elif t == ParameterType.BOOL_ARRAY:
        msg.bool_array_value = np.asarray(value, dtype=bool)
    elif t == ParameterType.INTEGER_ARRAY:
        msg.integer_array_value = np.asarray(value, dtype=np.int64)
    elif t == ParameterType.DOUBLE_ARRAY:
        msg.double_array_value = np.asarray(value, dtype=np.float64)
    elif t == ParameterType.STRING_ARRAY:
        msg.string_array_value = list(value)
    return msg


def value_from_msg(msg: Any) -> Any:
    """rcl_interfaces/ParameterValue → Python value."""
    t = ParameterType(msg.type)
    return {
        ParameterType.NOT_SET: lambda: None,
        ParameterType.BOOL: lambda: bool(msg.bool_value),
        ParameterType.INTEGER: lambda: int(msg.integer_value),
        ParameterType.DOUBLE: lambda: float(msg.double_value),
        ParameterType.STRING: lambda: str(msg.string_value),
        ParameterType.BYTE_ARRAY: lambda: bytes(bytearray(msg.byte_array_value)),
        ParameterType.BOOL_ARRAY: lambda: [bool(v) for v in msg.bool_array_value],
        ParameterType.INTEGER_ARRAY: lambda: [int(v) for v in msg.integer_array_value],
        ParameterType.DOUBLE_ARRAY: lambda: [float(v) for v in msg.double_array_value],
        ParameterType.STRING_ARRAY: lambda: [str(v) for v in msg.string_array_value],
    }[t]()


@dataclass(frozen=True)
class ParameterDescriptor:
    """What a declaration says of a parameter beyond its default."""

    description: str = ""
    read_only: bool = False
    dynamic_typing: bool = False
    #: inclusive (min, max) for numbers, None for no bound
    range: tuple[float, float] | None = None
    additional_constraints: str = ""


@dataclass(frozen=True)
class SetParametersResult:
    """What an on-set callback answers (rcl_interfaces/SetParametersResult)."""

    successful: bool
    reason: str = ""


@dataclass(frozen=True)
class ParameterOverride:
    """A value for ``node_pattern``'s parameter ``name`` from a file or a command line."""

    node_pattern: str
    name: str
    value: Any
    where: str = ""


@dataclass
class ParameterFile:
    """The parsed contents of one ROS 2 parameter file."""

    path: Path
    overrides: list[ParameterOverride] = field(default_factory=list)

    @property
    def node_patterns(self) -> list[str]:
        seen: list[str] = []
        for o in self.overrides:
            if o.node_pattern not in seen:
                seen.append(o.node_pattern)
        return seen


class _Located:
    """A scalar or list from YAML with the line it was written on (1-based)."""

    __slots__ = ("line", "value")

    def __init__(self, value: Any, line: int) -> None:
        self.value = value
        self.line = line


def _compose_located(node: yaml.Node, path: Path) -> Any:
    if isinstance(node, yaml.MappingNode):
        out: dict[str, Any] = {}
        for key_node, value_node in node.value:
            key = key_node.value
            out[str(key)] = (_compose_located(value_node, path), key_node.start_mark.line + 1)
        return out
    if isinstance(node, yaml.SequenceNode):
        items = [_compose_located(v, path) for v in node.value]
        return _Located([i.value if isinstance(i, _Located) else i for i in items],
                        node.start_mark.line + 1)
    if isinstance(node, yaml.ScalarNode):
        value = yaml.safe_load(yaml.serialize(node))
        return _Located(value, node.start_mark.line + 1)
    raise ParameterFileError(f"unsupported YAML node {node!r}", where=str(path))


def load_parameter_file(path: str | Path) -> ParameterFile:
    """Parse a ROS 2 parameter file; errors name the file, line and key."""
    p = Path(path)
    try:
        text = p.read_text()
    except OSError as exc:
        raise ParameterFileError(f"cannot read parameter file: {exc.strerror}", where=str(p)) from exc
    try:
        root = yaml.compose(text, Loader=yaml.SafeLoader)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"{p}:{mark.line + 1}" if mark is not None else str(p)
        problem = getattr(exc, "problem", None) or str(exc)
        raise ParameterFileError(f"malformed YAML: {problem}", where=where) from exc
    result = ParameterFile(p)
    if root is None:
        return result
    tree = _compose_located(root, p)
    if not isinstance(tree, dict):
        raise ParameterFileError("top level must map node names to {ros__parameters: ...}",
                                 where=f"{p}:1")
    _walk_nodes(tree, "", p, result)
    return result


def _walk_nodes(tree: dict[str, Any], prefix: str, path: Path, out: ParameterFile) -> None:
    for key, (value, line) in tree.items():
        if key == "ros__parameters":
            node_pattern = prefix or "/**"
            if isinstance(value, _Located) and value.value is None:
                continue
            if not isinstance(value, dict):
                raise ParameterFileError(
                    "ros__parameters must be a mapping", where=f"{path}:{line} node {node_pattern}"
                )
            _flatten_params(value, "", node_pattern, path, out)
            continue
        if not isinstance(value, dict):
            raise ParameterFileError(
                f"expected a node name mapping to ros__parameters, found key {key!r} with a value",
                where=f"{path}:{line}",
            )
        name = key if key.startswith("/") or not prefix else f"{prefix.rstrip('/')}/{key}"
        _walk_nodes(value, name, path, out)


def _flatten_params(
    tree: dict[str, Any], prefix: str, node_pattern: str, path: Path, out: ParameterFile
) -> None:
    for key, (value, line) in tree.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            _flatten_params(value, f"{name}.", node_pattern, path, out)
        else:
            out.overrides.append(
                ParameterOverride(node_pattern, name, value.value, f"{path}:{line}")
            )


def node_matches(pattern: str, fully_qualified_name: str) -> bool:
    """Does a parameter-file node key match a node (``/ns/name``)?

    ``/**`` matches every node; ``name`` matches a node of that name in any namespace (as
    launch files usually write them); ``/ns/name`` must match exactly; ``*`` and ``**`` glob.
    """
    if pattern in ("/**", "**"):
        return True
    if not pattern.startswith("/"):
        return fully_qualified_name.rsplit("/", 1)[-1] == pattern or fnmatch.fnmatchcase(
            fully_qualified_name, "*/" + pattern
        )
    if "*" in pattern:
        return fnmatch.fnmatchcase(fully_qualified_name, pattern.replace("**", "*"))
    return pattern == fully_qualified_name


def parse_cli_parameter(text: str, where: str = "command line") -> ParameterOverride:
    """``name:=value`` (value parsed as YAML) → an override for every node."""
    name, sep, raw = text.partition(":=")
    if not sep or not name:
        raise ParameterFileError(f"expected name:=value, got {text!r}", where=where)
    return ParameterOverride("/**", name, yaml.safe_load(raw) if raw else "", where)


def overrides_from_dict(values: dict[str, Any], where: str = "") -> list[ParameterOverride]:
    """Flatten a nested dict of parameters (as in YAML) into overrides for one node."""
    out: list[ParameterOverride] = []

    def walk(d: dict[str, Any], prefix: str) -> None:
        for k, v in d.items():
            if isinstance(v, dict):
                walk(v, f"{prefix}{k}.")
            else:
                out.append(ParameterOverride("/**", f"{prefix}{k}", v, where))

    walk(values, "")
    return out


def describe_sequence(values: Sequence[Any]) -> str:
    return ", ".join(repr(v) for v in values)


def load_params_file(path: Path) -> tuple[Any, yaml.Node | None]:
    """The document and its YAML node tree (for line numbers) of a parameters file; an
    unreadable file or malformed YAML raises `ParameterFileError` naming file, line, column."""
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise ParameterFileError(f"{path}: cannot read the parameters file: "
                              f"{exc.strerror or exc}") from exc
    try:
        return yaml.safe_load(text), yaml.compose(text, Loader=yaml.SafeLoader)
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        where = f"{path}:{mark.line + 1}:{mark.column + 1}" if mark is not None else str(path)
        raise ParameterFileError(f"{where}: malformed YAML: {exc.problem or exc.context}") from exc
    except yaml.YAMLError as exc:
        raise ParameterFileError(f"{path}: malformed YAML: {exc}") from exc
