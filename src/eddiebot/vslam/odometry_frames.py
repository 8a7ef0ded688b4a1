"""Odometry frames (`RGBD/OdomHeadingSigma`): each node gets a frame tied to its position whose
heading follows the wheel odometry, so the optimised graph keeps the encoders' heading."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
from numpy.typing import NDArray

from eddiebot.vslam.graph import GraphLink
from eddiebot.vslam.memory import Link, LinkType

F64 = NDArray[np.float64]


#: ids of the per-node odometry frames in the optimised graph (`RGBD/OdomHeadingSigma`): node id + this
ODOM_FRAME_ID_OFFSET = 1 << 40
_FRAME_TIE_VARIANCE = 1e-8  # m², rad²: a node's odometry frame shares its position (and the root's yaw)
_ODOMETRY_LINKS = (LinkType.NEIGHBOR, LinkType.NEIGHBOR_MERGED)


def _worst_link_error(ids: NDArray[np.int64], lin: F64, ang: F64, sigma: float) -> float:
    """The largest `RGBD/OptimizeMaxError` ratio of an optimised graph's links. With odometry
    frames (``sigma`` > 0) a frame shares its node's position by construction (a constraint, not
    a measurement): only the frame links' heading is judged."""
    if sigma > 0:
        tie = (ids[:, 0] < ODOM_FRAME_ID_OFFSET) & (ids[:, 1] >= ODOM_FRAME_ID_OFFSET)
        lin = np.where(tie, 0.0, lin)
    return max(float(lin.max(initial=0.0)), float(ang.max(initial=0.0)))


def odometry_frame_graph(poses: Mapping[int, F64], links: Sequence[Link | GraphLink], root: int,
                         heading_sigma: float, frame_poses: Mapping[int, F64] | None = None,
                         ) -> tuple[dict[int, F64], list[GraphLink]]:
    """The graph to optimise when the odometry heading carries a non-accumulating error.

    Wheel encoders that quantise the heading (Eddie's: 36 positions per wheel turn, ≈ 2° of
    heading per position) report at every node a heading that is off by an error of its own
    which does not add up along the path, while the positions, integrated from every encoder
    step, follow the true direction of travel; a neighbour link, expressed in its first node's
    reported heading, then carries a sideways error of its length times that node's heading
    error. Modelled per link (independent x, y, yaw noise), the heading looks like a random
    walk and the graph turns whole stretches of the path to fit the loop closures.

    Here every node `i` gets an odometry frame (id `ODOM_FRAME_ID_OFFSET + i`, initial pose
    from `frame_poses` or the node's): the neighbour links (`NEIGHBOR`, `NEIGHBOR_MERGED`) join
    the frames, and a link node → frame (identity) ties each frame to its node in position and
    lets its heading differ by `heading_sigma` (rad). The root's frame is tied in heading as
    well: the map frame is the odometry's at the root. Loop-closure and other links stay
    between the nodes. Returns the poses (nodes and frames) and the links to optimise.
    """
    return OdometryFrames().graph(poses, links, root, heading_sigma, frame_poses)


class OdometryFrames:
    """`odometry_frame_graph` for a graph that grows between calls: the links it derives (a
    tie per node, the frame copy of each link) are kept per node and per link object, so a call
    builds only those of new nodes and new or replaced links. Same result as the function,
    link for link (the same `GraphLink` fields, in the same order)."""

    def __init__(self) -> None:
        self._sigma = -1.0
        self._root = 0
        self._ties: dict[int, GraphLink] = {}  # node id → tie link (node → its frame)
        self._moved: dict[tuple[int, int], tuple[Link | GraphLink, GraphLink]] = {}
        self._heading = np.eye(6)
        self._rigid = np.eye(6)
        self._eye = np.eye(4)

    def fits(self, root: int, heading_sigma: float) -> bool:
        """True when `extend` can continue the last `graph` call's links (same root and σ)."""
        return heading_sigma == self._sigma and root == self._root

    def extend(self, poses: Mapping[int, F64], links: Sequence[Link | GraphLink], root: int,
               heading_sigma: float, frame_poses: Mapping[int, F64] | None = None,
               ) -> tuple[dict[int, F64], list[GraphLink]]:
        """The part of `graph` for added nodes (`poses`) and links only (`fits` must hold):
        those nodes, their frames and ties, and the links' graph copies."""
        assert self.fits(root, heading_sigma)
        return self._build(poses, links, root, heading_sigma, frame_poses, forget=False)

    def graph(self, poses: Mapping[int, F64], links: Sequence[Link | GraphLink], root: int,
              heading_sigma: float, frame_poses: Mapping[int, F64] | None = None,
              ) -> tuple[dict[int, F64], list[GraphLink]]:
        """`odometry_frame_graph(poses, links, root, heading_sigma, frame_poses)`."""
        return self._build(poses, links, root, heading_sigma, frame_poses, forget=True)

    def _build(self, poses: Mapping[int, F64], links: Sequence[Link | GraphLink], root: int,
               heading_sigma: float, frame_poses: Mapping[int, F64] | None, forget: bool,
               ) -> tuple[dict[int, F64], list[GraphLink]]:
        if heading_sigma != self._sigma or root != self._root:
            tie = 1.0 / _FRAME_TIE_VARIANCE
            self._sigma, self._root = heading_sigma, root
            self._heading = np.diag([tie, tie, tie, tie, tie, 1.0 / heading_sigma**2])
            self._rigid = np.diag(np.full(6, tie))
            self._ties = {}
        known = frame_poses or {}
        out_poses: dict[int, F64] = dict(poses)
        out: list[GraphLink] = []
        ties = self._ties
        offset = ODOM_FRAME_ID_OFFSET
        for i in poses:
            f = offset + i
            out_poses[f] = known.get(f, poses[i])
            t = ties.get(i)
            if t is None:
                t = ties[i] = GraphLink(i, f, self._eye, self._rigid if i == root else self._heading)
            out.append(t)
        moved = self._moved
        if forget and len(moved) > 2 * len(links) + 1024:  # forget links no longer given
            moved.clear()
        for lk in links:
            key = (lk.from_id, lk.to_id)
            entry = moved.get(key)
            if entry is None or entry[0] is not lk:
                if getattr(lk, "type", None) in _ODOMETRY_LINKS:
                    g = GraphLink(offset + lk.from_id, offset + lk.to_id, lk.transform,
                                  lk.information)
                else:
                    g = GraphLink(lk.from_id, lk.to_id, lk.transform, lk.information,
                                  lk.switchable)
                entry = moved[key] = (lk, g)
            out.append(entry[1])
        return out_poses, out
