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
from eddiebot.msgs.sensor_msgs import PointCloud2, PointField
from eddiebot.msgs.std_msgs import Header
from eddiebot.msgs.visualization_msgs import Marker
from eddiebot.vslam.memory import Link as GraphLink
from eddiebot.vslam.memory import LinkType
from eddiebot.vslam.memory import Node as MemoryNode
from eddiebot.vslam.records import ProcessResult

__all__ = ["cloud_message", "graph_markers", "graph_message", "info_message",
           "map_data_message", "pose_message", "transform_message"]

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


def graph_markers(poses: Mapping[int, F64], links: Iterable[GraphLink], frame_id: str,
                  first_id: int) -> list[Marker]:
    """``~/graph_markers`` (not upstream): the nodes as spheres, neighbour links blue and loop
    links red, marker ids from `first_id`."""
    header = Header(frame_id=frame_id)
    nodes = Marker(header=header, ns="rtabmap_nodes", id=first_id, type=Marker.SPHERE_LIST,
                   action=Marker.ADD)
    nodes.scale.x = nodes.scale.y = nodes.scale.z = 0.06
    nodes.color.r, nodes.color.g, nodes.color.b, nodes.color.a = 1.0, 0.5, 0.0, 1.0
    nodes.pose.orientation.w = 1.0
    nodes.points = [Point(x=float(t[0, 3]), y=float(t[1, 3]), z=float(t[2, 3]))
                    for t in poses.values()]
    out = [nodes]
    for k, (name, kinds, rgb) in enumerate((
            ("rtabmap_neighbor_links", {LinkType.NEIGHBOR}, (0.0, 0.6, 1.0)),
            ("rtabmap_loop_links", None, (1.0, 0.0, 0.0)))):
        m = Marker(header=header, ns=name, id=first_id + k + 1, type=Marker.LINE_LIST,
                   action=Marker.ADD)
        m.scale.x = 0.02
        m.color.r, m.color.g, m.color.b, m.color.a = (*rgb, 1.0)
        m.pose.orientation.w = 1.0
        pts = []
        for lk in links:
            is_kind = lk.type in kinds if kinds is not None else lk.type != LinkType.NEIGHBOR
            if not is_kind or lk.from_id not in poses or lk.to_id not in poses:
                continue
            a, b = poses[lk.from_id], poses[lk.to_id]
            pts += [Point(x=float(a[0, 3]), y=float(a[1, 3]), z=float(a[2, 3])),
                    Point(x=float(b[0, 3]), y=float(b[1, 3]), z=float(b[2, 3]))]
        m.points = pts
        out.append(m)
    return out


def cloud_message(xyz: F64, colors: NDArray[np.uint8], header: Header) -> PointCloud2:
    """A coloured cloud (N×3 m, N×3 RGB) as PointCloud2 with x, y, z and packed rgb."""
    n = int(xyz.shape[0])
    packed = np.zeros((n, 4), np.float32)
    packed[:, :3] = xyz
    if n:
        c = np.asarray(colors, np.uint32).reshape(n, 3)
        packed[:, 3] = ((c[:, 0] << 16) | (c[:, 1] << 8) | c[:, 2]).view(np.float32)
    fields = [PointField(name=name, offset=4 * k, datatype=PointField.FLOAT32, count=1)
              for k, name in enumerate(("x", "y", "z", "rgb"))]
    return PointCloud2(header=header, height=1, width=n, fields=fields, is_bigendian=False,
                       point_step=16, row_step=16 * n, data=packed.view(np.uint8).reshape(-1),
                       is_dense=True)
