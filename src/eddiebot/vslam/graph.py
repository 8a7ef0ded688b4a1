"""Pose-graph optimisation behind a small interface.

With `Reg/Force3DoF` (the report's setting) the graph is SE(2) and runs incrementally in gtsam's
iSAM2: `IncrementalPose2Graph` keeps the graph between calls and folds in only the nodes and
links that are new, so a loop closure costs an iSAM2 update (a few ms at 1,000 nodes) instead of
a batch re-solve of the whole graph. Without Force3DoF the graph is Pose3, kept in iSAM2 the
same way (`IncrementalPose3Graph`); `GTSAM/Incremental false` (and, for Pose3,
`Optimizer/Robust`) re-solves it in batch with gtsam Levenberg–Marquardt (`GtsamPoseGraph`).

Everything the core needs is `PoseGraphOptimizer.optimize` and `optimized_link_errors` (the
`RGBD/OptimizeMaxError` residuals). Poses and link transforms are 4×4 (m); informations are 6×6
in (x, y, z, roll, pitch, yaw).

`Optimizer/Robust` (both optimisers' `robust`): loop closures become Vertigo switchable
constraints (`eddiebot.vslam.switchable`).

Modules: `graph_links` (link types, residuals), `graph_batch` (Levenberg–Marquardt),
`graph_incremental` (iSAM2, SE(2)), `graph_incremental3` (iSAM2, Pose3), `switchable` (Vertigo factors); this module puts them behind
`GtsamPoseGraph` and `make_optimizer`.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping

import numpy as np
from numpy.typing import NDArray

from eddiebot.vslam.graph_batch import BatchPoseGraph
from eddiebot.vslam.graph_incremental import IncrementalPose2Graph
from eddiebot.vslam.graph_incremental3 import IncrementalPose3Graph
from eddiebot.vslam.graph_links import (
    F64,
    GraphLink,
    LinkError,
    LinkLike,
    PoseGraphOptimizer,
    link_errors,
)
from eddiebot.vslam.switchable import add_switchable, switchable_between

__all__ = [
    "GraphLink",
    "GtsamPoseGraph",
    "IncrementalPose2Graph",
    "IncrementalPose3Graph",
    "LinkError",
    "LinkLike",
    "PoseGraphOptimizer",
    "add_switchable",
    "discard_links",
    "link_errors",
    "make_optimizer",
    "optimized_link_errors",
    "switchable_between",
]



class GtsamPoseGraph(BatchPoseGraph):
    """Pose3 (or, with `three_dof`, Pose2) pose graph.

    With `incremental` (the default) every call is delegated to an `IncrementalPose2Graph`
    (`three_dof`) or, unless `robust`, an `IncrementalPose3Graph` (gtsam iSAM2); otherwise each
    call re-solves the whole graph with Levenberg–Marquardt. `robust`: `Optimizer/Robust`.
    """

    def __init__(self, three_dof: bool, epsilon: float = 1e-5, *,
                 incremental: bool = True, robust: bool = False) -> None:
        super().__init__(three_dof, epsilon, robust=robust)
        self.incremental: IncrementalPose2Graph | None = (
            IncrementalPose2Graph(epsilon, robust=robust) if three_dof and incremental else None
        )
        #: Pose3 in iSAM2 (`GTSAM/Incremental`); switchable links are solved in batch
        self.incremental3: IncrementalPose3Graph | None = (
            IncrementalPose3Graph(epsilon) if not three_dof and incremental and not robust
            else None)

    def optimize(
        self,
        poses: Mapping[int, F64],
        links: Iterable[LinkLike],
        root_id: int,
        iterations: int,
    ) -> dict[int, F64]:
        """Optimise the component of `root_id`; nodes not connected to it are left out."""
        if self.incremental is not None:
            return self.incremental.optimize(poses, links, root_id, iterations)
        if self.incremental3 is not None:
            return self.incremental3.optimize(poses, links, root_id, iterations)
        return self.optimize_batch(poses, links, root_id, iterations)


def make_optimizer(force_3dof: bool, epsilon: float = 1e-5,
                   robust: bool = False) -> PoseGraphOptimizer:
    """The back end for `Reg/Force3DoF`: incremental SE(2) if true, batch Pose3 otherwise;
    `robust`: `Optimizer/Robust`."""
    if force_3dof:
        return IncrementalPose2Graph(epsilon, robust=robust)
    return GtsamPoseGraph(False, epsilon, robust=robust)



def optimized_link_errors(
    optimizer: PoseGraphOptimizer, optimized: Mapping[int, F64], links: Iterable[LinkLike]
) -> tuple[NDArray[np.int64], F64, F64]:
    """`RGBD/OptimizeMaxError` residuals right after `optimizer.optimize(..., links, ...)`
    returned `optimized`: ((from_id, to_id) rows, linear ratios, angular ratios).

    The incremental graph answers from its own arrays (no per-link Python); any other optimiser
    goes through `link_errors`.
    """
    inner = optimizer.incremental if isinstance(optimizer, GtsamPoseGraph) else optimizer
    if isinstance(inner, IncrementalPose2Graph) and inner.node_count:
        return inner.link_error_ratios()
    inner3 = optimizer.incremental3 if isinstance(optimizer, GtsamPoseGraph) else optimizer
    if isinstance(inner3, IncrementalPose3Graph) and inner3.node_count:
        return inner3.link_error_ratios()
    errors = link_errors(optimized, links)
    ids = np.array([(e.from_id, e.to_id) for e in errors], np.int64).reshape(-1, 2)
    return (ids, np.array([e.linear_ratio for e in errors], np.float64),
            np.array([e.angular_ratio for e in errors], np.float64))


def discard_links(optimizer: PoseGraphOptimizer, links: Iterable[LinkLike]) -> None:
    """Tell the optimiser that these links, just optimised, were rejected
    (`RGBD/OptimizeMaxError`) and will be missing from the next call; the incremental graph
    removes their factors at once instead of rebuilding later. Other optimisers keep nothing."""
    inner = optimizer.incremental if isinstance(optimizer, GtsamPoseGraph) else optimizer
    if isinstance(inner, IncrementalPose2Graph):
        inner.remove_links([(lk.from_id, lk.to_id) for lk in links])


