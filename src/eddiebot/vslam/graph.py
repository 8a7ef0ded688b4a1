"""Pose-graph optimisation behind a small interface.

With `Reg/Force3DoF` (the report's setting) the graph is SE(2) and runs incrementally in gtsam's
iSAM2: `IncrementalPose2Graph` keeps the graph between calls and folds in only the nodes and
links that are new, so a loop closure costs an iSAM2 update (a few ms at 1,000 nodes) instead of
a batch re-solve of the whole graph. Without Force3DoF the graph is Pose3, solved in batch by
gtsam Levenberg–Marquardt (`GtsamPoseGraph`).

Everything the core needs is `PoseGraphOptimizer.optimize` and `optimized_link_errors` (the
`RGBD/OptimizeMaxError` residuals). Poses and link transforms are 4×4 (m); informations are 6×6
in (x, y, z, roll, pitch, yaw).

`Optimizer/Robust` (both optimisers' `robust`): every switchable link (a loop closure, not
odometry) becomes a Vertigo switchable constraint, as upstream adds them with g2o or GTSAM: a
switch variable s (starting at 1, clamped to [0, 1], with a prior of 1 at σ = 1) scales the
closure's whitened residual and is optimised with the poses, so a closure the rest of the
graph contradicts is switched off (s → 0) instead of bending the map. gtsam's Python wrapper
has no Vertigo factor: `switchable_between` is a `CustomFactor` with the analytic Jacobians.
(gtsam's DCS kernel, the closed form of the switch for the current poses, was tried: from a
dead-reckoned guess 0.5 m off it switched off every true closure of a second lap, where the
joint optimisation of the switches closes them.)
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from functools import lru_cache
from typing import NamedTuple, Protocol

import gtsam
import numpy as np
from numpy.typing import NDArray

from eddiebot.vslam.transforms import yaw_of

__all__ = [
    "GraphLink",
    "GtsamPoseGraph",
    "IncrementalPose2Graph",
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

F64 = NDArray[np.float64]
_FIXED_SIGMA = 1e-6
_IDX_POSE2 = np.array([0, 1, 5])
_IDX_POSE3 = np.array([3, 4, 5, 0, 1, 2])
_INFO_IGNORED = 1e-4
_MIN_VARIANCE = 1e-6  # (1 mm)², (1 mrad)²: floor of link variances in the incremental graph
# anchor of the incremental graph's root (as `eddiebot.slam.pose_graph.PoseGraph`'s node 0)
_PRIOR_NOISE = gtsam.noiseModel.Diagonal.Sigmas(np.array([1e-4, 1e-4, 1e-5]))
#: Vertigo's switch prior (upstream: a switch starting at 1, prior 1 with σ = 1)
_SWITCH_PRIOR = gtsam.noiseModel.Isotropic.Sigma(1, 1.0)
#: keys of switch variables (gtsam symbol 's'), above every node id
_SWITCH_KEY_BASE = gtsam.symbol("s", 0)
_RELINEARIZE_THRESHOLD = 0.01  # iSAM2 relinearisation of the incremental graph (m or rad)


@dataclass(frozen=True)
class GraphLink:
    """A constraint: pose of `to_id` in the frame of `from_id`, with its information matrix."""

    from_id: int
    to_id: int
    transform: F64
    information: F64
    #: a loop closure, which `Optimizer/Robust` may switch off (odometry links: False)
    switchable: bool = False


class LinkLike(Protocol):
    """Anything with a link's fields (`GraphLink`, `eddiebot.vslam.memory.Link`)."""

    @property
    def from_id(self) -> int: ...
    @property
    def to_id(self) -> int: ...
    @property
    def transform(self) -> F64: ...
    @property
    def information(self) -> F64: ...
    @property
    def switchable(self) -> bool: ...


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
        links: Iterable[LinkLike],
        root_id: int,
        iterations: int,
    ) -> dict[int, F64]:
        """Optimised poses of the nodes connected to `root_id` (which stays fixed)."""
        ...


class GtsamPoseGraph:
    """Pose3 (or, with `three_dof`, Pose2) pose graph.

    With `three_dof` and `incremental` (the default) every call is delegated to an
    `IncrementalPose2Graph` (gtsam iSAM2); otherwise each call
    re-solves the whole graph with Levenberg–Marquardt. `robust`: `Optimizer/Robust`.
    """

    def __init__(self, three_dof: bool, epsilon: float = 1e-5, *,
                 incremental: bool = True, robust: bool = False) -> None:
        self.three_dof = three_dof
        self.epsilon = epsilon
        self.robust = robust
        self.switches: dict[tuple[int, int], float] = {}
        """Under `robust`: each switchable link's (from_id, to_id) switch after the last
        batch solve (1 = kept, 0 = switched off)."""
        self.incremental: IncrementalPose2Graph | None = (
            IncrementalPose2Graph(epsilon, robust=robust) if three_dof and incremental else None
        )

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
                key = _SWITCH_KEY_BASE + len(switch_keys)
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
        keys = [k for k in all_keys if k < _SWITCH_KEY_BASE]
        self.switches = {pair: _clamped(result.atVector(k)) for pair, k in switch_keys.items()}
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
    """SE(2) graph kept between calls in gtsam's iSAM2, with its links held as arrays.

    Each `optimize` call receives the whole connected graph (as the batch optimiser does); only
    nodes and links not seen before are folded into iSAM2, with extra relinearisation rounds for
    the first loop closure after a stretch without any. The graph is rebuilt from the given
    poses (one batch-sized iSAM2 update) when it cannot be continued: a link seen before is gone
    (the core removed a closure rejected by `RGBD/OptimizeMaxError`, whose factor iSAM2 had
    already absorbed; the rebuild restarts from the poses the core kept, i.e. the previous
    graph), a node left (memory management), or the root changed. `remove_links` /
    `discard_links` take such a closure out of iSAM2 without a rebuild instead; the core does
    not use them (in the 1,000-node benchmark they let 12 more closures fail the check later).
    `RGBD/OptimizeFromGraphEnd` moves the root every call, so that case is solved in batch.

    Per call the bookkeeping is a few set operations over the link keys; the estimate and the
    `RGBD/OptimizeMaxError` residuals (`link_error_ratios`) are computed on arrays, so the cost
    at ~1,000 nodes is the iSAM2 update itself (a few ms), not Python loops over the graph.
    """

    def __init__(self, epsilon: float = 1e-5,
                 relinearize_threshold: float = _RELINEARIZE_THRESHOLD, *,
                 robust: bool = False) -> None:
        self.epsilon = epsilon
        self.robust = robust
        """`Optimizer/Robust`: loop closures switchable (DCS kernel)."""
        self.relinearize_threshold = relinearize_threshold
        """iSAM2 relinearises a pose whose update exceeds this (m or rad); read when the iSAM2
        graph is (re)built."""
        self.rebuilds = 0
        """How often the incremental graph had to be rebuilt."""
        self.recoveries = 0
        """How often an iSAM2 update failed and the graph was re-solved in batch."""
        self.removed_links = 0
        """Links taken out by `remove_links` (closures rejected after optimisation)."""
        self._batch = GtsamPoseGraph(True, epsilon, incremental=False, robust=robust)
        self._next_switch = _SWITCH_KEY_BASE
        self.reset()

    def reset(self) -> None:
        """Forget the graph (the next call rebuilds it)."""
        self._isam: gtsam.ISAM2 | None = None
        self._index: dict[int, int] = {}  # node id → slot (insertion order)
        self._ids: list[int] = []
        self._xyt = np.zeros((0, 3))
        self._z = np.zeros(0)
        self._order = np.zeros(0, np.int64)  # slots in gtsam key (= id) order
        self._links: dict[tuple[int, int, int], int] = {}  # key → link slot
        self._lk_slots = np.zeros((0, 2), np.int64)
        self._lk_transform = np.zeros((0, 4, 4))
        self._lk_info = np.zeros((0, 6))
        self._lk_factor = np.zeros(0, np.int64)  # iSAM2 factor index
        self._lk_keys: list[tuple[int, int, int]] = []
        self._n_links = 0
        self._root = 0
        self._root_pose: F64 | None = None
        self._closing = False

    def optimize(
        self,
        poses: Mapping[int, F64],
        links: Iterable[LinkLike],
        root_id: int,
        iterations: int,
    ) -> dict[int, F64]:
        """Optimised poses of the component of `root_id` (root fixed at its first pose)."""
        link_list = links if isinstance(links, list) else list(links)
        keyed: dict[tuple[int, int, int], LinkLike] = {
            (lk.from_id, lk.to_id, 0): lk for lk in link_list}
        if len(keyed) != len(link_list):  # parallel links between two nodes
            keyed = {}
            for lk in link_list:
                key = (lk.from_id, lk.to_id, 0)
                while key in keyed:
                    key = (key[0], key[1], key[2] + 1)
                keyed[key] = lk
        root_pose = np.asarray(poses[root_id], dtype=np.float64)
        if (self._root_pose is not None and root_id == self._root
                and not np.allclose(root_pose, self._root_pose, rtol=0.0, atol=1e-3)):
            # the root is re-anchored every call (OptimizeFromGraphEnd): nothing to keep
            self.reset()
            return self._batch.optimize_batch(poses, link_list, root_id, iterations)
        # keys not in the graph; every graph key was given again iff the others number as many
        new_keys = keyed.keys() - self._links.keys()
        if (self._isam is None or root_id != self._root
                or len(keyed) - len(new_keys) != len(self._links)
                or not poses.keys() >= self._index.keys()):
            if self._isam is not None:
                self.rebuilds += 1
            self._start(root_id, root_pose)
            new_keys = set(keyed)
        try:
            self._update(poses, keyed, new_keys)
        except RuntimeError:
            # gtsam reports an ill-conditioned incremental update (a loop edge far from the
            # current linearisation) as IndeterminateSystemException: re-solve in batch and
            # restart iSAM2 from that optimum
            self.recoveries += 1
            solved = self._batch.optimize_batch(poses, link_list, root_id, max(iterations, 100))
            self._start(root_id, root_pose)
            self._update({**poses, **solved}, keyed)
        return dict(zip(self._ids, self.poses_array()))

    def extend(
        self,
        new_poses: Mapping[int, F64],
        new_links: Iterable[LinkLike],
        root_id: int,
        root_pose: F64,
        iterations: int,
        whole: Callable[[], tuple[Mapping[int, F64], Sequence[LinkLike]]],
    ) -> bool:
        """`optimize` for a caller that knows what changed since its last call: the graph
        given then plus the nodes `new_poses` (initial poses) and the links `new_links`, none
        removed (a link whose key the graph holds is skipped, as `optimize` skips it). The
        same iSAM2 update and estimate as `optimize(poses, links, root_id, iterations)` with
        the whole graph, without building it; `whole()` builds it only if an update fails
        (the batch recovery). False, with nothing changed, when the graph cannot be continued
        (no graph yet, another root, the root moved): call `optimize` instead. The estimate:
        `node_ids`, `poses_array`."""
        if self._isam is None or root_id != self._root or self._root_pose is None:
            return False
        root_pose = np.asarray(root_pose, dtype=np.float64)
        if not np.allclose(root_pose, self._root_pose, rtol=0.0, atol=1e-3):
            return False
        keyed: dict[tuple[int, int, int], LinkLike] = {}
        for lk in new_links:
            key = (lk.from_id, lk.to_id, 0)
            while key in keyed:
                key = (key[0], key[1], key[2] + 1)
            keyed[key] = lk
        new_keys = keyed.keys() - self._links.keys()
        try:
            self._update(new_poses, keyed, new_keys)
        except RuntimeError:
            poses, link_list = whole()
            self._recover(poses, link_list, root_id, root_pose, iterations)
        return True

    def _recover(self, poses: Mapping[int, F64], links: Sequence[LinkLike], root_id: int,
                 root_pose: F64, iterations: int) -> None:
        """Re-solve in batch after a failed iSAM2 update and restart iSAM2 from that optimum."""
        link_list = list(links)
        keyed: dict[tuple[int, int, int], LinkLike] = {}
        for lk in link_list:
            key = (lk.from_id, lk.to_id, 0)
            while key in keyed:
                key = (key[0], key[1], key[2] + 1)
            keyed[key] = lk
        self.recoveries += 1
        solved = self._batch.optimize_batch(poses, link_list, root_id, max(iterations, 100))
        self._start(root_id, root_pose)
        self._update({**poses, **solved}, keyed)

    @property
    def node_count(self) -> int:
        """Nodes in the graph."""
        return len(self._ids)

    @property
    def root_id(self) -> int:
        """The graph's root (fixed node)."""
        return self._root

    def knows(self, node_id: int) -> bool:
        """True when the node is in the graph."""
        return node_id in self._index

    @property
    def node_ids(self) -> list[int]:
        """Ids in the graph, in the order of `poses_array`."""
        return list(self._ids)

    def poses_array(self) -> F64:
        """Current estimates as 4×4 matrices (N, 4, 4), z kept from each node's input pose."""
        xyt = self._xyt
        c, s = np.cos(xyt[:, 2]), np.sin(xyt[:, 2])
        mats = np.zeros((len(xyt), 4, 4))
        mats[:, 0, 0], mats[:, 0, 1], mats[:, 1, 0], mats[:, 1, 1] = c, -s, s, c
        mats[:, 2, 2] = mats[:, 3, 3] = 1.0
        mats[:, 0, 3], mats[:, 1, 3], mats[:, 2, 3] = xyt[:, 0], xyt[:, 1], self._z
        return mats

    def link_error_ratios(self) -> tuple[NDArray[np.int64], F64, F64]:
        """`RGBD/OptimizeMaxError` residuals of every link in the graph at the current estimate:
        ((from_id, to_id) rows, linear ratios, angular ratios), as `link_errors` computes them."""
        n = self._n_links
        fr, to = self._lk_slots[:n, 0], self._lk_slots[:n, 1]
        m = self._lk_transform[:n]
        xa, xb = self._xyt[fr], self._xyt[to]
        # T = inv(A) B for planar A, B: Rz(θb − θa), Rz(−θa)(tb − ta), z difference
        ca, sa = np.cos(xa[:, 2]), np.sin(xa[:, 2])
        dx, dy = xb[:, 0] - xa[:, 0], xb[:, 1] - xa[:, 1]
        t = np.stack([ca * dx + sa * dy, -sa * dx + ca * dy, self._z[to] - self._z[fr]], axis=1)
        phi = xb[:, 2] - xa[:, 2]
        c, s = np.cos(phi), np.sin(phi)
        # R = Mᵀ Rz(φ): its trace and the axis vector of R − Rᵀ (2 sin θ along the axis)
        trace = c * (m[:, 0, 0] + m[:, 1, 1]) + s * (m[:, 1, 0] - m[:, 0, 1]) + m[:, 2, 2]
        v0 = c * m[:, 1, 2] - s * m[:, 0, 2] - m[:, 2, 1]
        v1 = m[:, 2, 0] - c * m[:, 0, 2] - s * m[:, 1, 2]
        v2 = c * (m[:, 0, 1] - m[:, 1, 0]) + s * (m[:, 0, 0] + m[:, 1, 1])
        two_sin = np.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
        lin, ang = _ratios(np.abs(t - m[:, :3, 3]), two_sin, trace, self._lk_info[:n])
        ids = np.asarray(self._ids, np.int64)
        return ids[self._lk_slots[:n]], lin, ang

    # -- internals --------------------------------------------------------------------------
    def _start(self, root_id: int, root_pose: F64) -> None:
        self.reset()
        params = gtsam.ISAM2Params()
        # 0.01 by default (gtsam's own default is 0.1); 0.05 was faster on a synthetic circle
        # but not on the 1,000-node benchmark (docs/benchmarks/vslam.md#vslam-loop)
        params.setRelinearizeThreshold(self.relinearize_threshold)
        params.relinearizeSkip = 1
        self._isam = gtsam.ISAM2(params)
        self._root = root_id
        self._root_pose = root_pose.copy()

    def _update(self, poses: Mapping[int, F64],
                keyed: Mapping[tuple[int, int, int], LinkLike],
                new_keys: Iterable[tuple[int, int, int]] | None = None) -> None:
        isam = self._isam
        assert isam is not None
        factors = gtsam.NonlinearFactorGraph()
        values = gtsam.Values()
        new_ids: list[int] = []
        if not self._index:
            root = self._root
            factors.add(gtsam.PriorFactorPose2(root, _pose2(poses[root]), _PRIOR_NOISE))
            self._add_node(root, poses[root], values, new_ids)
        if new_keys is None:
            new_keys = keyed.keys() - self._links.keys()
        # (a node of the graph is in `poses` unless the caller gave only new ones: `extend`)
        index = self._index
        fresh = [(key, keyed[key]) for key in new_keys
                 if (key[0] in poses or key[0] in index) and (key[1] in poses or key[1] in index)]
        fresh.sort(key=lambda kv: kv[0])
        # attach new nodes through new links (the root's component only)
        pending = fresh
        while pending:
            left = []
            for key, lk in pending:
                a, b = lk.from_id in self._index, lk.to_id in self._index
                if a == b:
                    left.append((key, lk))
                    continue
                new_id = lk.to_id if a else lk.from_id
                self._add_node(new_id, poses[new_id], values, new_ids)
            if len(left) == len(pending):
                break
            pending = left
        loop = False
        added: list[tuple[tuple[int, int, int], LinkLike]] = []
        positions: list[int] = []  # each added link's factor among the new factors
        for key, lk in fresh:
            i, j = self._index.get(lk.from_id), self._index.get(lk.to_id)
            if i is None or j is None or i == j:
                continue
            loop |= abs(i - j) != 1
            info = np.asarray(lk.information, dtype=np.float64)
            sub = info[_IDX_POSE2[:, None], _IDX_POSE2]
            noise = gtsam.noiseModel.Gaussian.Covariance(_floored_covariance(sub))
            if self.robust and lk.switchable:
                add_switchable(factors, values, lk.from_id, lk.to_id, lk.transform, noise,
                               self._next_switch, True)
                self._next_switch += 1
            else:
                factors.add(gtsam.BetweenFactorPose2(lk.from_id, lk.to_id,
                                                     _pose2(np.asarray(lk.transform)), noise))
            positions.append(factors.size() - 1)  # (a switchable link's factor is its last)
            added.append((key, lk))
        if new_ids:
            self._grow_nodes(new_ids, poses)
        result = isam.update(factors, values)
        indices = list(result.getNewFactorsIndices())
        first = factors.size() - len(indices)  # (the root's prior, if any, is among them)
        self._add_links(added, [indices[k - first] for k in positions])
        # extra relinearisation rounds for the first closure after a stretch without any;
        # while closures come every call, each update relinearises anyway
        for _ in range(4 if loop and not self._closing else 0):
            isam.update()
        self._closing = loop
        self._xyt[self._order] = gtsam.utilities.extractPose2(isam.calculateEstimate())

    def _add_node(self, node_id: int, pose: F64, values: gtsam.Values,
                  new_ids: list[int]) -> None:
        self._index[node_id] = len(self._ids)
        self._ids.append(node_id)
        values.insert(node_id, _pose2(np.asarray(pose, dtype=np.float64)))
        new_ids.append(node_id)

    def _grow_nodes(self, new_ids: list[int], poses: Mapping[int, F64]) -> None:
        new = np.array([_xyt(np.asarray(poses[i], dtype=np.float64)) for i in new_ids])
        self._xyt = np.concatenate([self._xyt, new])
        self._z = np.concatenate([self._z, [float(poses[i][2, 3]) for i in new_ids]])
        self._order = np.argsort(np.asarray(self._ids, np.int64), kind="stable")

    def _add_links(self, added: list[tuple[tuple[int, int, int], LinkLike]],
                   factors: list[int]) -> None:
        if not added:
            return
        n, m = self._n_links, len(added)
        if n + m > len(self._lk_slots):
            cap = max(n + m, 2 * len(self._lk_slots), 64)
            self._lk_slots = np.resize(self._lk_slots, (cap, 2))
            self._lk_transform = np.resize(self._lk_transform, (cap, 4, 4))
            self._lk_info = np.resize(self._lk_info, (cap, 6))
            self._lk_factor = np.resize(self._lk_factor, cap)
        for k, (key, lk) in enumerate(added):
            self._links[key] = n + k
            self._lk_keys.append(key)
            self._lk_slots[n + k] = (self._index[lk.from_id], self._index[lk.to_id])
            self._lk_transform[n + k] = lk.transform
            self._lk_info[n + k] = np.diagonal(np.asarray(lk.information, dtype=np.float64))
            self._lk_factor[n + k] = factors[k]
        self._n_links = n + m

    def remove_links(self, pairs: Iterable[tuple[int, int]]) -> int:
        """Take links (from_id, to_id), as given to `optimize`, out of the graph: their factors
        leave iSAM2 and the estimate relinearises without them, so the next `optimize` call
        (whose links no longer hold them) continues instead of rebuilding. Links whose removal
        would cut a node off (chain links) are left for that rebuild. Returns how many left."""
        if self._isam is None:
            return 0
        slots = []
        for a, b in pairs:
            for key in ((a, b, 0), (b, a, 0)):
                slot = self._links.get(key)
                if slot is not None:
                    i, j = self._lk_slots[slot]
                    if abs(int(i) - int(j)) != 1:
                        slots.append(slot)
        if not slots:
            return 0
        self._isam.update(gtsam.NonlinearFactorGraph(), gtsam.Values(),
                          [int(self._lk_factor[k]) for k in slots])
        self._isam.update()
        for slot in sorted(slots, reverse=True):
            self._drop_link_slot(slot)
        self._xyt[self._order] = gtsam.utilities.extractPose2(self._isam.calculateEstimate())
        self.removed_links += len(slots)
        return len(slots)

    def _drop_link_slot(self, slot: int) -> None:
        last = self._n_links - 1
        del self._links[self._lk_keys[slot]]
        if slot != last:
            moved = self._lk_keys[last]
            self._links[moved] = slot
            self._lk_keys[slot] = moved
            for arr in (self._lk_slots, self._lk_transform, self._lk_info, self._lk_factor):
                arr[slot] = arr[last]
        self._lk_keys.pop()
        self._n_links = last


def make_optimizer(force_3dof: bool, epsilon: float = 1e-5,
                   robust: bool = False) -> PoseGraphOptimizer:
    """The back end for `Reg/Force3DoF`: incremental SE(2) if true, batch Pose3 otherwise;
    `robust`: `Optimizer/Robust`."""
    if force_3dof:
        return IncrementalPose2Graph(epsilon, robust=robust)
    return GtsamPoseGraph(False, epsilon, robust=robust)


def add_switchable(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values, from_id: int,
                   to_id: int, transform: F64, noise: gtsam.noiseModel.Base, switch_key: int,
                   three_dof: bool) -> None:
    """A Vertigo switchable constraint: the switch variable `switch_key` (initial 1) with its
    prior, then the link's factor scaled by the switch (`switchable_between`)."""
    values.insert(switch_key, np.array([1.0]))
    graph.add(gtsam.PriorFactorVector(switch_key, np.array([1.0]), _SWITCH_PRIOR))
    graph.add(switchable_between(from_id, to_id, switch_key, transform, noise, three_dof))


def switchable_between(from_id: int, to_id: int, switch_key: int, transform: F64,
                       noise: gtsam.noiseModel.Base, three_dof: bool) -> gtsam.CustomFactor:
    """Vertigo's `BetweenFactorSwitchableLinear`: s · (gtsam BetweenFactor's error), s the
    switch clamped to [0, 1] (Vertigo's `SwitchVariableLinear` clamps on retract; here the
    value is clamped where used, and its Jacobian stays the unscaled error so a switch pushed
    past a bound can come back)."""
    if three_dof:
        measured2 = _pose2(np.asarray(transform, dtype=np.float64))

        def error2(this: gtsam.CustomFactor, v: gtsam.Values,
                   jacobians: list[NDArray[np.float64]] | None) -> NDArray[np.float64]:
            a, b = v.atPose2(from_id), v.atPose2(to_id)
            s = _clamped(v.atVector(switch_key))
            ha, hb = np.zeros((3, 3), order="F"), np.zeros((3, 3), order="F")
            hx = a.between(b, ha, hb)
            hm1, hm2 = np.zeros((3, 3), order="F"), np.zeros((3, 3), order="F")
            delta = measured2.between(hx, hm1, hm2)
            hlog = np.zeros((3, 3), order="F")
            e = np.asarray(gtsam.Pose2.Logmap(delta, hlog), dtype=np.float64)
            if jacobians is not None:
                d = hlog @ hm2
                jacobians[0] = s * (d @ ha)
                jacobians[1] = s * (d @ hb)
                jacobians[2] = e.reshape(3, 1)
            return s * e

        return gtsam.CustomFactor(noise, [from_id, to_id, switch_key], error2)
    measured3 = _pose3(np.asarray(transform, dtype=np.float64))

    def error3(this: gtsam.CustomFactor, v: gtsam.Values,
               jacobians: list[NDArray[np.float64]] | None) -> NDArray[np.float64]:
        a, b = v.atPose3(from_id), v.atPose3(to_id)
        s = _clamped(v.atVector(switch_key))
        ha, hb = np.zeros((6, 6), order="F"), np.zeros((6, 6), order="F")
        hx = a.between(b, ha, hb)
        hm1, hm2 = np.zeros((6, 6), order="F"), np.zeros((6, 6), order="F")
        delta = measured3.between(hx, hm1, hm2)
        hlog = np.zeros((6, 6), order="F")
        e = np.asarray(gtsam.Pose3.Logmap(delta, hlog), dtype=np.float64)
        if jacobians is not None:
            d = hlog @ hm2
            jacobians[0] = s * (d @ ha)
            jacobians[1] = s * (d @ hb)
            jacobians[2] = e.reshape(6, 1)
        return s * e

    return gtsam.CustomFactor(noise, [from_id, to_id, switch_key], error3)


def _clamped(switch: NDArray[np.float64]) -> float:
    return min(max(float(switch[0]), 0.0), 1.0)


def _floored_covariance(information: F64) -> F64:
    """Σ = Ω⁻¹ with eigenvalues ≥ `_MIN_VARIANCE`: near-exact registrations (σ ≈ 0.1 mm on
    synthetic images) next to the anchor prior otherwise make iSAM2's Cholesky ill-posed.
    Cached by the matrix's bytes: a rebuilt graph re-adds the same links (read-only result)."""
    info = np.ascontiguousarray(information, dtype=np.float64)
    return _floored_covariance_of(info.tobytes(), info.shape)


@lru_cache(maxsize=1 << 16)
def _floored_covariance_of(data: bytes, shape: tuple[int, ...]) -> F64:
    information = np.frombuffer(data, dtype=np.float64).reshape(shape)
    w, v = np.linalg.eigh(0.5 * (information + information.T))
    w = 1.0 / np.clip(w, 1e-12, None)
    out = np.asarray((v * np.clip(w, _MIN_VARIANCE, None)) @ v.T)
    out.flags.writeable = False
    return out


def _xyt(t: F64) -> F64:
    return np.array([float(t[0, 3]), float(t[1, 3]), yaw_of(t)])


def _pose2(t: F64) -> gtsam.Pose2:
    return gtsam.Pose2(float(t[0, 3]), float(t[1, 3]), yaw_of(t))


def _pose3(t: F64) -> gtsam.Pose3:
    return gtsam.Pose3(np.asarray(t, dtype=np.float64))


def _component(root: int, links: list[LinkLike]) -> set[int]:
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


def link_errors(poses: Mapping[int, F64], links: Iterable[LinkLike]) -> list[LinkError]:
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
    lin_ratio, ang_ratio = _error_ratios(a, b, m, info)
    return [LinkError(lk.from_id, lk.to_id, x, y)
            for lk, x, y in zip(usable, lin_ratio.tolist(), ang_ratio.tolist())]


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


def _error_ratios(a: F64, b: F64, m: F64, info: F64) -> tuple[F64, F64]:
    """Linear and angular ratios of links with poses `a` (from), `b` (to), transforms `m`
    (all (L, 4, 4)) and information diagonals `info` (L, 6)."""
    ra = a[:, :3, :3]
    # T = inv(A) B
    t_rot = np.einsum("nji,njk->nik", ra, b[:, :3, :3])
    t_tr = np.einsum("nji,nj->ni", ra, b[:, :3, 3] - a[:, :3, 3])
    rot = np.einsum("nji,njk->nik", m[:, :3, :3], t_rot)  # Mᵀ T
    axis = np.stack([rot[:, 2, 1] - rot[:, 1, 2], rot[:, 0, 2] - rot[:, 2, 0],
                     rot[:, 1, 0] - rot[:, 0, 1]], axis=1)
    two_sin = np.sqrt(np.einsum("ni,ni->n", axis, axis))
    trace = rot[:, 0, 0] + rot[:, 1, 1] + rot[:, 2, 2]
    return _ratios(np.abs(t_tr - m[:, :3, 3]), two_sin, trace, info)


def _ratios(d: F64, two_sin: F64, trace: F64, info: F64) -> tuple[F64, F64]:
    """Ratios from per-axis translation deviations `d` (L, 3), the rotation errors R = Mᵀ T
    as 2 sin θ (the norm of R − Rᵀ's axis vector) and trace(R) = 1 + 2 cos θ, and information
    diagonals (L, 6)."""
    lin_info = np.where(info[:, :3] > _INFO_IGNORED, info[:, :3], np.inf)
    ang_info = np.where(info[:, 3:] > _INFO_IGNORED, info[:, 3:], np.inf)
    # σ floored as the incremental graph floors link variances, so the check judges the
    # optimum by the noise it was computed with; minima and maxima over the three columns
    # element-wise (the values of `.min(axis=1)`, without its per-row reduction cost)
    lin_sigma = np.sqrt(np.maximum(1.0 / _min3(lin_info), _MIN_VARIANCE))
    ang_sigma = np.sqrt(np.maximum(1.0 / _min3(ang_info), _MIN_VARIANCE))
    lin_d = np.where(np.isfinite(lin_info), d, 0.0)
    lin = np.maximum(np.maximum(lin_d[:, 0], lin_d[:, 1]), lin_d[:, 2])
    # θ = atan2(2 sin θ, 2 cos θ): arccos of the trace alone cannot resolve angles below
    # ~2e-8 rad, so two exact formulas for the same link disagreed
    ang = np.arctan2(two_sin, trace - 1.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        lin_ratio = np.where(lin_sigma > 0, lin / lin_sigma, 0.0)
        ang_ratio = np.where(ang_sigma > 0, ang / ang_sigma, 0.0)
    return lin_ratio, ang_ratio


def _min3(a: F64) -> F64:
    return np.minimum(np.minimum(a[:, 0], a[:, 1]), a[:, 2])
