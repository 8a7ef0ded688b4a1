"""The server side of ROS 2's ``interactive_markers`` protocol, as slam_toolbox's node serves
it for RViz2's InteractiveMarkers display, and the graph-node markers its
``LoopClosureAssistant`` puts there.

Protocol (``interactive_markers::InteractiveMarkerServer``, ROS 2): under a namespace ``ns``
the server answers ``ns/get_interactive_markers`` (visualization_msgs/GetInteractiveMarkers:
every marker and the sequence number of the latest update) and publishes
``ns/update`` (visualization_msgs/InteractiveMarkerUpdate, type UPDATE: markers added or
replaced, names erased; ``seq_num`` grows by one per update). A client asks for the full
set once, then applies updates, and asks again when it sees a sequence number skipped.
RViz sends ``ns/feedback`` (InteractiveMarkerFeedback); the owner of the server handles it
and tells the server where a dragged marker now is (`MarkerServer.set_pose`). As upstream's
ROS 2 server: no keep-alive messages, ``server_id`` left empty, ``update`` on a depth-100
reliable queue.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from eddiebot.core.time import ns_to_stamp
from eddiebot.msgs.visualization_msgs import (
    GetInteractiveMarkers,
    InteractiveMarker,
    InteractiveMarkerControl,
    InteractiveMarkerUpdate,
    Marker,
)

if TYPE_CHECKING:
    from eddiebot.core.node import Node

__all__ = ["GRAPH_MARKER_SCALE", "MarkerServer", "graph_node_marker"]

#: Sizes of slam_toolbox's graph-node markers (m): the sphere and the interactive marker
#: around it (``vis_utils::toMarker(..., 0.1)``, ``toInteractiveMarker(m, 0.3)``).
GRAPH_MARKER_SCALE = (0.1, 0.3)


class MarkerServer:
    """An interactive marker server under ``namespace`` on ``node`` (see the module
    docstring). Markers are kept by name; `replace_all` publishes one update."""

    def __init__(self, node: Node, namespace: str) -> None:
        self.sequence_number = 0
        """The sequence number of the latest update (0 before the first)."""
        self.markers: dict[str, Any] = {}
        """The markers clients have been sent, by name (InteractiveMarker)."""
        self._pub = node.create_publisher(InteractiveMarkerUpdate, f"{namespace}/update", 100)
        self._srv = node.create_service(
            GetInteractiveMarkers, f"{namespace}/get_interactive_markers", self._get
        )

    def _get(self, req: Any, res: Any) -> Any:
        res.sequence_number = self.sequence_number
        res.markers = list(self.markers.values())
        return res

    def replace_all(self, markers: list[Any]) -> bool:
        """Make ``markers`` the server's whole set: one update adds or replaces them and erases
        every other name (upstream's ``clear()``, ``insert()``…, ``applyChanges()``). Returns
        whether an update was published (not when there was nothing before nor now)."""
        new = {str(m.name): m for m in markers}
        erases = [name for name in self.markers if name not in new]
        if not new and not erases:
            return False
        self.markers = new
        self.sequence_number += 1
        self._pub.publish(
            InteractiveMarkerUpdate(
                seq_num=self.sequence_number,
                type=InteractiveMarkerUpdate.UPDATE,
                markers=list(new.values()),
                erases=erases,
            )
        )
        return True

    def set_pose(self, name: str, pose: Any) -> bool:
        """Where a client dragged marker ``name`` (geometry_msgs/Pose): kept, so a client that
        asks for the full set sees it there, as upstream's ``processFeedback`` does. False when
        no such marker."""
        marker = self.markers.get(name)
        if marker is None:
            return False
        marker.pose = pose
        return True


def graph_node_marker(
    node_id: int, pose: npt.ArrayLike, frame_id: str, stamp_ns: int
) -> Any:
    """slam_toolbox's interactive marker for graph node ``node_id`` at robot pose ``pose``
    (x, y, theta in ``frame_id``; the marker is unrotated, as upstream, so the orientation a
    client sends back is the turn the user gave): named by the node id, a red sphere with a
    planar move control and a rotation control about the vertical axis
    (``vis_utils::toInteractiveMarker``)."""
    p = np.asarray(pose, dtype=np.float64).reshape(-1)
    sphere_scale, marker_scale = GRAPH_MARKER_SCALE
    stamp = ns_to_stamp(stamp_ns)
    sphere = Marker(ns="slam_toolbox", id=int(node_id), type=Marker.SPHERE, action=Marker.ADD)
    sphere.header.frame_id = frame_id
    sphere.header.stamp = stamp
    sphere.pose.position.x, sphere.pose.position.y = float(p[0]), float(p[1])
    sphere.pose.orientation.w = 1.0
    sphere.scale.x = sphere.scale.y = sphere.scale.z = sphere_scale
    sphere.color.r, sphere.color.a = 1.0, 1.0
    out = InteractiveMarker(name=str(int(node_id)), scale=marker_scale)
    out.header.frame_id = frame_id
    out.header.stamp = stamp
    out.pose.position.x, out.pose.position.y = float(p[0]), float(p[1])
    out.pose.orientation.w = 1.0
    controls = []
    for mode, shapes in (
        (InteractiveMarkerControl.MOVE_PLANE, [sphere]),
        (InteractiveMarkerControl.ROTATE_AXIS, []),
    ):
        control = InteractiveMarkerControl(
            orientation_mode=InteractiveMarkerControl.FIXED,
            interaction_mode=mode,
            always_visible=True,
            markers=shapes,
        )
        # upstream's quaternion (w = 0) turns the control's x axis onto the map's z axis:
        # move in the ground plane, rotate about the vertical
        o = control.orientation
        o.x, o.y, o.z, o.w = 0.7071, 0.0, 0.7071, 0.0
        controls.append(control)
    out.controls = controls
    return out
