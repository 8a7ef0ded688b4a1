"""Pose-graph optimisation behind a small interface (gtsam Pose2 for 3DoF, Pose3 otherwise).

This is a thin adapter so that the RGB-D SLAM core can later run on the shared 2D pose graph of
`eddiebot.slam`; everything the core needs is `PoseGraphOptimizer.optimize` and `link_errors`.
Poses and link transforms are 4×4 (m); informations are 6×6 in (x, y, z, roll, pitch, yaw).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Protocol

import gtsam
import numpy as np
from numpy.typing import NDArray

from eddiebot.vslam.transforms import yaw_of

__all__ = ["GraphLink", "GtsamPoseGraph", "LinkError", "PoseGraphOptimizer", "link_errors"]

F64 = NDArray[np.float64]
_FIXED_SIGMA = 1e-6
_IDX_POSE2 = np.array([0, 1, 5])
_IDX_POSE3 = np.array([3, 4, 5, 0, 1, 2])
_INFO_IGNORED = 1e-4


@dataclass(frozen=True)
class GraphLink:
    """A constraint: pose of `to_id` in the frame of `from_id`, with its information matrix."""

    from_id: int
    to_id: int
    transform: F64
    information: F64


@dataclass(frozen=True)
class LinkError:
    """RTAB-Map's normalised residual of one link after optimisation (`RGBD/OptimizeMaxError`)."""

    from_id: int
    to_id: int
    linear_ratio: float
    angular_ratio: float


class PoseGraphOptimizer(Protocol):
    """What the SLAM core needs from a pose-graph back end."""

    def optimize(
        self,
        poses: Mapping[int, F64],
        links: Iterable[GraphLink],
        root_id: int,
        iterations: int,
    ) -> dict[int, F64]:
        """Optimised poses of the nodes connected to `root_id` (which stays fixed)."""
        ...


class GtsamPoseGraph:
    """Levenberg–Marquardt over gtsam Pose2 (`three_dof`) or Pose3 between-factors."""

    def __init__(self, three_dof: bool, epsilon: float = 1e-5) -> None:
        self.three_dof = three_dof
        self.epsilon = epsilon

    def optimize(
        self,
        poses: Mapping[int, F64],
        links: Iterable[GraphLink],
        root_id: int,
        iterations: int,
    ) -> dict[int, F64]:
        """Optimise the component of `root_id`; nodes not connected to it are left out."""
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
        for lk in link_list:
            if lk.from_id not in component:
                continue
            noise = self._noise(lk.information)
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
        keys = list(result.keys())
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


def _pose2(t: F64) -> gtsam.Pose2:
    return gtsam.Pose2(float(t[0, 3]), float(t[1, 3]), yaw_of(t))


def _pose3(t: F64) -> gtsam.Pose3:
    return gtsam.Pose3(np.asarray(t, dtype=np.float64))


def _component(root: int, links: list[GraphLink]) -> set[int]:
    adjacency: dict[int, list[int]] = {}
    for lk in links:
        adjacency.setdefault(lk.from_id, []).append(lk.to_id)
        adjacency.setdefault(lk.to_id, []).append(lk.from_id)
    seen = {root}
    stack = [root]
    while stack:
        n = stack.pop()
        for m in adjacency.get(n, ()):
            if m not in seen:
                seen.add(m)
                stack.append(m)
    return seen


def link_errors(poses: Mapping[int, F64], links: Iterable[GraphLink]) -> list[LinkError]:
    """Per link: max axis deviation / linear σ and rotation deviation / angular σ.

    σ comes from the smallest information term among x, y, z (resp. roll, pitch, yaw), ignoring
    terms ≤ 1e-4, so a huge z variance of planar odometry does not count.
    """
    usable = [lk for lk in links if lk.from_id in poses and lk.to_id in poses]
    if not usable:
        return []
    a = np.stack([poses[lk.from_id] for lk in usable])
    b = np.stack([poses[lk.to_id] for lk in usable])
    m = np.stack([lk.transform for lk in usable])
    info = np.stack([np.diag(lk.information) for lk in usable])
    ra = a[:, :3, :3]
    # T = inv(A) B
    t_rot = np.einsum("nji,njk->nik", ra, b[:, :3, :3])
    t_tr = np.einsum("nji,nj->ni", ra, b[:, :3, 3] - a[:, :3, 3])
    d = np.abs(t_tr - m[:, :3, 3])
    lin_info = np.where(info[:, :3] > _INFO_IGNORED, info[:, :3], np.inf)
    ang_info = np.where(info[:, 3:] > _INFO_IGNORED, info[:, 3:], np.inf)
    lin_sigma = np.sqrt(1.0 / lin_info.min(axis=1))
    ang_sigma = np.sqrt(1.0 / ang_info.min(axis=1))
    lin = np.where(np.isfinite(lin_info), d, 0.0).max(axis=1)
    delta = np.einsum("nji,njk->nik", m[:, :3, :3], t_rot)
    c = np.clip((np.trace(delta, axis1=1, axis2=2) - 1.0) / 2.0, -1.0, 1.0)
    ang = np.arccos(c)
    with np.errstate(divide="ignore", invalid="ignore"):
        lin_ratio = np.where(lin_sigma > 0, lin / lin_sigma, 0.0)
        ang_ratio = np.where(ang_sigma > 0, ang / ang_sigma, 0.0)
    return [LinkError(lk.from_id, lk.to_id, float(x), float(y))
            for lk, x, y in zip(usable, lin_ratio, ang_ratio)]
