"""rtabmap_msgs messages from the SLAM core's state: ``MapGraph`` (optimised graph),
``MapData`` (graph and nodes) and ``Info`` (one update's statistics), as rtabmap_ros's
``mapGraph``, ``mapData`` and ``info`` topics carry them. Poses in the map frame (m,
quaternions); a node's ``pose`` in ``MapData`` is its odometry pose, as upstream."""

from __future__ import annotations

from collections.abc import Iterable, Mapping

import numpy as np
from numpy.typing import NDArray

from eddiebot.geometry import matrix_to_quaternion
from eddiebot.msgs.geometry_msgs import Point, Pose, Quaternion, Transform, Vector3
from eddiebot.msgs.rtabmap_msgs import Info, Link, MapData, MapGraph, Node
from eddiebot.msgs.std_msgs import Header
from eddiebot.vslam.memory import Link as GraphLink
from eddiebot.vslam.memory import Node as MemoryNode
from eddiebot.vslam.records import ProcessResult

__all__ = ["graph_message", "info_message", "map_data_message", "pose_message",
           "transform_message"]

F64 = NDArray[np.float64]


def _quaternion(m: F64) -> Quaternion:
    x, y, z, w = (float(v) for v in matrix_to_quaternion(m[:3, :3]))
    return Quaternion(x=x, y=y, z=z, w=w)


def transform_message(m: F64) -> Transform:
    """A 4×4 rigid transform as geometry_msgs/Transform."""
    return Transform(translation=Vector3(x=float(m[0, 3]), y=float(m[1, 3]), z=float(m[2, 3])),
                     rotation=_quaternion(m))


def pose_message(m: F64) -> Pose:
    """A 4×4 pose as geometry_msgs/Pose."""
    return Pose(position=Point(x=float(m[0, 3]), y=float(m[1, 3]), z=float(m[2, 3])),
                orientation=_quaternion(m))


def graph_message(header: Header, map_to_odom: F64, poses: Mapping[int, F64],
                  links: Iterable[GraphLink]) -> MapGraph:
    """The optimised graph: node poses (map frame) and the links between nodes with a pose."""
    ids = sorted(poses)
    out_links = [
        Link(from_id=int(lk.from_id), to_id=int(lk.to_id), type=int(lk.type),
             transform=transform_message(lk.transform),
             information=np.asarray(lk.information, np.float64).reshape(36).copy())
        for lk in links if lk.from_id in poses and lk.to_id in poses]
    return MapGraph(header=header, map_to_odom=transform_message(map_to_odom),
                    poses_id=np.asarray(ids, np.int32),
                    poses=[pose_message(poses[i]) for i in ids], links=out_links)


def map_data_message(header: Header, graph: MapGraph, nodes: Iterable[MemoryNode]) -> MapData:
    """The graph and the given nodes (id, map id, weight, stamp s, odometry pose; no sensor
    data: RTAB-Map's compressed images are its own formats)."""
    out = [Node(id=int(n.id), map_id=int(n.map_id), weight=int(n.weight),
                stamp=n.stamp_ns / 1e9, pose=pose_message(n.odom_pose)) for n in nodes]
    return MapData(header=header, graph=graph, nodes=out)


def info_message(header: Header, result: ProcessResult, wm_state: Iterable[int],
                 posterior: tuple[NDArray[np.int64], NDArray[np.float64]],
                 weights: Mapping[int, int], loop_transform: F64 | None = None) -> Info:
    """One update: the node (``ref_id``), accepted loop and proximity closures with the loop
    closure's transform (new node → old node; identity without one), working memory (with STM), the Bayes posterior, node weights and the
    statistics (``Group/Name/unit`` keys, as upstream)."""
    loop = result.loop_closure_id
    closure = np.eye(4) if loop_transform is None else loop_transform
    keys = sorted(result.statistics)
    ids, post = posterior
    wkeys = sorted(weights)
    return Info(
        header=header, ref_id=int(result.node_id), loop_closure_id=int(loop),
        proximity_detection_id=int(result.proximity_id),
        loop_closure_transform=transform_message(closure),
        wm_state=np.asarray(sorted(wm_state), np.int32),
        posterior_keys=np.asarray(ids, np.int32), posterior_values=np.asarray(post, np.float32),
        weights_keys=np.asarray(wkeys, np.int32),
        weights_values=np.asarray([weights[k] for k in wkeys], np.int32),
        stats_keys=keys,
        stats_values=np.asarray([result.statistics[k] for k in keys], np.float32))
