"""Localization against a saved map without pose jumps, as RTAB-Map does it.

The odometry of the last `RGBD/MaxOdomCacheSize` frames is kept with the localizations
accepted among them. A new localization (a loop closure or proximity link from the current
frame to a map node) is checked by optimising that local graph — the frames chained by their
odometry links, the map nodes held by priors of variance `RGBD/LocalizationPriorError` — and
rejected when a link's residual exceeds `RGBD/OptimizeMaxError` σ: a localization that would
move the robot further than the odometry's uncertainty allows since the previous ones. Pure
core: poses are 4×4 (m), the base in the odometry frame or the map frame.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from eddiebot.vslam.graph import GraphLink, GtsamPoseGraph, LinkLike, link_errors
from eddiebot.vslam.transforms import se3_inverse

__all__ = ["LocalizationCheck", "OdometryCache"]

F64 = NDArray[np.float64]
#: graph ids of the cached frames (map node ids stay below)
_FRAME_ID_OFFSET = 1 << 42


@dataclass
class _Frame:
    odom: F64  # base in the odometry frame
    information: F64 | None  # of the odometry link from the previous cached frame
    links: list[GraphLink] = field(default_factory=list)  # accepted localizations (to map nodes)


@dataclass(frozen=True)
class LocalizationCheck:
    """The outcome of one localization: the base pose in the map frame (None when rejected),
    why it was rejected, the largest residual (σ) of the local graph and the pose covariance
    (6×6: x, y, z, roll, pitch, yaw)."""

    pose: F64 | None
    reason: str = ""
    max_error: float = 0.0
    covariance: F64 | None = None


class OdometryCache:
    """The last frames' odometry and the localizations accepted among them (`RGBD/MaxOdomCacheSize`)."""

    def __init__(self, max_size: int, three_dof: bool, *, prior_variance: float = 0.001,
                 max_error: float = 3.0, iterations: int = 20, epsilon: float = 1e-5) -> None:
        self.max_size = max(1, int(max_size))
        self.prior_variance = float(prior_variance)
        self.max_error = float(max_error)
        self.iterations = int(iterations)
        self._optimizer = GtsamPoseGraph(three_dof, epsilon, incremental=False)
        self._frames: deque[_Frame] = deque(maxlen=self.max_size)
        self._first = 0  # sequence number of _frames[0]

    def __len__(self) -> int:
        return len(self._frames)

    @property
    def localizations(self) -> int:
        """Accepted localizations still in the cache."""
        return sum(len(f.links) for f in self._frames)

    def clear(self) -> None:
        """Forget every frame (odometry reset, mode change)."""
        self._first += len(self._frames)
        self._frames.clear()

    def add(self, odom: F64, information: F64) -> None:
        """A new frame: its odometry pose and the information of its motion since the last."""
        if len(self._frames) == self.max_size:
            self._first += 1
        prev = self._frames[-1] if self._frames else None
        self._frames.append(_Frame(np.asarray(odom, np.float64).copy(),
                                   None if prev is None else np.asarray(information, np.float64)))

    def localize(self, links: Sequence[LinkLike], map_poses: Mapping[int, F64]
                 ) -> LocalizationCheck:
        """Check localization links from the newest frame (`transform`: the map node in the
        frame's base) against the cached odometry and earlier localizations; accepted links are
        kept for the next checks."""
        if not self._frames:
            raise ValueError("localize: add the frame's odometry first")
        usable = [lk for lk in links if lk.to_id in map_poses]
        if not usable:
            return LocalizationCheck(None, "the linked map nodes have no pose")
        n = len(self._frames)
        ids = [_FRAME_ID_OFFSET + self._first + k for k in range(n)]
        current = ids[-1]
        new = [GraphLink(current, lk.to_id, lk.transform, lk.information) for lk in usable]
        loc_links = [lk for f in self._frames for lk in f.links] + new
        map_ids = sorted({lk.to_id for lk in loc_links})
        root = map_ids[0]
        # initial guess: the frames placed by the first new link and the odometry
        first = new[0]
        here = map_poses[first.to_id] @ se3_inverse(first.transform)
        odom_inv = se3_inverse(self._frames[-1].odom)
        poses: dict[int, F64] = {i: map_poses[i] for i in map_ids}
        for gid, f in zip(ids, self._frames):
            poses[gid] = here @ odom_inv @ f.odom
        prior = np.eye(6) / self.prior_variance
        graph: list[GraphLink] = [
            GraphLink(root, m, se3_inverse(map_poses[root]) @ map_poses[m], prior)
            for m in map_ids[1:]]
        for k in range(1, n):
            info = self._frames[k].information
            if info is None:
                continue
            delta = se3_inverse(self._frames[k - 1].odom) @ self._frames[k].odom
            graph.append(GraphLink(ids[k - 1], ids[k], delta, info))
        graph += loc_links
        optimized = self._optimizer.optimize(poses, graph, root, self.iterations)
        if current not in optimized:
            return LocalizationCheck(None, "the local graph does not reach the frame")
        errors = link_errors(optimized, graph)
        worst = max((max(e.linear_ratio, e.angular_ratio) for e in errors), default=0.0)
        if self.max_error > 0 and worst > self.max_error:
            return LocalizationCheck(
                None, f"RGBD/OptimizeMaxError exceeded by the localization ({worst:.1f} > "
                      f"{self.max_error:g} σ with the odometry of the last {n} frames)", worst)
        self._frames[-1].links.extend(new)
        cov = np.linalg.inv(sum(lk.information for lk in new))
        return LocalizationCheck(optimized[current], "", worst, np.asarray(cov, np.float64))
