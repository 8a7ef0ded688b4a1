"""Loop-closure plausibility: the covariance of the odometry path between two nodes and the
Mahalanobis distance of a closure against it."""

from __future__ import annotations

import heapq
from collections.abc import Mapping

import numpy as np
from numpy.typing import NDArray

from eddiebot.vslam.memory import Link
from eddiebot.vslam.odometry_frames import _ODOMETRY_LINKS
from eddiebot.vslam.transforms import se3_inverse, yaw_of

F64 = NDArray[np.float64]


def _xyt(t: F64) -> F64:
    return np.array([t[0, 3], t[1, 3], yaw_of(t)])


def _link_covariance_xyt(info: F64) -> F64:
    """(x, y, yaw) covariance of a link from its 6×6 information (diagonal terms)."""
    d = np.diag(np.asarray(info, dtype=np.float64))[[0, 1, 5]]
    return np.diag(1.0 / np.maximum(d, 1e-12))


def path_covariance(links: Mapping[int, Mapping[int, Link]], start: int, goal: int,
                    max_nodes: int = 100_000, *,
                    heading_sigma: float = 0.0) -> tuple[F64, F64] | None:
    """Pose of `goal` in `start`'s frame (x, y, yaw) and its 3×3 covariance, composed along the
    graph path from `start` to `goal` of least summed link variance (None if not connected).

    Each link's covariance (x, y, yaw, in the link's `from` frame) is propagated through the
    SE(2) composition with first-order Jacobians, so a heading uncertainty early on the path
    grows into a lateral one further along it. A path is one of several in a graph with loops,
    so this overestimates the marginal covariance: a conservative prediction for gating.
    `heading_sigma` (`RGBD/OdomHeadingSigma`) adds the odometry frame's heading offset where
    the path enters and where it leaves a run of odometry links.
    """
    if start == goal:
        return np.zeros(3), np.zeros((3, 3))
    best = {start: 0.0}
    parent: dict[int, int] = {}
    heap = [(0.0, start)]
    done: set[int] = set()
    while heap:
        cost, n = heapq.heappop(heap)
        if n in done:
            continue
        done.add(n)
        if n == goal or len(done) > max_nodes:
            break
        for m, lk in links.get(n, {}).items():
            if m in done:
                continue
            # trace of `_link_covariance_xyt(lk.information)`, in scalars (same values)
            info = lk.information
            w = cost + (1.0 / max(float(info[0, 0]), 1e-12) + 1.0 / max(float(info[1, 1]), 1e-12)
                        + 1.0 / max(float(info[5, 5]), 1e-12))
            if w < best.get(m, np.inf):
                best[m] = w
                parent[m] = n
                heapq.heappush(heap, (w, m))
    if goal not in parent:
        return None
    chain = [goal]
    while chain[-1] != start:
        chain.append(parent[chain[-1]])
    chain.reverse()
    pose = np.zeros(3)
    cov = np.zeros((3, 3))
    in_odometry = False
    for a, b in zip(chain[:-1], chain[1:]):
        lk = links[a][b]
        odometry = heading_sigma > 0 and lk.type in _ODOMETRY_LINKS
        if odometry != in_odometry:  # a node's heading ↔ its odometry frame's
            cov[2, 2] += heading_sigma**2
            in_odometry = odometry
        step = _xyt(lk.transform)
        c, s = np.cos(pose[2]), np.sin(pose[2])
        j1 = np.array([[1.0, 0.0, -s * step[0] - c * step[1]],
                       [0.0, 1.0, c * step[0] - s * step[1]],
                       [0.0, 0.0, 1.0]])
        j2 = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        cov = j1 @ cov @ j1.T + j2 @ _link_covariance_xyt(lk.information) @ j2.T
        pose = np.array([pose[0] + c * step[0] - s * step[1],
                         pose[1] + s * step[0] + c * step[1],
                         float(np.arctan2(np.sin(pose[2] + step[2]), np.cos(pose[2] + step[2])))])
    if in_odometry:
        cov[2, 2] += heading_sigma**2
    return pose, cov


def closure_mahalanobis(link: Link, from_pose: F64, to_pose: F64,
                        links: Mapping[int, Mapping[int, Link]], *,
                        heading_sigma: float = 0.0) -> float | None:
    """Mahalanobis distance (σ) between a candidate closure and the graph's prediction.

    `from_pose`/`to_pose`: current estimates of the closure's two nodes (map frame, 4×4). The
    prediction is their relative pose; its covariance is that of the least-variance graph path
    between them (`path_covariance`, with `heading_sigma`) plus the closure's own. None when
    they are not connected.
    """
    path = path_covariance(links, link.from_id, link.to_id, heading_sigma=heading_sigma)
    if path is None:
        return None
    _, cov = path
    pred = _xyt(se3_inverse(from_pose) @ to_pose)
    meas = _xyt(link.transform)
    d = meas - pred
    d[2] = float(np.arctan2(np.sin(d[2]), np.cos(d[2])))
    total = cov + _link_covariance_xyt(link.information)
    return float(np.sqrt(max(0.0, float(d @ np.linalg.solve(total, d)))))
