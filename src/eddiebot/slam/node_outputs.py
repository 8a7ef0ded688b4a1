"""The SLAM node's outputs: TF ``map → odom``, ``pose``, the occupancy grid on ``map`` /
``map_metadata`` and the graph markers on ``~/graph_visualization``."""

from __future__ import annotations

import time
from collections import deque
from typing import TYPE_CHECKING

import numpy as np

from eddiebot.core.entities import Publisher
from eddiebot.core.node import Node
from eddiebot.core.tf import TransformBroadcaster, make_transform_2d
from eddiebot.core.time import ns_to_stamp
from eddiebot.geometry import yaw_to_quaternion
from eddiebot.maps import OccupancyMap, map_to_msg
from eddiebot.msgs.geometry_msgs import Point, PoseWithCovarianceStamped
from eddiebot.msgs.visualization_msgs import Marker, MarkerArray
from eddiebot.slam.config import SlamConfig
from eddiebot.slam.mapper import SlamCore

if TYPE_CHECKING:
    from eddiebot.slam.node_editing import GraphEditing

__all__ = ["SlamOutputs"]


class SlamOutputs(Node):
    """Publishers of the SLAM node (a base of `SlamNode`, which sets the attributes below)."""

    core: SlamCore
    config: SlamConfig
    editing: GraphEditing
    tf_broadcaster: TransformBroadcaster
    map_pub: Publisher
    meta_pub: Publisher
    graph_pub: Publisher
    pose_pub: Publisher
    map_update_cpu_s: deque[float]
    _map_dirty: bool
    _last_map: OccupancyMap | None

    def _publish_transform(self) -> None:
        x, y, th = (float(v) for v in self.core.map_to_odom)
        # as slam_toolbox: stamped a little in the future so consumers never extrapolate
        stamp = self.get_clock().now_ns() + round(self.config.transform_timeout * 1e9)
        self.tf_broadcaster.sendTransform(
            make_transform_2d(self.config.map_frame, self.config.odom_frame, stamp, x, y, th)
        )

    def _publish_pose(self, pose: np.ndarray, cov: np.ndarray | None, stamp: int) -> None:
        msg = PoseWithCovarianceStamped()
        msg.header.frame_id = self.config.map_frame
        msg.header.stamp = ns_to_stamp(stamp)
        msg.pose.pose.position.x, msg.pose.pose.position.y = float(pose[0]), float(pose[1])
        q = yaw_to_quaternion(float(pose[2]))
        o = msg.pose.pose.orientation
        o.x, o.y, o.z, o.w = q
        c = np.zeros((6, 6))
        if cov is not None:
            ix = [0, 1, 5]
            c[np.ix_(ix, ix)] = np.asarray(cov, dtype=np.float64)[:3, :3]
        msg.pose.covariance = c.reshape(36)
        self.pose_pub.publish(msg)

    def _publish_map(self) -> None:
        """The map, every ``map_update_interval``, stamped now, as slam_toolbox's
        ``updateMap``: rebuilt when the graph changed, else the last one sent again (a
        consumer that waits for a map made after some moment, as exploring does after
        each arrival, must not wait for the robot to move)."""
        if len(self.core.nodes) == 0:
            return
        rebuilt = self._map_dirty or self._last_map is None
        if rebuilt:
            cpu0 = time.thread_time()
            self.core.update_map()
            self._last_map = self.core.occupancy_map()
            self.map_update_cpu_s.append(time.thread_time() - cpu0)
            self._map_dirty = False
        assert self._last_map is not None
        msg = map_to_msg(self._last_map, frame_id=self.config.map_frame,
                         stamp_ns=self.get_clock().now_ns())
        self.map_pub.publish(msg)
        self.meta_pub.publish(msg.info)
        if rebuilt:
            self._publish_graph()

    def _publish_graph(self) -> None:
        poses = self.core.node_poses()
        nodes = Marker(ns="slam_toolbox", id=0, type=Marker.SPHERE_LIST, action=Marker.ADD)
        nodes.header.frame_id = self.config.map_frame
        nodes.scale.x = nodes.scale.y = nodes.scale.z = 0.08
        nodes.color.r, nodes.color.g, nodes.color.b, nodes.color.a = 0.1, 0.3, 1.0, 1.0
        nodes.pose.orientation.w = 1.0
        graph = self.core.graph
        removed = set(graph.removed_nodes)  # lifelong mode marginalised them out
        nodes.points = [Point(x=float(p[0]), y=float(p[1]), z=0.0)
                        for k, p in enumerate(poses) if k not in removed]
        edges = Marker(ns="slam_toolbox_edges", id=1, type=Marker.LINE_LIST, action=Marker.ADD)
        edges.header.frame_id = self.config.map_frame
        edges.scale.x = 0.02
        edges.color.g, edges.color.a = 0.8, 0.8
        edges.pose.orientation.w = 1.0
        pts = []
        dropped = set(graph.removed_edges)
        for k, e in enumerate(graph.edges):
            if k in dropped:
                continue
            a, b = poses[e.i], poses[e.j]
            pts += [
                Point(x=float(a[0]), y=float(a[1]), z=0.0),
                Point(x=float(b[0]), y=float(b[1]), z=0.0),
            ]
        edges.points = pts
        self.graph_pub.publish(MarkerArray(markers=[nodes, edges]))
        self.editing.publish_markers()
