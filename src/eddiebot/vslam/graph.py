"""Pose-graph optimisation behind a small interface.

With `Reg/Force3DoF` (the report's setting) the graph is SE(2) and runs incrementally on the 2D
SLAM's `eddiebot.slam.pose_graph.PoseGraph` (iSAM2): `IncrementalPose2Graph` keeps the graph
between calls and folds in only the nodes and links that are new, so a loop closure costs an
iSAM2 update instead of a batch re-solve of the whole graph. Without Force3DoF the graph is
Pose3, solved in batch by gtsam Levenberg–Marquardt (`GtsamPoseGraph`).

Everything the core needs is `PoseGraphOptimizer.optimize` and `link_errors`. Poses and link
transforms are 4×4 (m); informations are 6×6 in (x, y, z, roll, pitch, yaw).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import NamedTuple, Protocol

import gtsam
import numpy as np
from numpy.typing import NDArray

from eddiebot.slam.pose_graph import EdgeKind, PoseGraph
from eddiebot.vslam.transforms import yaw_of

__all__ = [
    "GraphLink",
    "GtsamPoseGraph",
    "IncrementalPose2Graph",
    "LinkError",
    "PoseGraphOptimizer",
    "link_errors",
    "make_optimizer",
]

F64 = NDArray[np.float64]
_FIXED_SIGMA = 1e-6
_IDX_POSE2 = np.array([0, 1, 5])
_IDX_POSE3 = np.array([3, 4, 5, 0, 1, 2])
_INFO_IGNORED = 1e-4
_MIN_VARIANCE = 1e-6  # (1 mm)², (1 mrad)²: floor of link variances in the incremental graph


@dataclass(frozen=True)
class GraphLink:
    """A constraint: pose of `to_id` in the frame of `from_id`, with its information matrix."""

    from_id: int
    to_id: int
    transform: F64
    information: F64


class LinkError(NamedTuple):
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
    """Pose3 (or, with `three_dof`, Pose2) pose graph.

    With `three_dof` and `incremental` (the default) every call is delegated to an
    `IncrementalPose2Graph` (iSAM2 on `eddiebot.slam.pose_graph.PoseGraph`); otherwise each call
    re-solves the whole graph with Levenberg–Marquardt.
    """

    def __init__(self, three_dof: bool, epsilon: float = 1e-5, *,
                 incremental: bool = True) -> None:
        self.three_dof = three_dof
        self.epsilon = epsilon
        self.incremental: IncrementalPose2Graph | None = (
            IncrementalPose2Graph(epsilon) if three_dof and incremental else None
        )

    def optimize(
        self,
        poses: Mapping[int, F64],
        links: Iterable[GraphLink],
        root_id: int,
        iterations: int,
    ) -> dict[int, F64]:
        """Optimise the component of `root_id`; nodes not connected to it are left out."""
        if self.incremental is not None:
            return self.incremental.optimize(poses, links, root_id, iterations)
        return self.optimize_batch(poses, links, root_id, iterations)

    def optimize_batch(
        self,
        poses: Mapping[int, F64],
        links: Iterable[GraphLink],
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


class IncrementalPose2Graph:
    """SE(2) graph kept between calls on `eddiebot.slam.pose_graph.PoseGraph` (iSAM2).

    Each `optimize` call receives the whole connected graph (as the batch optimiser does); only
    nodes and links not seen before are folded into iSAM2, with extra relinearisation rounds when
    a new link closes a loop. The graph is rebuilt from the given poses (one batch-sized iSAM2
    update) when it cannot be continued: a link seen before is gone (the core removed a closure
    rejected by `RGBD/OptimizeMaxError`, whose factor iSAM2 had already absorbed), a node left
    (memory management), or the root changed. `RGBD/OptimizeFromGraphEnd` moves the root every
    call, so that case is solved in batch.
    """

    def __init__(self, epsilon: float = 1e-5) -> None:
        self.epsilon = epsilon
        self.rebuilds = 0
        """How often the incremental graph had to be rebuilt."""
        self._graph: PoseGraph | None = None
        self._index: dict[int, int] = {}
        self._ids: list[int] = []
        self._links: set[tuple[int, int, int]] = set()
        self._root = 0
        self._root_pose: F64 | None = None
        self._closing = False
        self._batch = GtsamPoseGraph(True, epsilon, incremental=False)

    def reset(self) -> None:
        """Forget the graph (the next call rebuilds it)."""
        self._graph = None
        self._index = {}
        self._ids = []
        self._links = set()
        self._root_pose = None
        self._closing = False

    def optimize(
        self,
        poses: Mapping[int, F64],
        links: Iterable[GraphLink],
        root_id: int,
        iterations: int,
    ) -> dict[int, F64]:
        """Optimised poses of the component of `root_id` (root fixed at its first pose)."""
        link_list = [lk for lk in links if lk.from_id in poses and lk.to_id in poses]
        keyed: dict[tuple[int, int, int], GraphLink] = {}
        for lk in link_list:
            k = 0
            while (lk.from_id, lk.to_id, k) in keyed:
                k += 1
            keyed[(lk.from_id, lk.to_id, k)] = lk
        root_pose = np.asarray(poses[root_id], dtype=np.float64)
        if (self._root_pose is not None and root_id == self._root
                and not np.allclose(root_pose, self._root_pose, rtol=0.0, atol=1e-3)):
            # the root is re-anchored every call (OptimizeFromGraphEnd): nothing to keep
            self.reset()
            return self._batch.optimize_batch(poses, link_list, root_id, iterations)
        if (self._graph is None or root_id != self._root
                or not self._links.issubset(keyed.keys())
                or any(i not in poses for i in self._ids)):
            if self._graph is not None:
                self.rebuilds += 1
            self.reset()
            self._graph = PoseGraph(optimizer="isam2", robust_kernel="none")
            self._root = root_id
            self._root_pose = root_pose.copy()
        graph = self._graph
        assert graph is not None
        if not self._index:
            self._index[root_id] = graph.add_node(_xyt(poses[root_id]))
            self._ids.append(root_id)
        # attach new nodes through new links to the graph (the root's component only)
        fresh = [(key, lk) for key, lk in keyed.items() if key not in self._links]
        pending = fresh
        while pending:
            left = []
            for key, lk in pending:
                a, b = lk.from_id in self._index, lk.to_id in self._index
                if a == b:
                    left.append((key, lk))
                    continue
                new_id = lk.to_id if a else lk.from_id
                self._index[new_id] = graph.add_node(_xyt(poses[new_id]))
                self._ids.append(new_id)
            if len(left) == len(pending):
                break
            pending = left
        loop = False
        for key, lk in fresh:
            if lk.from_id not in self._index or lk.to_id not in self._index:
                continue
            i, j = self._index[lk.from_id], self._index[lk.to_id]
            if i == j:
                continue
            chain = abs(i - j) == 1
            loop |= not chain
            sub = np.asarray(lk.information, dtype=np.float64)[_IDX_POSE2[:, None], _IDX_POSE2]
            graph.add_edge(i, j, _xyt(lk.transform), _floored_covariance(sub),
                           kind=EdgeKind.ODOMETRY if chain else EdgeKind.LOOP)
            self._links.add(key)
        # extra relinearisation rounds for the first closure after a stretch without any;
        # while closures come every call, each update relinearises anyway
        full = loop and not self._closing
        self._closing = loop
        graph.optimize(full=full)
        xyt = graph.poses
        c, s = np.cos(xyt[:, 2]), np.sin(xyt[:, 2])
        mats = np.zeros((len(xyt), 4, 4))
        mats[:, 0, 0], mats[:, 0, 1], mats[:, 1, 0], mats[:, 1, 1] = c, -s, s, c
        mats[:, 2, 2] = mats[:, 3, 3] = 1.0
        mats[:, 0, 3], mats[:, 1, 3] = xyt[:, 0], xyt[:, 1]
        # keep the out-of-plane part (z) of the input pose, as RTAB-Map's 2D optimisers
        mats[:, 2, 3] = [float(poses[i][2, 3]) for i in self._ids]
        return dict(zip(self._ids, mats))


def make_optimizer(force_3dof: bool, epsilon: float = 1e-5) -> PoseGraphOptimizer:
    """The back end for `Reg/Force3DoF`: incremental SE(2) if true, batch Pose3 otherwise."""
    if force_3dof:
        return IncrementalPose2Graph(epsilon)
    return GtsamPoseGraph(False, epsilon)


def _floored_covariance(information: F64) -> F64:
    """Σ = Ω⁻¹ with eigenvalues ≥ `_MIN_VARIANCE`: near-exact registrations (σ ≈ 0.1 mm on
    synthetic images) next to the anchor prior otherwise make iSAM2's Cholesky ill-posed."""
    w, v = np.linalg.eigh(0.5 * (information + information.T))
    w = 1.0 / np.clip(w, 1e-12, None)
    return np.asarray((v * np.clip(w, _MIN_VARIANCE, None)) @ v.T)


def _xyt(t: F64) -> F64:
    return np.array([float(t[0, 3]), float(t[1, 3]), yaw_of(t)])


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
    terms ≤ 1e-4, so a huge z variance of planar odometry does not count; σ² is floored at
    1e-6 (1 mm, 1 mrad) as in `IncrementalPose2Graph`.
    """
    usable = [lk for lk in links if lk.from_id in poses and lk.to_id in poses]
    if not usable:
        return []
    a = np.stack([poses[lk.from_id] for lk in usable])
    b = np.stack([poses[lk.to_id] for lk in usable])
    m = np.stack([lk.transform for lk in usable])
    info = np.diagonal(np.stack([lk.information for lk in usable]), axis1=1, axis2=2)
    ra = a[:, :3, :3]
    # T = inv(A) B
    t_rot = np.einsum("nji,njk->nik", ra, b[:, :3, :3])
    t_tr = np.einsum("nji,nj->ni", ra, b[:, :3, 3] - a[:, :3, 3])
    d = np.abs(t_tr - m[:, :3, 3])
    lin_info = np.where(info[:, :3] > _INFO_IGNORED, info[:, :3], np.inf)
    ang_info = np.where(info[:, 3:] > _INFO_IGNORED, info[:, 3:], np.inf)
    # σ floored as the incremental graph floors link variances, so the check judges the
    # optimum by the noise it was computed with
    lin_sigma = np.sqrt(np.maximum(1.0 / lin_info.min(axis=1), _MIN_VARIANCE))
    ang_sigma = np.sqrt(np.maximum(1.0 / ang_info.min(axis=1), _MIN_VARIANCE))
    lin = np.where(np.isfinite(lin_info), d, 0.0).max(axis=1)
    delta = np.einsum("nji,njk->nik", m[:, :3, :3], t_rot)
    c = np.clip((np.trace(delta, axis1=1, axis2=2) - 1.0) / 2.0, -1.0, 1.0)
    ang = np.arccos(c)
    with np.errstate(divide="ignore", invalid="ignore"):
        lin_ratio = np.where(lin_sigma > 0, lin / lin_sigma, 0.0)
        ang_ratio = np.where(ang_sigma > 0, ang / ang_sigma, 0.0)
    return [LinkError(lk.from_id, lk.to_id, x, y)
            for lk, x, y in zip(usable, lin_ratio.tolist(), ang_ratio.tolist())]
