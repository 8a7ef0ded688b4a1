"""Interactive editing of a SLAM graph: staged node moves applied as constraints
(slam_toolbox's ``manual_loop_closure``), pure — no bus, no clock, no files.

slam_toolbox's interactive mode lets a user drag graph nodes in RViz; each release of a
marker stages a move (node id → pose), ``manual_loop_closure`` applies the staged moves and
re-optimises, ``clear_changes`` drops them. Upstream's Ceres solver only overwrites the moved
node's initial value (``CeresSolver::ModifyNode``) before optimising, so the optimiser pulls
the node most of the way back unless the graph is ambiguous there. Here each staged move
becomes a constraint the graph keeps: an edge from node 0 (anchored by the graph's prior)
to the moved node, measuring the pose the user gave with standard deviations
`MANUAL_MOVE_SIGMAS`. The node then lands where it was put, and its neighbours follow
through their odometry and scan-match edges. The edge is a loop edge outside the χ² gate
(the user's word is not tested against the estimate) and is saved with the session.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np
import numpy.typing as npt

from eddiebot.geometry import se2_between
from eddiebot.slam.errors import GraphEditError
from eddiebot.slam.mapper import SlamCore
from eddiebot.slam.pose_graph import EdgeKind

__all__ = ["MANUAL_MOVE_SIGMAS", "apply_node_moves", "check_node_move"]

FloatArray = npt.NDArray[np.float64]

#: Standard deviations (m, m, rad) of the constraint a manual move adds: tight enough that
#: the node lands within a few centimetres of where it was put, loose enough that the graph's
#: other edges stay well conditioned.
MANUAL_MOVE_SIGMAS = np.array([0.01, 0.01, 0.005])


def check_node_move(core: SlamCore, node_id: int, pose: npt.ArrayLike) -> FloatArray:
    """The move of ``node_id`` to ``pose`` (robot pose in the map frame, m/rad) as a
    validated array; `GraphEditError` naming the node when it cannot be moved."""
    p = np.asarray(pose, dtype=np.float64).reshape(-1)
    n = len(core.nodes)
    if p.size != 3 or not np.all(np.isfinite(p)):
        raise GraphEditError(f"node {node_id}: pose {p.tolist()} is not a finite (x, y, theta)")
    if not 0 <= node_id < n:
        raise GraphEditError(
            f"node {node_id}: no such node (the graph has {n} nodes, ids 0..{n - 1})"
            if n
            else f"node {node_id}: the graph is empty"
        )
    if node_id == 0:
        raise GraphEditError(
            "node 0: it anchors the map frame and cannot be moved; move another node"
        )
    if core.nodes[node_id].retired:
        raise GraphEditError(f"node {node_id}: retired (lifelong mapping removed it)")
    p[2] = math.remainder(float(p[2]), math.tau)
    return p


def apply_node_moves(core: SlamCore, moves: Mapping[int, npt.ArrayLike]) -> int:
    """Apply staged moves (node id → robot pose in the map frame) as constraints and
    re-optimise the graph; returns how many were applied. Every move is checked before any
    is applied, so a bad one leaves the graph untouched."""
    checked = {int(k): check_node_move(core, int(k), v) for k, v in moves.items()}
    if not checked:
        return 0
    anchor = core.node_poses()[0]
    cov = np.diag(MANUAL_MOVE_SIGMAS**2)
    for node_id, target in sorted(checked.items()):
        core.graph.add_edge(
            0, node_id, se2_between(anchor, target), cov, kind=EdgeKind.LOOP, robust=False
        )
    core.graph.optimize(full=True)
    return len(checked)
