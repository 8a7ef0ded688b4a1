"""Behaviour trees for the BT navigator, on py_trees, with Nav2's node semantics.

:mod:`eddiebot.nav.bt.nodes` has the control nodes (PipelineSequence, RecoveryNode,
ReactiveFallback, RoundRobin, RateController), conditions and non-blocking action nodes;
:mod:`eddiebot.nav.bt.trees` builds Nav2's default trees by factory functions over a
:class:`~eddiebot.nav.bt.nodes.NavBlackboard` instance.
"""

from eddiebot.nav.bt.nodes import NavBlackboard, tick_child
from eddiebot.nav.bt.trees import (
    NavClients,
    TreeOptions,
    navigate_through_poses_tree,
    navigate_to_pose_tree,
)

__all__ = [
    "NavBlackboard",
    "NavClients",
    "TreeOptions",
    "navigate_through_poses_tree",
    "navigate_to_pose_tree",
    "tick_child",
]
