"""Loading BehaviorTree.CPP v3/v4 XML into trees of :mod:`eddiebot.nav.bt` nodes.

A file holds ``<root>`` with one or more ``<BehaviorTree ID=…>`` (the one run is named by
``main_tree_to_execute``, or is the only one), optional ``<include path=…/>`` of other
files (relative to the including file) and a ``<TreeNodesModel>`` (read by Groot, skipped
here). Nodes are written by type (``<Sequence>``) or, in v3's form, ``<Action ID=…>``;
``<SubTree ID=… port="{key}" _autoremap="true"/>`` runs another tree on its own blackboard
with the given ports remapped to the parent's (v3: ``__shared_blackboard``,
``SubTreePlus`` with ``__autoremap``).

Everything is checked when the file is loaded, never later: an unknown node type, an
attribute that is not one of the node's ports, a literal that does not convert to its
port's type, an output port given a literal, a wrong number of children, or a missing
``SubTree`` each raise one :class:`~eddiebot.nav.bt.core.TreeError` naming file, line and
node.
"""

from __future__ import annotations

import difflib
import importlib
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from xml.parsers import expat

from eddiebot.nav.bt.controls import CONTROL_NODES
from eddiebot.nav.bt.core import (
    Blackboard,
    ControlNode,
    DecoratorNode,
    NodeConfig,
    PortDirection,
    Status,
    TreeError,
    TreeNode,
    blackboard_key,
    convert_literal,
)
from eddiebot.nav.bt.nodes import NAV2_NODES

__all__ = ["BT_NODE_ENTRY_POINT_GROUP", "BehaviorTreeFactory", "Tree", "parse_xml"]

#: entry-point group a package names its BT-node registration function in
BT_NODE_ENTRY_POINT_GROUP = "eddiebot.nav.bt_nodes"

#: v3 names BT.CPP v4 renamed
_V3_ALIASES = {"SequenceStar": "SequenceWithMemory", "SubTreePlus": "SubTree"}
#: the generic v3 form <Action ID="Type">
_GENERIC = {"Action", "Condition", "Decorator", "Control"}
#: attributes every node takes
_COMMON = {"name", "_description", "_uid", "_fullpath"}
#: BT.CPP v4 scripting attributes (pre/post conditions), refused by name
_SCRIPTING = {"_skipIf", "_successIf", "_failureIf", "_while", "_onSuccess", "_onFailure",
              "_onHalted", "_post"}


@dataclass
class Element:
    tag: str
    attrs: dict[str, str]
    line: int
    file: str
    children: list[Element] = field(default_factory=list)

    def at(self) -> str:
        return f"{self.file}:{self.line}"


def parse_xml(text: str, file: str) -> Element:
    """The document's root element, each element with its line (expat, no DTDs)."""
    parser = expat.ParserCreate()
    stack: list[Element] = []
    root: list[Element] = []

    def start(tag: str, attrs: dict[str, str]) -> None:
        el = Element(tag, dict(attrs), parser.CurrentLineNumber, file)
        if stack:
            stack[-1].children.append(el)
        else:
            root.append(el)
        stack.append(el)

    def end(_tag: str) -> None:
        stack.pop()

    parser.StartElementHandler = start
    parser.EndElementHandler = end
    try:
        parser.Parse(text, True)
    except expat.ExpatError as exc:
        raise TreeError(f"{file}:{exc.lineno}: malformed XML: {expat.ErrorString(exc.code)}") \
            from None
    if not root:
        raise TreeError(f"{file}:1: no XML element")
    return root[0]


class Tree:
    """A loaded tree: tick its root, halt it, look its nodes up."""

    def __init__(self, root: TreeNode, blackboard: Blackboard, file: str,
                 nodes: list[TreeNode]) -> None:
        self.root = root
        self.blackboard = blackboard
        self.file = file
        self.nodes = nodes

    def tick_once(self) -> Status:
        return self.root.execute_tick()

    def halt(self) -> None:
        self.root.halt_node()

    def find(self, name: str) -> list[TreeNode]:
        return [n for n in self.nodes if n.name == name]

    def by_type(self, tag: str) -> list[TreeNode]:
        return [n for n in self.nodes if n.config.tag == tag]

    def __iter__(self) -> Iterator[TreeNode]:
        return iter(self.nodes)


class _SubTreeNode(DecoratorNode):
    """A SubTree: ticks the tree it instantiates."""

    def tick(self) -> Status:
        self.status = Status.RUNNING
        return self.child.execute_tick()


class BehaviorTreeFactory:
    """Node types by name (BT.CPP's ``BehaviorTreeFactory``): BT.CPP's and Nav2's built-in
    nodes, plus whatever :meth:`register_node_type` or :meth:`load_plugin` add."""

    def __init__(self) -> None:
        self.builders: dict[str, type[TreeNode]] = {**CONTROL_NODES, **NAV2_NODES}

    def register_node_type(self, name: str, cls: type[TreeNode]) -> None:
        if not (isinstance(cls, type) and issubclass(cls, TreeNode)):
            raise TypeError(f"BT node {name!r}: {cls!r} is not a TreeNode subclass")
        self.builders[name] = cls

    def load_plugin(self, lib: str) -> None:
        """Resolve one ``plugin_lib_names`` entry: Nav2's own libraries
        (``nav2_*_bt_node``) are built in; another name is an entry point of group
        ``eddiebot.nav.bt_nodes`` or an importable module, whose ``register_bt_nodes(factory)``
        registers its nodes."""
        if lib.startswith("nav2_") and lib.endswith("_bt_node"):
            return
        fn: Callable[[BehaviorTreeFactory], Any] | None = None
        from importlib.metadata import entry_points

        for ep in entry_points(group=BT_NODE_ENTRY_POINT_GROUP):
            if ep.name == lib:
                try:
                    fn = ep.load()
                except Exception as exc:  # any failure importing user code is reported
                    raise TreeError(f"plugin_lib_names: entry point {ep.name!r} = {ep.value!r} "
                                    f"(group {BT_NODE_ENTRY_POINT_GROUP!r}) failed to load: "
                                    f"{type(exc).__name__}: {exc}") from None
                break
        if fn is None:
            try:
                module = importlib.import_module(lib)
            except ImportError as exc:
                raise TreeError(f"plugin_lib_names: {lib!r} is neither an entry point of "
                                f"{BT_NODE_ENTRY_POINT_GROUP!r} nor an importable module "
                                f"({exc})") from None
            fn = getattr(module, "register_bt_nodes", None)
            if fn is None:
                raise TreeError(f"plugin_lib_names: module {lib!r} has no "
                                f"register_bt_nodes(factory)")
        fn(self)

    # -- loading ----------------------------------------------------------------------------
    def create_tree_from_file(self, path: str | Path, blackboard: Blackboard | None = None,
                              context: Any = None) -> Tree:
        p = Path(path)
        if not p.is_file():
            raise TreeError(f"{p}: behaviour tree file not found")
        return self._create(self._read(p), str(p), blackboard, context)

    def create_tree_from_text(self, text: str, blackboard: Blackboard | None = None,
                              context: Any = None, file: str = "<string>") -> Tree:
        return self._create(parse_xml(text, file), file, blackboard, context)

    def _read(self, p: Path) -> Element:
        try:
            text = p.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            raise TreeError(f"{p}: cannot read behaviour tree file: {exc}") from None
        return parse_xml(text, str(p))

    def _definitions(self, root: Element, base: Path | None, seen: set[str],
                     out: dict[str, Element]) -> None:
        if root.tag != "root":
            raise TreeError(f"{root.at()}: the document element must be <root>, not <{root.tag}>")
        for el in root.children:
            if el.tag == "BehaviorTree":
                tid = el.attrs.get("ID")
                if not tid:
                    raise TreeError(f"{el.at()}: <BehaviorTree> without ID")
                if tid in out:
                    raise TreeError(f"{el.at()}: BehaviorTree {tid!r} defined twice "
                                    f"(first at {out[tid].at()})")
                if len(el.children) != 1:
                    raise TreeError(f"{el.at()}: BehaviorTree {tid!r} must have exactly one "
                                    f"root node, has {len(el.children)}")
                out[tid] = el
            elif el.tag == "include":
                rel = el.attrs.get("path")
                if not rel:
                    raise TreeError(f"{el.at()}: <include> without path")
                p = Path(rel)
                if not p.is_absolute() and base is not None:
                    p = base / p
                if not p.is_file():
                    raise TreeError(f"{el.at()}: included file {rel!r} not found")
                key = str(p.resolve())
                if key in seen:
                    continue
                seen.add(key)
                self._definitions(self._read(p), p.parent, seen, out)
            elif el.tag == "TreeNodesModel":
                continue
            else:
                raise TreeError(f"{el.at()}: unexpected <{el.tag}> in <root> (expected "
                                f"BehaviorTree, include or TreeNodesModel)")

    def _create(self, root: Element, file: str, blackboard: Blackboard | None,
                context: Any) -> Tree:
        base = Path(file).parent if file != "<string>" else None
        defs: dict[str, Element] = {}
        self._definitions(root, base, {str(Path(file).resolve())} if base else set(), defs)
        if not defs:
            raise TreeError(f"{root.at()}: no <BehaviorTree> in the file")
        main = root.attrs.get("main_tree_to_execute")
        if main is None:
            if len(defs) > 1:
                raise TreeError(f"{root.at()}: several BehaviorTrees and no "
                                f"main_tree_to_execute")
            main = next(iter(defs))
        if main not in defs:
            raise TreeError(f"{root.at()}: main_tree_to_execute {main!r} is not defined "
                            f"(trees: {', '.join(sorted(defs))})")
        bb = blackboard if blackboard is not None else Blackboard()
        nodes: list[TreeNode] = []
        top = self._build(defs[main].children[0], defs, bb, context, nodes, [main])
        return Tree(top, bb, file, nodes)

    def _node_type(self, el: Element) -> str:
        tag = _V3_ALIASES.get(el.tag, el.tag)
        if tag in _GENERIC:
            tid = el.attrs.get("ID")
            if not tid:
                raise TreeError(f"{el.at()}: <{el.tag}> without ID")
            tag = _V3_ALIASES.get(tid, tid)
        return tag

    def _unknown(self, el: Element, tag: str) -> TreeError:
        near = difflib.get_close_matches(tag, [*self.builders, "SubTree"], n=1)
        hint = f"; did you mean {near[0]!r}?" if near else ""
        return TreeError(f"{el.at()}: unknown node type {tag!r}{hint}")

    def _build(self, el: Element, defs: dict[str, Element], bb: Blackboard, context: Any,
               nodes: list[TreeNode], stack: list[str]) -> TreeNode:
        tag = self._node_type(el)
        if tag == "SubTree":
            return self._subtree(el, defs, bb, context, nodes, stack)
        cls = self.builders.get(tag)
        if cls is None:
            raise self._unknown(el, tag)
        attrs = {k: v for k, v in el.attrs.items() if not (el.tag in _GENERIC and k == "ID")}
        ports = cls.PORTS
        for key, raw in attrs.items():
            if key in _COMMON:
                continue
            if key in _SCRIPTING:
                raise TreeError(f"{el.at()}: {tag}: the scripting attribute {key!r} is not "
                                f"supported")
            port = ports.get(key)
            if port is None:
                near = difflib.get_close_matches(key, list(ports), n=1)
                hint = f"; did you mean {near[0]!r}?" if near else ""
                names = ", ".join(sorted(ports)) or "none"
                raise TreeError(f"{el.at()}: {tag}: unknown port {key!r}{hint} "
                                f"(its ports: {names})")
            if blackboard_key(raw) is not None:
                continue
            if port.direction != PortDirection.INPUT:
                raise TreeError(f"{el.at()}: {tag}: output port {key!r} takes a blackboard "
                                f"entry {{key}}, not {raw!r}")
            try:
                convert_literal(raw, port.type)
            except ValueError as exc:
                raise TreeError(f"{el.at()}: {tag}: port {key!r}: {exc}") from None
        n = len(el.children)
        if issubclass(cls, DecoratorNode):
            if n != 1:
                raise TreeError(f"{el.at()}: {tag} is a decorator and takes exactly one child, "
                                f"has {n}")
        elif issubclass(cls, ControlNode):
            lo, hi = cls.MIN_CHILDREN, cls.MAX_CHILDREN
            if n < lo or (hi is not None and n > hi):
                want = f"{lo}" if hi == lo else f"{lo}..{hi or 'n'}"
                raise TreeError(f"{el.at()}: {tag} takes {want} children, has {n}")
        elif n:
            raise TreeError(f"{el.at()}: {tag} is a leaf node and takes no children, has {n}")
        config = NodeConfig(ports=attrs, blackboard=bb, context=context, file=el.file,
                            line=el.line, tag=tag)
        try:
            node = cls(attrs.get("name", tag), config)
        except (ValueError, TypeError) as exc:
            raise TreeError(f"{el.at()}: {tag}: {exc}") from None
        nodes.append(node)
        node.children = [self._build(c, defs, bb, context, nodes, stack) for c in el.children]
        return node

    def _subtree(self, el: Element, defs: dict[str, Element], parent: Blackboard, context: Any,
                 nodes: list[TreeNode], stack: list[str]) -> TreeNode:
        tid = el.attrs.get("ID")
        if not tid:
            raise TreeError(f"{el.at()}: <SubTree> without ID")
        if tid not in defs:
            near = difflib.get_close_matches(tid, list(defs), n=1)
            hint = f"; did you mean {near[0]!r}?" if near else ""
            raise TreeError(f"{el.at()}: SubTree {tid!r} is not defined{hint}")
        if tid in stack:
            raise TreeError(f"{el.at()}: SubTree {tid!r} includes itself "
                            f"({' -> '.join([*stack, tid])})")
        if el.children:
            raise TreeError(f"{el.at()}: SubTree {tid!r} takes no children")
        auto = False
        remap: dict[str, str] = {}
        literals: dict[str, str] = {}
        for key, raw in el.attrs.items():
            if key in ("ID", *_COMMON):
                continue
            if key in ("_autoremap", "__autoremap", "__shared_blackboard"):
                try:
                    auto = bool(convert_literal(raw, bool))
                except ValueError as exc:
                    raise TreeError(f"{el.at()}: SubTree {tid!r}: {key}: {exc}") from None
                continue
            if key.startswith("_"):
                raise TreeError(f"{el.at()}: SubTree {tid!r}: attribute {key!r} is not supported")
            ref = blackboard_key(raw)
            if ref is None:
                literals[key] = raw
            else:
                remap[key] = ref or key
        child_bb = Blackboard(parent, remap, autoremap=auto)
        for key, value in literals.items():
            child_bb.set(key, value)
        config = NodeConfig(ports={}, blackboard=parent, context=context, file=el.file,
                            line=el.line, tag="SubTree")
        node = _SubTreeNode(el.attrs.get("name", tid), config)
        nodes.append(node)
        node.children = [self._build(defs[tid].children[0], defs, child_bb, context, nodes,
                                     [*stack, tid])]
        return node
