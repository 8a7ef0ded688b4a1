"""The incremental Pose3 graph (gtsam iSAM2, RTAB-Map's `GTSAM/Incremental`) behind the 6DoF
core: a loop closure costs an iSAM2 update instead of a Levenberg–Marquardt re-solve of the
whole graph."""

from __future__ import annotations

from collections.abc import Iterable, Mapping

import gtsam
import numpy as np
from numpy.typing import NDArray

from eddiebot.vslam.graph_batch import BatchPoseGraph
from eddiebot.vslam.graph_isam import IsamGraph
from eddiebot.vslam.graph_links import (
    _FIXED_SIGMA,
    F64,
    LinkLike,
    _component,
    _error_ratios,
    _pose3,
)

__all__ = ["IncrementalPose3Graph"]

_RELINEARIZE_THRESHOLD = 0.01  # as the SE(2) graph and upstream GTSAM/IncRelinearizeThreshold


class IncrementalPose3Graph(IsamGraph):
    """Pose3 graph kept between calls in gtsam's iSAM2, with its links held as arrays.

    Each `optimize` call receives the whole connected graph (as the batch optimiser does); the
    nodes and links not seen before are folded into iSAM2 (noise models as the batch
    optimiser's), with extra relinearisation rounds for the first loop closure after a stretch
    without any. The graph is rebuilt from the given poses (one batch-sized iSAM2 update) when
    it cannot be continued: a link seen before is gone (a closure rejected by
    `RGBD/OptimizeMaxError`; the core restarts from the poses it kept), a node left (memory
    management), the root changed or moved (`RGBD/OptimizeFromGraphEnd`: solved in batch). A
    failed iSAM2 update (ill-conditioned) is re-solved in batch and iSAM2 restarts from there.
    """

    def __init__(self, epsilon: float = 1e-5,
                 relinearize_threshold: float = _RELINEARIZE_THRESHOLD) -> None:
        self.epsilon = epsilon
        self.relinearize_threshold = relinearize_threshold
        self.rebuilds = 0
        """How often the incremental graph had to be rebuilt."""
        self.recoveries = 0
        """How often an iSAM2 update failed and the graph was re-solved in batch."""
        self._batch = BatchPoseGraph(False, epsilon)
        self.reset()

    def reset(self) -> None:
        """Forget the graph (the next call rebuilds it)."""
        self._isam: gtsam.ISAM2 | None = None
        self._ids: list[int] = []
        self._index: dict[int, int] = {}
        self._est = np.zeros((0, 4, 4))
        self._order = np.zeros(0, np.int64)  # slots in gtsam key (= id) order
        self._links: set[tuple[int, int, int]] = set()
        self._lk_slots = np.zeros((0, 2), np.int64)
        self._lk_transform = np.zeros((0, 4, 4))
        self._lk_info = np.zeros((0, 6))
        self._n_links = 0
        self._root = 0
        self._root_pose: F64 | None = None
        self._closing = False

    @property
    def node_count(self) -> int:
        """Nodes in the graph."""
        return len(self._ids)

    def _estimate(self) -> F64:
        return self._est

    def link_error_ratios(self) -> tuple[NDArray[np.int64], F64, F64]:
        """`RGBD/OptimizeMaxError` residuals of every link in the graph at the current estimate:
        ((from_id, to_id) rows, linear ratios, angular ratios), as `link_errors` computes them."""
        n = self._n_links
        slots = self._lk_slots[:n]
        lin, ang = _error_ratios(self._est[slots[:, 0]], self._est[slots[:, 1]],
                                 self._lk_transform[:n], self._lk_info[:n])
        ids = np.asarray(self._ids, np.int64)
        return ids[slots], lin, ang

    # -- internals --------------------------------------------------------------------------
    def _update(self, poses: Mapping[int, F64], keyed: Mapping[tuple[int, int, int], LinkLike],
                new_keys: Iterable[tuple[int, int, int]]) -> None:
        isam = self._isam
        assert isam is not None
        factors = gtsam.NonlinearFactorGraph()
        values = gtsam.Values()
        new_ids: list[int] = []
        index = self._index
        fresh = sorted(key for key in new_keys
                       if (key[0] in poses or key[0] in index)
                       and (key[1] in poses or key[1] in index))
        if not index:
            root = self._root
            factors.add(gtsam.PriorFactorPose3(root, _pose3(poses[root]),
                                               gtsam.noiseModel.Isotropic.Sigma(6, _FIXED_SIGMA)))
            reach = _component(root, [keyed[k] for k in fresh])
            for node_id in sorted(reach):
                self._add_node(node_id, poses, values, new_ids)
        else:
            pending = fresh
            while pending:  # attach new nodes through new links (the root's component only)
                left = []
                for key in pending:
                    lk = keyed[key]
                    a, b = lk.from_id in index, lk.to_id in index
                    if a == b:
                        left.append(key)
                    elif (lk.to_id if a else lk.from_id) in poses:
                        self._add_node(lk.to_id if a else lk.from_id, poses, values, new_ids)
                if len(left) == len(pending):
                    break
                pending = left
        loop = False
        added: list[LinkLike] = []
        for key in fresh:
            lk = keyed[key]
            i, j = index.get(lk.from_id), index.get(lk.to_id)
            if i is None or j is None or i == j:
                continue
            loop |= abs(i - j) != 1
            factors.add(gtsam.BetweenFactorPose3(lk.from_id, lk.to_id, _pose3(lk.transform),
                                                 self._batch._noise(lk.information)))
            self._links.add(key)
            added.append(lk)
        if new_ids:
            self._est = np.concatenate([self._est, np.stack([poses[i] for i in new_ids])])
            self._order = np.argsort(np.asarray(self._ids, np.int64), kind="stable")
        self._add_links(added)
        isam.update(factors, values)
        for _ in range(4 if loop and not self._closing else 0):
            isam.update()
        self._closing = loop
        flat = gtsam.utilities.extractPose3(isam.calculateEstimate())  # R row-major, then t
        est = np.zeros((len(flat), 4, 4))
        est[:, :3, :3] = flat[:, :9].reshape(-1, 3, 3)
        est[:, :3, 3] = flat[:, 9:]
        est[:, 3, 3] = 1.0
        self._est[self._order] = est

    def _add_node(self, node_id: int, poses: Mapping[int, F64], values: gtsam.Values,
                  new_ids: list[int]) -> None:
        self._index[node_id] = len(self._ids)
        self._ids.append(node_id)
        values.insert(node_id, _pose3(np.asarray(poses[node_id], dtype=np.float64)))
        new_ids.append(node_id)

    def _add_links(self, added: list[LinkLike]) -> None:
        if not added:
            return
        n, m = self._n_links, len(added)
        if n + m > len(self._lk_slots):
            cap = max(n + m, 2 * len(self._lk_slots), 64)
            self._lk_slots = np.resize(self._lk_slots, (cap, 2))
            self._lk_transform = np.resize(self._lk_transform, (cap, 4, 4))
            self._lk_info = np.resize(self._lk_info, (cap, 6))
        index = self._index
        for k, lk in enumerate(added):
            self._lk_slots[n + k] = (index[lk.from_id], index[lk.to_id])
            self._lk_transform[n + k] = lk.transform
            self._lk_info[n + k] = np.diagonal(np.asarray(lk.information, dtype=np.float64))
        self._n_links = n + m
