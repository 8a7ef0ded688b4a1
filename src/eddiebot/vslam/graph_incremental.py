"""The incremental SE(2) pose graph (gtsam iSAM2) behind `Reg/Force3DoF`."""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence

import gtsam
import numpy as np
from numpy.typing import NDArray

from eddiebot.vslam.graph_batch import BatchPoseGraph
from eddiebot.vslam.graph_isam import IsamGraph, keyed_links
from eddiebot.vslam.graph_links import (
    _IDX_POSE2,
    F64,
    LinkLike,
    _floored_covariance,
    _pose2,
    _ratios,
    _xyt,
)
from eddiebot.vslam.switchable import SWITCH_KEY_BASE, add_switchable

__all__ = ["IncrementalPose2Graph"]

# anchor of the incremental graph's root (as `eddiebot.slam.pose_graph.PoseGraph`'s node 0)
_PRIOR_NOISE = gtsam.noiseModel.Diagonal.Sigmas(np.array([1e-4, 1e-4, 1e-5]))
_RELINEARIZE_THRESHOLD = 0.01  # iSAM2 relinearisation of the incremental graph (m or rad)


class IncrementalPose2Graph(IsamGraph):
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
        self._batch = BatchPoseGraph(True, epsilon, robust=robust)
        self._next_switch = SWITCH_KEY_BASE
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
        keyed = keyed_links(new_links)
        new_keys = keyed.keys() - self._links.keys()
        try:
            self._update(new_poses, keyed, new_keys)
        except RuntimeError:
            poses, link_list = whole()
            self._recover(poses, link_list, root_id, root_pose, iterations)
        return True

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

    def _estimate(self) -> F64:
        return self.poses_array()

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

