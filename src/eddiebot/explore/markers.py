"""The explore node's ``explore/frontiers`` markers (visualization_msgs/MarkerArray).

Per frontier: its cells as POINTS (blue, red once abandoned) and its centroid as a green
SPHERE (larger for the current target); markers of frontiers gone since the last array are
deleted.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from eddiebot.explore.frontiers import Frontier
from eddiebot.explore.tracking import Blacklist
from eddiebot.maps import OccupancyMap

__all__ = ["frontier_markers"]


def frontier_markers(frontiers: Sequence[Frontier], ids: Sequence[int], blacklist: Blacklist,
                     target: int | None, grid: OccupancyMap, stamp: Any,
                     last_count: int = 0) -> Any:
    """The MarkerArray for ``frontiers`` (tracked as ``ids``) on ``grid``'s frame, deleting
    the markers of the ``last_count`` earlier ones beyond them."""
    from eddiebot.msgs.geometry_msgs import Point
    from eddiebot.msgs.visualization_msgs import Marker, MarkerArray

    frame = grid.frame_id or "map"
    markers = []
    for k, (f, tid) in enumerate(zip(frontiers, ids, strict=True)):
        abandoned = blacklist.contains(f.centroid)
        cells = Marker(ns="frontiers", id=2 * k, type=Marker.POINTS, action=Marker.ADD)
        cells.header.frame_id, cells.header.stamp = frame, stamp
        cells.scale.x = cells.scale.y = grid.resolution
        cells.color.r, cells.color.g, cells.color.b, cells.color.a = \
            (1.0, 0.0, 0.0, 1.0) if abandoned else (0.0, 0.0, 1.0, 1.0)
        cells.pose.orientation.w = 1.0
        cells.points = [Point(x=float(x), y=float(y), z=0.0) for x, y in f.points]
        dot = Marker(ns="frontiers", id=2 * k + 1, type=Marker.SPHERE, action=Marker.ADD)
        dot.header.frame_id, dot.header.stamp = frame, stamp
        dot.pose.position.x, dot.pose.position.y = f.centroid
        dot.pose.orientation.w = 1.0
        size = 0.3 if tid == target else 0.15
        dot.scale.x = dot.scale.y = dot.scale.z = size
        dot.color.g, dot.color.a = 1.0, 1.0
        markers += [cells, dot]
    for k in range(2 * len(frontiers), last_count):
        gone = Marker(ns="frontiers", id=k, action=Marker.DELETE)
        gone.header.frame_id = frame
        markers.append(gone)
    return MarkerArray(markers=markers)
