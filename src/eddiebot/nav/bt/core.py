"""BehaviorTree.CPP v4's tree model: statuses, ports, blackboards and the node base classes.

A node is ticked with :meth:`TreeNode.execute_tick`, which stores the returned status; a
node whose status is ``IDLE`` is fresh (never ticked, or reset by its parent). Halting
(:meth:`TreeNode.halt_node`) stops a ``RUNNING`` node and resets it to ``IDLE``, as BT.CPP's
``haltChild`` does. Ports are declared per class in :attr:`TreeNode.PORTS`; a port's XML
value is either a literal (converted to the port's type when the tree is loaded) or a
blackboard reference ``{key}`` (``{=}`` names the key after the port).
"""

from __future__ import annotations

import enum
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, ClassVar

__all__ = [
    "Blackboard",
    "ControlNode",
    "DecoratorNode",
    "LeafNode",
    "NodeConfig",
    "Port",
    "PortDirection",
    "StatefulActionNode",
    "Status",
    "TreeError",
    "TreeNode",
    "input_port",
    "output_port",
]


class TreeError(ValueError):
    """A tree file that cannot be loaded: the message names file, line and node."""


class Status(enum.Enum):
    IDLE = "IDLE"
    RUNNING = "RUNNING"
    SUCCESS = "SUCCESS"
    FAILURE = "FAILURE"
    SKIPPED = "SKIPPED"


class PortDirection(enum.Enum):
    INPUT = "input"
    OUTPUT = "output"
    INOUT = "inout"


_NO_DEFAULT = object()


@dataclass(frozen=True)
class Port:
    direction: PortDirection
    #: ``float``, ``int``, ``bool``, ``str`` (literals convert to these), or ``object`` for
    #: message-typed ports, which take a blackboard reference only
    type: type = str
    default: Any = _NO_DEFAULT
    description: str = ""

    @property
    def has_default(self) -> bool:
        return self.default is not _NO_DEFAULT


def input_port(type_: type = str, default: Any = _NO_DEFAULT, description: str = "") -> Port:
    return Port(PortDirection.INPUT, type_, default, description)


def output_port(type_: type = object, description: str = "") -> Port:
    return Port(PortDirection.OUTPUT, type_, _NO_DEFAULT, description)


def convert_literal(text: str, type_: type) -> Any:
    """A port literal as BT.CPP's ``convertFromString`` reads it (raises ``ValueError``)."""
    if type_ is str:
        return text
    if type_ is bool:
        low = text.strip().lower()
        if low in ("true", "1"):
            return True
        if low in ("false", "0"):
            return False
        raise ValueError(f"{text!r} is not a bool (true/false)")
    if type_ is int:
        return int(text.strip())
    if type_ is float:
        return float(text.strip())
    raise ValueError(f"a {type_.__name__} port takes a blackboard entry {{key}}, not a literal")


def blackboard_key(text: str) -> str | None:
    """``"{key}"`` → ``"key"``, ``"{=}"`` → ``""`` (the port's own name); anything else →
    None."""
    t = text.strip()
    if len(t) >= 2 and t[0] == "{" and t[-1] == "}":
        key = t[1:-1].strip()
        return "" if key == "=" else key
    return None


class Blackboard:
    """BT.CPP's blackboard: entries by key; a SubTree's blackboard maps some of its keys
    (or, with ``_autoremap``, every key it does not hold) onto its parent's."""

    def __init__(self, parent: Blackboard | None = None, remap: dict[str, str] | None = None,
                 autoremap: bool = False) -> None:
        self.parent = parent
        self.remap = dict(remap or {})
        self.autoremap = autoremap
        self._entries: dict[str, Any] = {}

    def _owner(self, key: str) -> tuple[Blackboard, str]:
        if self.parent is not None:
            if key in self.remap:
                return self.parent._owner(self.remap[key])
            if self.autoremap and key not in self._entries:
                return self.parent._owner(key)
        return self, key

    def has(self, key: str) -> bool:
        bb, k = self._owner(key)
        return k in bb._entries

    def get(self, key: str, default: Any = None) -> Any:
        bb, k = self._owner(key)
        return bb._entries.get(k, default)

    def set(self, key: str, value: Any) -> None:
        bb, k = self._owner(key)
        bb._entries[k] = value

    def keys(self) -> list[str]:
        return sorted(self._entries)


@dataclass
class NodeConfig:
    """What the loader gives a node: its XML attributes, blackboard, context and source."""

    ports: dict[str, str] = field(default_factory=dict)
    blackboard: Blackboard = field(default_factory=Blackboard)
    #: the navigator's services to the nodes (clients, clock, robot pose): see
    #: :class:`eddiebot.nav.bt.context.TreeContext`
    context: Any = None
    file: str = "<string>"
    line: int = 0
    #: the XML tag, i.e. the registered node type
    tag: str = ""


class TreeNode:
    """A node of the tree (BT.CPP's ``TreeNode``)."""

    PORTS: ClassVar[dict[str, Port]] = {}

    def __init__(self, name: str, config: NodeConfig) -> None:
        self.name = name
        self.config = config
        self.status = Status.IDLE
        self.children: list[TreeNode] = []

    # -- ticking --------------------------------------------------------------------------
    def tick(self) -> Status:  # pragma: no cover - interface
        raise NotImplementedError

    def execute_tick(self) -> Status:
        status = self.tick()
        if status == Status.IDLE:
            raise RuntimeError(f"{self.where()}: tick() returned IDLE")
        if status != Status.SKIPPED:
            self.status = status
        return status

    def halt(self) -> None:
        """Stop a running node (override to cancel work)."""

    def halt_node(self) -> None:
        self.halt()
        self.status = Status.IDLE

    def reset_status(self) -> None:
        self.status = Status.IDLE

    def where(self) -> str:
        c = self.config
        return f"{c.file}:{c.line}: {c.tag or type(self).__name__} {self.name!r}"

    # -- ports ----------------------------------------------------------------------------
    def get_input(self, name: str, default: Any = None) -> Any:
        """The port's value: its blackboard entry, its literal, or its declared default;
        ``default`` when none of them is there."""
        port = self.PORTS.get(name)
        raw = self.config.ports.get(name)
        if raw is None:
            if port is not None and port.has_default:
                return port.default
            return default
        key = blackboard_key(raw)
        if key is not None:
            bb = self.config.blackboard
            return bb.get(key or name, default) if bb.has(key or name) else default
        return convert_literal(raw, port.type if port is not None else str)

    def get_input_or_blackboard(self, name: str, default: Any = None) -> Any:
        """Nav2's ``getInputOrBlackboard``: the port if the XML sets it, else the blackboard
        entry of the same name."""
        if name in self.config.ports:
            return self.get_input(name, default)
        return self.config.blackboard.get(name, default)

    def set_output(self, name: str, value: Any) -> bool:
        """Write ``value`` to the port's blackboard entry; False when the XML leaves the port
        unconnected (BT.CPP's ``setOutput`` error, which Nav2 ignores)."""
        raw = self.config.ports.get(name)
        if raw is None:
            return False
        key = blackboard_key(raw)
        if key is None:
            return False
        self.config.blackboard.set(key or name, value)
        return True

    @property
    def context(self) -> Any:
        return self.config.context


class LeafNode(TreeNode):
    """An action or condition: no children."""


class StatefulActionNode(LeafNode):
    """BT.CPP's ``StatefulActionNode``: ``on_start`` on the first tick, ``on_running`` on
    the following ones, ``on_halted`` when halted while running."""

    def on_start(self) -> Status:  # pragma: no cover - interface
        raise NotImplementedError

    def on_running(self) -> Status:  # pragma: no cover - interface
        raise NotImplementedError

    def on_halted(self) -> None:
        """Cancel what ``on_start`` began."""

    def tick(self) -> Status:
        if self.status in (Status.IDLE, Status.SKIPPED, Status.SUCCESS, Status.FAILURE):
            return self.on_start()
        return self.on_running()

    def halt(self) -> None:
        if self.status == Status.RUNNING:
            self.on_halted()


class ControlNode(TreeNode):
    """A node with one or more children (BT.CPP's ``ControlNode``)."""

    MIN_CHILDREN: ClassVar[int] = 1
    MAX_CHILDREN: ClassVar[int | None] = None

    def halt_child(self, i: int) -> None:
        child = self.children[i]
        if child.status == Status.RUNNING:
            child.halt_node()
        child.reset_status()

    def reset_children(self, start: int = 0) -> None:
        for i in range(start, len(self.children)):
            self.halt_child(i)

    def halt(self) -> None:
        self.reset_children()


class DecoratorNode(ControlNode):
    """A node with exactly one child (BT.CPP's ``DecoratorNode``)."""

    MAX_CHILDREN: ClassVar[int | None] = 1

    @property
    def child(self) -> TreeNode:
        return self.children[0]

    def reset_child(self) -> None:
        self.halt_child(0)

    def execute_tick(self) -> Status:
        # BT.CPP v4: a decorator leaves its finished child IDLE, so the next tick starts it anew
        status = super().execute_tick()
        if self.child.status in (Status.SUCCESS, Status.FAILURE):
            self.child.reset_status()
        return status


#: a constructor the factory calls: (name, config) → node
Builder = Callable[[str, NodeConfig], TreeNode]
