"""What the incremental graphs (SE(2) and Pose3, gtsam iSAM2) share: link keys, and the
`optimize` control that folds new nodes and links into iSAM2, rebuilds when the graph cannot be
continued and re-solves in batch when an update fails."""

from __future__ import annotations

from collections.abc import Collection, Iterable, Mapping, Sequence

import gtsam
import numpy as np

from eddiebot.vslam.graph_batch import BatchPoseGraph
from eddiebot.vslam.graph_links import F64, LinkLike

__all__ = ["IsamGraph", "keyed_links"]

LinkKey = tuple[int, int, int]


def keyed_links(links: Iterable[LinkLike]) -> dict[LinkKey, LinkLike]:
    """Links by (from, to, k): the k-th parallel link between two nodes."""
    keyed: dict[LinkKey, LinkLike] = {}
    for lk in links:
        key = (lk.from_id, lk.to_id, 0)
        while key in keyed:
            key = (key[0], key[1], key[2] + 1)
        keyed[key] = lk
    return keyed


class IsamGraph:
    """The control of an incremental graph; subclasses hold the graph (`reset`, `_update`,
    `_estimate`)."""

    relinearize_threshold: float
    rebuilds: int
    recoveries: int
    _batch: BatchPoseGraph
    _isam: gtsam.ISAM2 | None
    _ids: list[int]
    _index: dict[int, int]
    _links: Collection[LinkKey]
    _root: int
    _root_pose: F64 | None

    def reset(self) -> None:
        raise NotImplementedError

    def _update(self, poses: Mapping[int, F64], keyed: Mapping[LinkKey, LinkLike],
                new_keys: Iterable[LinkKey]) -> None:
        raise NotImplementedError

    def _estimate(self) -> Iterable[F64]:
        raise NotImplementedError

    def optimize(
        self,
        poses: Mapping[int, F64],
        links: Iterable[LinkLike],
        root_id: int,
        iterations: int,
    ) -> dict[int, F64]:
        """Optimised poses of the component of `root_id` (root fixed at its given pose)."""
        link_list = links if isinstance(links, list) else list(links)
        keyed = keyed_links(link_list)
        root_pose = np.asarray(poses[root_id], dtype=np.float64)
        if (self._root_pose is not None and root_id == self._root
                and not np.allclose(root_pose, self._root_pose, rtol=0.0, atol=1e-3)):
            # the root is re-anchored every call (OptimizeFromGraphEnd): nothing to keep
            self.reset()
            return self._batch.optimize_batch(poses, link_list, root_id, iterations)
        # keys not in the graph; every graph key was given again iff the others number as many
        new_keys = keyed.keys() - set(self._links)
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
            # current linearisation) as IndeterminateSystemException
            self._recover(poses, link_list, root_id, root_pose, iterations)
        return dict(zip(self._ids, self._estimate()))

    def _recover(self, poses: Mapping[int, F64], links: Sequence[LinkLike], root_id: int,
                 root_pose: F64, iterations: int) -> None:
        """Re-solve in batch after a failed iSAM2 update and restart iSAM2 from that optimum."""
        keyed = keyed_links(links)
        self.recoveries += 1
        solved = self._batch.optimize_batch(poses, links, root_id, max(iterations, 100))
        self._start(root_id, root_pose)
        self._update({**poses, **solved}, keyed, set(keyed))

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
