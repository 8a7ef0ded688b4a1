"""Merging a second SLAM session into a running graph (slam_toolbox's ``add_submap`` /
``merge_submaps``), pure — no bus, no clock, no files.

slam_toolbox's merge tool (``merge_maps_kinematic``) loads serialized sessions, shows each
as a map the user drags into place, and on ``merge_submaps`` renders every scan at its moved
pose into one grid; the graphs stay apart. Here a session is merged into the graph itself:

1. `place_session` finds the rigid transform from the second session's map frame into this
   one — by scan matching when no pose is given (up to ``samples`` of its nodes, spread
   along its path, are relocalised over the whole current map until
   `RELOCALIZATION_CONSENSUS` agree; the transforms they imply are clustered and the largest
   cluster wins), or from a given transform (the user's placement).
   (Each sampled node is matched with the scans of its neighbours along its own path: a
   local view.) Each sampled node is then matched against the current nodes near its placed pose (the
   loop-closure search window and thresholds); every match that agrees with the placement is a
   `MergeLink`. A placement found by search needs two links (one for a single-node session):
   a featureless corridor can relocalise somewhere in a room, but its scans then do not match
   the nodes there.
2. `merge_session` appends the session's nodes (scans, odometry, retired flags) and edges to
   the graph, its poses moved by the transform, adds each link as a loop edge (the links
   were vetted together, so they skip the χ² gate), and re-optimises. A session placed by
   hand with no link is tied to node 0 by the transform alone (`HAND_PLACEMENT_SIGMAS`).

The merged nodes keep their own odometry frame: the next scan of a running mapper starts a
new chain linked by scan matching to the nodes it is matched against, as after a start pose.

A running node searches on a copy: `map_snapshot` copies the map as it is (on the node's
executor, cheap: the scans are shared), `place_copy` runs on the copy in another process
while the live graph goes on growing, and `rebase_placement` re-expresses the placement
against the live graph as it is when it is merged (each link kept relative to its anchor
node, which loop closures may have moved meanwhile).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from eddiebot.geometry import se2_between, se2_compose, se2_inverse
from eddiebot.slam.config import SlamConfig
from eddiebot.slam.errors import MergeError
from eddiebot.slam.mapper import NodeRecord, SlamCore
from eddiebot.slam.mapper.measurement import _rotate_covariance
from eddiebot.slam.pose_graph import EdgeKind

__all__ = [
    "AGREEMENT_HEADING",
    "AGREEMENT_POSITION",
    "HAND_PLACEMENT_SIGMAS",
    "LOCAL_VIEW_NODES",
    "MINIMUM_LINK_RESPONSE",
    "RELOCALIZATION_CONSENSUS",
    "MapCopy",
    "MergeLink",
    "Placement",
    "map_snapshot",
    "merge_session",
    "place_copy",
    "place_session",
    "rebase_placement",
]

FloatArray = npt.NDArray[np.float64]

#: Two placements agree when their transforms differ by at most this much (m, rad).
AGREEMENT_POSITION = 0.3
AGREEMENT_HEADING = 0.1
#: A link's fine response must reach this (or the loop-closure threshold when higher): a
#: merge commits a whole session, and a local view half unexplained — a corridor's one wall
#: and end matching a room's corner — is no place to commit it.
MINIMUM_LINK_RESPONSE = 0.6
#: Relocalised samples whose placements agree that end the global search.
RELOCALIZATION_CONSENSUS = 3
#: Nodes either side of a sampled node (along its session's path) whose scans join it in the
#: local view that is relocalised and matched.
LOCAL_VIEW_NODES = 4
#: Standard deviations (m, m, rad) tying a session placed by hand, with no scan-matched link,
#: to node 0 of the graph.
HAND_PLACEMENT_SIGMAS = np.array([0.1, 0.1, 0.05])


@dataclass(frozen=True)
class MergeLink:
    """A node of the second session matched against the current map."""

    node: int
    """Node id in the second session."""
    anchor: int
    """The nearest current node it was matched against."""
    pose: FloatArray
    """The matched robot pose in this map's frame (x, y, theta)."""
    response: float
    covariance: FloatArray
    """The match's covariance, map frame (3, 3)."""


@dataclass(frozen=True)
class Placement:
    """Where a second session goes: ``transform`` maps its map frame into this one."""

    transform: FloatArray
    links: tuple[MergeLink, ...]
    by_scan_matching: bool
    relocalized: int = 0
    """Sampled nodes whose global relocalisation passed the loop-closure thresholds (the
    search stops at `RELOCALIZATION_CONSENSUS` agreeing)."""


def _mean_transform(ts: list[FloatArray]) -> FloatArray:
    a = np.array(ts)
    th = math.atan2(float(np.sin(a[:, 2]).mean()), float(np.cos(a[:, 2]).mean()))
    return np.array([float(a[:, 0].mean()), float(a[:, 1].mean()), th])


def _agree(a: FloatArray, b: FloatArray) -> bool:
    return (
        math.hypot(float(a[0] - b[0]), float(a[1] - b[1])) <= AGREEMENT_POSITION
        and abs(math.remainder(float(a[2] - b[2]), math.tau)) <= AGREEMENT_HEADING
    )


def _largest_cluster(ts: list[FloatArray]) -> list[FloatArray]:
    best: list[FloatArray] = []
    for t in ts:
        members = [u for u in ts if _agree(t, u)]
        if len(members) > len(best):
            best = members
    return best


def _samples(other: SlamCore, count: int) -> list[int]:
    active = [i for i, n in enumerate(other.nodes) if not n.retired and n.points.shape[0] >= 10]
    if len(active) <= count:
        return active
    picks = np.linspace(0, len(active) - 1, count).round().astype(int)
    return [active[int(k)] for k in picks]


def _check(core: SlamCore, other: SlamCore) -> None:
    if not core.nodes:
        raise MergeError("the current graph is empty: load the session instead of merging it")
    if not other.nodes:
        raise MergeError("the session to merge holds no nodes")
    a, b = core.sensor_offset, other.sensor_offset
    if math.hypot(float(a[0] - b[0]), float(a[1] - b[1])) > 1e-3 or abs(
        math.remainder(float(a[2] - b[2]), math.tau)
    ) > 1e-3:
        raise MergeError(
            f"the session's laser was mounted at ({b[0]:.3f}, {b[1]:.3f}, {b[2]:.3f}), this "
            f"map's at ({a[0]:.3f}, {a[1]:.3f}, {a[2]:.3f}): one laser per map"
        )


def _local_points(other: SlamCore, k: int, poses: FloatArray) -> FloatArray:
    """End points of node ``k`` and of its session's nodes within ``LOCAL_VIEW_NODES`` along
    its path, in node ``k``'s sensor frame: a local map is far more distinctive than one
    scan when relocalising in a large map."""
    offset = other.sensor_offset
    here = se2_inverse(se2_compose(poses[k], offset))
    parts = []
    for j in range(max(0, k - LOCAL_VIEW_NODES), min(len(other.nodes), k + LOCAL_VIEW_NODES + 1)):
        node = other.nodes[j]
        if node.retired or node.points.shape[0] == 0:
            continue
        rel = se2_compose(here, se2_compose(poses[j], offset))
        c, s = math.cos(float(rel[2])), math.sin(float(rel[2]))
        pts = node.points
        parts.append(np.stack([rel[0] + c * pts[:, 0] - s * pts[:, 1],
                               rel[1] + s * pts[:, 0] + c * pts[:, 1]], axis=1))
    pts = np.concatenate(parts) if parts else other.nodes[k].points
    limit = 3 * max(1, other.nodes[k].points.shape[0])
    return np.ascontiguousarray(pts[:: max(1, -(-pts.shape[0] // limit))])


def _relocalized_transforms(core: SlamCore, other: SlamCore, picks: list[int]) -> list[FloatArray]:
    """Transforms implied by the sampled nodes that global relocalisation places, until
    `RELOCALIZATION_CONSENSUS` of them agree (each search covers the whole map: the cost of
    a merge)."""
    poses = other.node_poses()
    # the whole-map grid relocalisation caches is the graph as it was: rebuild it now, and
    # leave the core's record of relocalisation attempts as it was
    core._global = None
    before = len(core.relocalizations)
    out = []
    try:
        for k in picks[::2] + picks[1::2]:  # spread along the path from the start
            found = core.relocalize(_local_points(other, k, poses))
            if found.accepted:
                out.append(se2_compose(found.pose, se2_inverse(poses[k])))
                if len(_largest_cluster(out)) >= RELOCALIZATION_CONSENSUS:
                    break
    finally:
        del core.relocalizations[before:]
        core._global = None
    return out


def _link(core: SlamCore, other: SlamCore, k: int, placed: FloatArray) -> MergeLink | None:
    """Node ``k`` of ``other`` matched against the current nodes near ``placed`` (its robot
    pose in this map); None when nothing near or the match is weak."""
    cfg = core.config
    offset = core.sensor_offset
    sensor = se2_compose(placed, offset)
    positions = core._positions()
    active = np.flatnonzero(core.active_mask())
    d = np.hypot(positions[active, 0] - sensor[0], positions[active, 1] - sensor[1])
    keep = d <= cfg.loop_search_maximum_distance
    if not np.any(keep):
        return None
    near = [int(i) for i in active[keep][np.argsort(d[keep], kind="stable")]][
        : 2 * cfg.scan_buffer_size
    ]
    points = _local_points(other, k, other.node_poses())
    coarse = core._match_against(near, points, sensor, core._loop_coarse)
    if coarse.response < cfg.loop_match_minimum_response_coarse:
        return None
    fine = core._match_against(near, points, coarse.pose, core._loop_fine)
    if fine.response < max(cfg.loop_match_minimum_response_fine, MINIMUM_LINK_RESPONSE):
        return None
    variance = float(np.linalg.eigvalsh(0.5 * (fine.covariance[:2, :2] + fine.covariance[:2, :2].T))[-1])
    if cfg.loop_match_maximum_variance_fine > 0.0 and variance > cfg.loop_match_maximum_variance_fine:
        return None
    pose = se2_compose(fine.pose, se2_inverse(offset))
    return MergeLink(k, near[0], pose, float(fine.response), np.asarray(fine.covariance))


def place_session(
    core: SlamCore,
    other: SlamCore,
    *,
    transform: npt.ArrayLike | None = None,
    samples: int = 12,
) -> Placement:
    """Where ``other`` (a loaded session) lies in ``core``'s map: by scan matching, or at
    ``transform`` (its map frame in this one, x, y, theta) refined by the links found near it.
    `MergeError` when it cannot be placed (nothing matches and no transform is given)."""
    _check(core, other)
    picks = _samples(other, max(1, samples))
    relocalized = 0
    if transform is None:
        found = _relocalized_transforms(core, other, picks)
        relocalized = len(found)
        cluster_found = _largest_cluster(found)
        if not cluster_found:
            raise MergeError(
                f"none of the {len(picks)} sampled nodes of the session relocalised in the "
                "current map: place it by hand (give its pose) or map where the sessions overlap"
            )
        guess = _mean_transform(cluster_found)
    else:
        cluster_found = []
        guess = np.asarray(transform, dtype=np.float64).reshape(3).copy()
        if not np.all(np.isfinite(guess)):
            raise MergeError(f"placement {guess.tolist()} is not a finite (x, y, theta)")
    poses = other.node_poses()
    links = []
    for k in picks:
        link = _link(core, other, k, se2_compose(guess, poses[k]))
        if link is not None:
            links.append(link)
    implied = [se2_compose(lk.pose, se2_inverse(poses[lk.node])) for lk in links]
    cluster = _largest_cluster(implied)
    # the links that agree with each other (and, for a search, with the relocalisation)
    keep = [
        lk for lk, t in zip(links, implied)
        if any(t is c for c in cluster) and (transform is not None or _agree(t, guess))
    ]
    if transform is None and len(keep) < min(2, len(picks)):
        raise MergeError(
            f"{len(cluster_found)} of {len(picks)} sampled nodes of the session relocalised in "
            f"the current map, but {len(keep)} matched the nodes near where they placed it: "
            "not placed (place it by hand, or map where the sessions overlap)"
        )
    if keep:
        final = _mean_transform([se2_compose(lk.pose, se2_inverse(poses[lk.node])) for lk in keep])
    else:
        final = guess
    return Placement(final, tuple(keep), transform is None, relocalized)


@dataclass(frozen=True)
class MapCopy:
    """What placement reads of a graph, copied (`map_snapshot`): picklable, so the search can
    run in another process while the graph goes on growing."""

    config: SlamConfig
    sensor_offset: FloatArray
    nodes: tuple[NodeRecord, ...]
    """The node records (retired ones retired); scans and points shared with the graph's."""
    poses: FloatArray
    """The nodes' robot poses in its map frame (N, 3)."""

    def core(self) -> SlamCore:
        """A `SlamCore` holding the copy: its nodes at their poses, no edges (placement reads
        poses and scans only)."""
        out = SlamCore(self.config, sensor_offset=self.sensor_offset)
        if self.nodes:
            out._restore(list(self.nodes), self.poses.copy(), [])
        return out


def map_snapshot(core: SlamCore) -> MapCopy:
    """``core``'s map as it is now, for `place_copy` (cheap: node records are copied, their
    scans and points shared — a node's scan is never changed in place)."""
    poses = core.node_poses().copy() if core.nodes else np.zeros((0, 3))
    nodes = tuple(dataclasses.replace(n) for n in core.nodes)
    return MapCopy(core.config, core.sensor_offset.copy(), nodes, poses)


def place_copy(map_copy: MapCopy, session: MapCopy, **kwargs: Any) -> Placement:
    r"""`place_session` of ``session`` on ``map_copy`` (both `map_snapshot`\ s): what the
    node's placement process runs."""
    return place_session(map_copy.core(), session.core(), **kwargs)


def rebase_placement(
    placement: Placement, other: SlamCore, searched: FloatArray, core: SlamCore
) -> Placement:
    """``placement``, found on a snapshot whose node poses were ``searched`` (N, 3), against
    ``core`` as it is now: each link's matched pose moves with its anchor node (kept relative
    to it), links whose anchor is gone (retired, or no longer in the graph) are dropped, and a
    transform found by scan matching is re-derived from the links kept."""
    if not placement.links:
        return placement
    now = core.node_poses()
    active = core.active_mask()
    removed = set(core.graph.removed_nodes)
    own = other.node_poses()
    links = []
    for lk in placement.links:
        a = lk.anchor
        if a >= now.shape[0] or a >= searched.shape[0] or not active[a] or a in removed:
            continue
        pose = se2_compose(now[a], se2_between(searched[a], lk.pose))
        turn = float(now[a, 2] - searched[a, 2])
        links.append(dataclasses.replace(
            lk, pose=pose, covariance=_rotate_covariance(lk.covariance, -turn)))
    if links:
        transform = _mean_transform([se2_compose(lk.pose, se2_inverse(own[lk.node])) for lk in links])
    else:
        transform = placement.transform
    return dataclasses.replace(placement, transform=transform, links=tuple(links))


def merge_session(core: SlamCore, other: SlamCore, placement: Placement) -> range:
    """Append ``other``'s nodes and edges to ``core`` at ``placement``, link them and
    re-optimise; returns the new node ids. Nodes lifelong mode marginalised out of ``other``
    are left behind with their edges, as a saved session leaves them."""
    _check(core, other)
    t = placement.transform
    gone = set(other.graph.removed_nodes)
    keep = [k for k in range(len(other.nodes)) if k not in gone]
    if not keep:
        raise MergeError("the session to merge holds no nodes")
    own = other.node_poses()[keep]
    poses = se2_compose(np.broadcast_to(t, own.shape), own)
    core.node_poses()  # folds in anything pending before the graph grows
    offset = len(core.nodes)
    new_id = {old: offset + new for new, old in enumerate(keep)}
    for k, pose in zip(keep, poses):
        node = other.nodes[k]
        core.graph.add_node(pose)
        core.nodes.append(dataclasses.replace(node, odom_pose=node.odom_pose.copy()))
    dropped = set(other.graph.removed_edges)
    for q, e in enumerate(other.graph.edges):
        if q not in dropped:
            core.graph.add_edge(new_id[e.i], new_id[e.j], e.measurement, e.covariance,
                                kind=e.kind, robust=e.robust)
    graph_poses = core.graph.poses
    for lk in placement.links:
        anchor = graph_poses[lk.anchor]
        core.graph.add_edge(
            lk.anchor,
            new_id[lk.node],
            se2_between(anchor, lk.pose),
            _rotate_covariance(lk.covariance, float(anchor[2])),
            kind=EdgeKind.LOOP,
        )
    if not placement.links:
        removed = set(core.graph.removed_nodes)
        first = next(k for k in range(offset) if k not in removed)
        core.graph.add_edge(
            first,
            offset,
            se2_between(graph_poses[first], poses[0]),
            np.diag(HAND_PLACEMENT_SIGMAS**2),
            kind=EdgeKind.LOOP,
        )
    core.graph.optimize(full=True)
    # the next live scan starts a new chain: the last node is now the session's, not its own
    core._state.last_processed_odom = None
    core._global = None
    return range(offset, len(core.nodes))


