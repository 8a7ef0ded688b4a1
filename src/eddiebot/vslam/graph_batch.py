"""Batch pose-graph optimisation: gtsam Levenberg–Marquardt over the whole component of the
root, Pose3 or (`Reg/Force3DoF`) Pose2, loop closures switchable under `Optimizer/Robust`."""

from __future__ import annotations

from collections.abc import Iterable, Mapping

import gtsam
import numpy as np

from eddiebot.vslam.graph_links import (
    _FIXED_SIGMA,
    _IDX_POSE2,
    _IDX_POSE3,
    F64,
    LinkLike,
    _component,
    _pose2,
    _pose3,
)
from eddiebot.vslam.switchable import SWITCH_KEY_BASE, add_switchable, clamped_switch

__all__ = ["BatchPoseGraph"]


class BatchPoseGraph:
    """Pose3 (or, with `three_dof`, Pose2) pose graph re-solved as a whole on every call with
    Levenberg–Marquardt. `robust`: `Optimizer/Robust`."""

    def __init__(self, three_dof: bool, epsilon: float = 1e-5, *, robust: bool = False) -> None:
        self.three_dof = three_dof
        self.epsilon = epsilon
        self.robust = robust
        self.switches: dict[tuple[int, int], float] = {}
        """Under `robust`: each switchable link's (from_id, to_id) switch after the last
        solve (1 = kept, 0 = switched off)."""

    def optimize(
        self,
        poses: Mapping[int, F64],
        links: Iterable[LinkLike],
        root_id: int,
        iterations: int,
    ) -> dict[int, F64]:
        """Optimise the component of `root_id`; nodes not connected to it are left out."""
        return self.optimize_batch(poses, links, root_id, iterations)

    def optimize_batch(
        self,
        poses: Mapping[int, F64],
        links: Iterable[LinkLike],
        root_id: int,
        iterations: int,
    ) -> dict[int, F64]:
        """Levenberg–Marquardt on the whole component of `root_id` from `poses`."""
        link_list = [lk for lk in links if lk.from_id in poses and lk.to_id in poses]
        component = _component(root_id, link_list)
        graph = gtsam.NonlinearFactorGraph()
        values = gtsam.Values()
        for node_id in component:
            if self.three_dof:
                values.insert(node_id, _pose2(poses[node_id]))
            else:
                values.insert(node_id, _pose3(poses[node_id]))
        if self.three_dof:
            fixed = gtsam.noiseModel.Isotropic.Sigma(3, _FIXED_SIGMA)
            graph.add(gtsam.PriorFactorPose2(root_id, _pose2(poses[root_id]), fixed))
        else:
            fixed = gtsam.noiseModel.Isotropic.Sigma(6, _FIXED_SIGMA)
            graph.add(gtsam.PriorFactorPose3(root_id, _pose3(poses[root_id]), fixed))
        switch_keys: dict[tuple[int, int], int] = {}
        for lk in link_list:
            if lk.from_id not in component:
                continue
            noise = self._noise(lk.information)
            if self.robust and lk.switchable:
                key = SWITCH_KEY_BASE + len(switch_keys)
                switch_keys[(lk.from_id, lk.to_id)] = key
                add_switchable(graph, values, lk.from_id, lk.to_id, lk.transform, noise, key,
                               self.three_dof)
                continue
            if self.three_dof:
                graph.add(gtsam.BetweenFactorPose2(lk.from_id, lk.to_id,
                                                   _pose2(lk.transform), noise))
            else:
                graph.add(gtsam.BetweenFactorPose3(lk.from_id, lk.to_id,
                                                   _pose3(lk.transform), noise))
        params = gtsam.LevenbergMarquardtParams()
        params.setMaxIterations(max(1, iterations))
        params.setRelativeErrorTol(self.epsilon)
        result = gtsam.LevenbergMarquardtOptimizer(graph, values, params).optimize()
        all_keys = result.keys()
        keys = [k for k in all_keys if k < SWITCH_KEY_BASE]
        self.switches = {pair: clamped_switch(result.atVector(k)) for pair, k in switch_keys.items()}
        out: dict[int, F64] = {}
        if self.three_dof:
            xyt = gtsam.utilities.extractPose2(result)
            c, s = np.cos(xyt[:, 2]), np.sin(xyt[:, 2])
            mats = np.zeros((len(keys), 4, 4))
            mats[:, 0, 0], mats[:, 0, 1], mats[:, 1, 0], mats[:, 1, 1] = c, -s, s, c
            mats[:, 2, 2] = mats[:, 3, 3] = 1.0
            mats[:, 0, 3], mats[:, 1, 3] = xyt[:, 0], xyt[:, 1]
            for k, node_id in enumerate(keys):
                # keep the out-of-plane part (z) of the input pose
                mats[k, 2, 3] = poses[int(node_id)][2, 3]
                out[int(node_id)] = mats[k]
        else:
            flat = gtsam.utilities.extractPose3(result)  # rows: R (row-major 9) then t
            for k, node_id in enumerate(keys):
                t = np.eye(4)
                t[:3, :3] = flat[k, :9].reshape(3, 3)
                t[:3, 3] = flat[k, 9:]
                out[int(node_id)] = t
        return out

    def _noise(self, info6: F64) -> gtsam.noiseModel.Base:
        info = np.asarray(info6, dtype=np.float64)
        # gtsam Pose3 tangent order is (rx, ry, rz, tx, ty, tz)
        idx = _IDX_POSE2 if self.three_dof else _IDX_POSE3
        sub_info = info[idx[:, None], idx]
        diag = np.diagonal(sub_info)
        if np.count_nonzero(sub_info - np.diag(diag)) == 0:
            return gtsam.noiseModel.Diagonal.Precisions(diag.copy())
        return gtsam.noiseModel.Gaussian.Information(sub_info)

