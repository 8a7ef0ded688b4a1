"""The ``rtabmap`` node's outputs: TF ``map → odom``, the occupancy grid, ``mapGraph`` /
``mapData`` / ``info``, ``localization_pose``, graph markers and the assembled cloud."""

from __future__ import annotations

from typing import Any

import numpy as np

from eddiebot.core.node import Node
from eddiebot.core.qos import qos_profile_latched
from eddiebot.core.tf import TransformBroadcaster, make_transform
from eddiebot.core.time import ns_to_stamp
from eddiebot.geometry import matrix_to_quaternion
from eddiebot.maps import map_to_msg
from eddiebot.msgs.geometry_msgs import PoseWithCovarianceStamped
from eddiebot.msgs.nav_msgs import OccupancyGrid
from eddiebot.msgs.rtabmap_msgs import Info, MapData, MapGraph
from eddiebot.msgs.sensor_msgs import PointCloud2
from eddiebot.msgs.std_msgs import Header
from eddiebot.msgs.visualization_msgs import Marker, MarkerArray
from eddiebot.vslam.ros_messages import (
    cloud_message,
    graph_markers,
    graph_message,
    info_message,
    map_data_message,
    pose_message,
)
from eddiebot.vslam.rtabmap import ProcessResult, Rtabmap

__all__ = ["RtabmapOutputs"]

_SEC = 1_000_000_000


class RtabmapOutputs(Node):
    """Publishers of the ``rtabmap`` node (a base of `RtabmapNode`, which sets the attributes
    below)."""

    core: Rtabmap
    map_frame_id: str
    odom_frame_id: str
    tf_tolerance: float
    cloud_voxel_size: float
    _map_dirty: bool

    def _create_outputs(self, map_topic: str) -> None:
        self.tf_broadcaster = TransformBroadcaster(self)
        self.map_pub = self.create_publisher(OccupancyGrid, map_topic, qos_profile_latched)
        self.graph_pub = self.create_publisher(MapGraph, "~/mapGraph", qos_profile_latched)
        self.map_data_pub = self.create_publisher(MapData, "~/mapData", qos_profile_latched)
        self.info_pub = self.create_publisher(Info, "~/info", 10)
        self.localization_pose_pub = self.create_publisher(
            PoseWithCovarianceStamped, "~/localization_pose", 10)
        self.markers_pub = self.create_publisher(MarkerArray, "~/graph_markers",
                                                 qos_profile_latched)
        self._published_nodes: set[int] = set()
        self.cloud_pub = self.create_publisher(PointCloud2, "~/cloud_map", qos_profile_latched)

    def _publish_tf(self) -> None:
        m = self.core.map_to_odom
        q = matrix_to_quaternion(m[:3, :3])
        stamp = self.get_clock().now_ns() + round(self.tf_tolerance * _SEC)
        self.tf_broadcaster.sendTransform(make_transform(
            self.map_frame_id, self.odom_frame_id, stamp, float(m[0, 3]), float(m[1, 3]),
            float(m[2, 3]), *(float(v) for v in q)))

    def _publish_map(self, force: bool = False) -> None:
        if not (self._map_dirty or force) and self.map_pub.sequence > 0:
            return
        grid = self.core.occupancy_grid()
        if grid is None:
            return
        msg = map_to_msg(grid.to_occupancy_map(self.map_frame_id), frame_id=self.map_frame_id,
                         stamp_ns=self.get_clock().now_ns())
        self.map_pub.publish(msg)
        self._map_dirty = False
        self._publish_graph()

    def _publish_info(self, result: ProcessResult, t: int) -> None:
        header = Header(stamp=ns_to_stamp(t), frame_id=self.map_frame_id)
        core = self.core
        loop_tf = None
        partner = result.loop_closure_id
        if partner and result.node_id:
            link = core.memory.links.get(result.node_id, {}).get(partner)
            loop_tf = None if link is None else link.transform
        weights = {i: n.weight for i, n in core.memory.nodes.items()}
        self.info_pub.publish(info_message(
            header, result, [*core.memory.wm, *core.memory.stm], core.bayes.posterior_arrays(),
            weights, loop_tf))

    def _publish_localization_pose(self, pose: np.ndarray, t: int) -> None:
        """rtabmap's ``localization_pose``: the base in the map frame, covariance 9999 until
        localized, then the last accepted localization's."""
        msg = PoseWithCovarianceStamped()
        msg.header = Header(stamp=ns_to_stamp(t), frame_id=self.map_frame_id)
        msg.pose.pose = pose_message(pose)
        cov = self.core.localization_covariance
        if not self.core.localized or cov is None:
            cov = np.diag([9999.0] * 6)
        msg.pose.covariance = np.asarray(cov, np.float64).reshape(36).copy()
        self.localization_pose_pub.publish(msg)

    def _publish_graph(self) -> None:
        all_poses, links = self.core.graph()
        frames = self.core.map_frames()
        current = frames.get(self.core.current_frame, [])
        poses = {i: all_poses[i] for i in current}
        header = Header(stamp=self.get_clock().now().to_msg(), frame_id=self.map_frame_id)
        graph = graph_message(header, self.core.map_to_odom, poses, links)
        self.graph_pub.publish(graph)
        fresh = [n for i, n in sorted(self.core.memory.nodes.items())
                 if i in poses and i not in self._published_nodes]
        self.map_data_pub.publish(map_data_message(header, graph, fresh))
        self._published_nodes.update(n.id for n in fresh)
        out: list[Marker] = []
        for frame, ids in frames.items():
            # a map not merged yet is drawn in its own frame, map_<id> (no TF joins it)
            name = (self.map_frame_id if frame == self.core.current_frame
                    else f"{self.map_frame_id}_{frame}")
            out += graph_markers({i: all_poses[i] for i in ids}, links, name, len(out))
        self.markers_pub.publish(MarkerArray(markers=out))

    def cloud_message(self) -> Any:
        """The assembled cloud (map frame) as PointCloud2 with x, y, z and packed rgb."""
        xyz, colors = self.core.point_cloud(self.cloud_voxel_size)
        header = Header(stamp=self.get_clock().now().to_msg(), frame_id=self.map_frame_id)
        return cloud_message(xyz, colors, header)

