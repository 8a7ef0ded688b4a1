"""The in-memory occupancy map and its conversions (messages, coordinates)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

__all__ = [
    "FREE",
    "OCCUPIED",
    "UNKNOWN",
    "OccupancyMap",
    "is_inside",
    "map_from_msg",
    "map_to_msg",
    "map_to_world",
    "world_to_map",
]

#: Cell values as in nav2_util (``OCC_GRID_UNKNOWN``, ``OCC_GRID_FREE``, ``OCC_GRID_OCCUPIED``).
UNKNOWN = -1
FREE = 0
OCCUPIED = 100


@dataclass(frozen=True)
class OccupancyMap:
    """An occupancy grid in the map frame.

    ``data`` is int8 of shape (height, width); row 0 is the lowest y and column 0 the lowest
    x (the layout of ``nav_msgs/OccupancyGrid``, not of the image file). Values: -1 unknown,
    0 free .. 100 occupied. ``resolution`` is metres per cell; ``origin`` is the pose
    (x m, y m, yaw rad) of the lower-left corner of cell (0, 0).
    """

    data: npt.NDArray[np.int8]
    resolution: float
    origin: tuple[float, float, float] = (0.0, 0.0, 0.0)
    # Not part of equality: two maps with the same cells are the same map.
    frame_id: str = field(default="map", compare=False)

    def __post_init__(self) -> None:
        data = np.asarray(self.data)
        if data.ndim != 2:
            raise ValueError(
                f"OccupancyMap.data must be 2-D (height, width), got shape {data.shape}"
            )
        if data.dtype != np.int8:
            data = data.astype(np.int8)
        data = np.ascontiguousarray(data)
        data.flags.writeable = False
        object.__setattr__(self, "data", data)
        if not (math.isfinite(self.resolution) and self.resolution > 0.0):
            raise ValueError(f"OccupancyMap.resolution must be > 0, got {self.resolution}")
        origin = tuple(float(v) for v in self.origin)
        if len(origin) != 3:
            raise ValueError(f"OccupancyMap.origin must be (x, y, yaw), got {self.origin}")
        object.__setattr__(self, "origin", origin)
        object.__setattr__(self, "resolution", float(self.resolution))

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, OccupancyMap):
            return NotImplemented
        return (
            self.resolution == other.resolution
            and self.origin == other.origin
            and self.data.shape == other.data.shape
            and bool(np.array_equal(self.data, other.data))
        )

    def __hash__(self) -> int:
        return hash((self.resolution, self.origin, self.data.shape, self.data.tobytes()))

    @property
    def width(self) -> int:
        """Number of columns (cells along x)."""
        return int(self.data.shape[1])

    @property
    def height(self) -> int:
        """Number of rows (cells along y)."""
        return int(self.data.shape[0])


def _origin_rotation(origin: tuple[float, float, float]) -> tuple[float, float]:
    return math.cos(origin[2]), math.sin(origin[2])


def world_to_map(grid: OccupancyMap, points: npt.ArrayLike) -> npt.NDArray[np.int64]:
    """Cell indices (column, row) of world points (..., 2) in the map frame, m.

    Indices are floored and not clipped: check them with `is_inside`.
    """
    pts = np.asarray(points, dtype=float)
    c, s = _origin_rotation(grid.origin)
    dx = pts[..., 0] - grid.origin[0]
    dy = pts[..., 1] - grid.origin[1]
    u = (c * dx + s * dy) / grid.resolution
    v = (-s * dx + c * dy) / grid.resolution
    return np.stack([np.floor(u), np.floor(v)], axis=-1).astype(np.int64)


def map_to_world(grid: OccupancyMap, cells: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """World coordinates (..., 2), m, of the centres of cells given as (column, row)."""
    idx = np.asarray(cells, dtype=float)
    c, s = _origin_rotation(grid.origin)
    u = (idx[..., 0] + 0.5) * grid.resolution
    v = (idx[..., 1] + 0.5) * grid.resolution
    return np.stack([grid.origin[0] + c * u - s * v, grid.origin[1] + s * u + c * v], axis=-1)


def is_inside(grid: OccupancyMap, cells: npt.ArrayLike) -> npt.NDArray[np.bool_]:
    """Whether cells (..., 2) given as (column, row) lie inside the grid."""
    idx = np.asarray(cells)
    return (
        (idx[..., 0] >= 0)
        & (idx[..., 0] < grid.width)
        & (idx[..., 1] >= 0)
        & (idx[..., 1] < grid.height)
    )


def map_to_msg(grid: OccupancyMap, *, frame_id: str | None = None, stamp_ns: int = 0) -> Any:
    """A ``nav_msgs/OccupancyGrid`` carrying the map (header stamped with ``stamp_ns``)."""
    from eddiebot.msgs.builtin_interfaces import Time
    from eddiebot.msgs.geometry_msgs import Point, Pose, Quaternion
    from eddiebot.msgs.nav_msgs import MapMetaData, OccupancyGrid
    from eddiebot.msgs.std_msgs import Header

    stamp = Time(sec=int(stamp_ns // 1_000_000_000), nanosec=int(stamp_ns % 1_000_000_000))
    yaw = grid.origin[2]
    origin = Pose(
        position=Point(x=grid.origin[0], y=grid.origin[1], z=0.0),
        orientation=Quaternion(x=0.0, y=0.0, z=math.sin(yaw / 2.0), w=math.cos(yaw / 2.0)),
    )
    info = MapMetaData(
        map_load_time=stamp,
        resolution=float(grid.resolution),
        width=grid.width,
        height=grid.height,
        origin=origin,
    )
    return OccupancyGrid(
        header=Header(stamp=stamp, frame_id=frame_id if frame_id is not None else grid.frame_id),
        info=info,
        data=np.ascontiguousarray(grid.data, dtype=np.int8).reshape(-1).copy(),
    )


def map_from_msg(msg: Any) -> OccupancyMap:
    """An `OccupancyMap` from a ``nav_msgs/OccupancyGrid``."""
    info = msg.info
    width, height = int(info.width), int(info.height)
    data = np.asarray(msg.data, dtype=np.int8)
    if data.size != width * height:
        raise ValueError(
            f"OccupancyGrid data has {data.size} cells, info says {width}x{height}={width * height}"
        )
    q = info.origin.orientation
    norm = math.sqrt(q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w)
    yaw = (
        0.0
        if norm == 0.0
        else math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))
    )
    frame_id = msg.header.frame_id or "map"
    return OccupancyMap(
        data=data.reshape(height, width).copy(),
        resolution=float(info.resolution),
        origin=(float(info.origin.position.x), float(info.origin.position.y), yaw),
        frame_id=frame_id,
    )
