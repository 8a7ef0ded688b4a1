"""Behaviour trees for the BT navigator: BehaviorTree.CPP v3/v4 XML with Nav2's nodes.

:mod:`~eddiebot.nav.bt.core` has the tree model (statuses, ports, blackboards, node base
classes), :mod:`~eddiebot.nav.bt.controls` registers BT.CPP's and Nav2's control and
decorator nodes, :mod:`~eddiebot.nav.bt.nodes` Nav2's action, service, selector and
condition nodes (one module each), and :mod:`~eddiebot.nav.bt.factory` loads XML files into
trees, refusing unknown nodes and ports with file and line. :mod:`~eddiebot.nav.bt.trees`
ships Nav2's default trees.
"""

from eddiebot.nav.bt.context import TreeContext
from eddiebot.nav.bt.core import (
    Blackboard,
    ControlNode,
    DecoratorNode,
    LeafNode,
    NodeConfig,
    Port,
    StatefulActionNode,
    Status,
    TreeError,
    TreeNode,
    input_port,
    output_port,
)
from eddiebot.nav.bt.factory import BT_NODE_ENTRY_POINT_GROUP, BehaviorTreeFactory, Tree
from eddiebot.nav.bt.trees import DEFAULT_TREES, TREES_DIR, resolve_tree_path

__all__ = [
    "BT_NODE_ENTRY_POINT_GROUP",
    "DEFAULT_TREES",
    "TREES_DIR",
    "BehaviorTreeFactory",
    "Blackboard",
    "ControlNode",
    "DecoratorNode",
    "LeafNode",
    "NodeConfig",
    "Port",
    "StatefulActionNode",
    "Status",
    "Tree",
    "TreeContext",
    "TreeError",
    "TreeNode",
    "input_port",
    "output_port",
    "resolve_tree_path",
]
