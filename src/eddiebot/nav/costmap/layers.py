"""Costmap layers with Nav2's updateBounds/updateCosts contract.

A layer is told the robot pose and grows the update bounds (world frame, m) to cover what it
changed (``update_bounds``); the layered costmap then resets that window of the master grid
and lets each layer, in order, write its costs into it (``update_costs``, cell window
``[i0, i1) x [j0, j1)``). Static, obstacle and range layers keep their own grid and combine it
into the master; the inflation layer works on the master directly.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from eddiebot.maps import OccupancyMap
from eddiebot.nav.cost_values import (
    FREE_SPACE,
    INSCRIBED_INFLATED_OBSTACLE,
    LETHAL_OBSTACLE,
    NO_INFORMATION,
)
from eddiebot.nav.costmap import _kernels
from eddiebot.nav.costmap.costmap2d import Costmap2D
from eddiebot.nav.costmap.footprint import transform_footprint
from eddiebot.nav.params import require

if TYPE_CHECKING:
    from eddiebot.nav.costmap.layered import LayeredCostmap

Bounds = list[float]  # [min_x, min_y, max_x, max_y], world frame (m)


def empty_bounds() -> Bounds:
    return [math.inf, math.inf, -math.inf, -math.inf]


def touch(bounds: Bounds, x: float, y: float) -> None:
    bounds[0] = min(bounds[0], x)
    bounds[1] = min(bounds[1], y)
    bounds[2] = max(bounds[2], x)
    bounds[3] = max(bounds[3], y)


def merge_bounds(bounds: Bounds, other: npt.ArrayLike) -> None:
    o = np.asarray(other, dtype=np.float64)
    if o[0] <= o[2] and o[1] <= o[3]:
        touch(bounds, float(o[0]), float(o[1]))
        touch(bounds, float(o[2]), float(o[3]))


# --- combination rules (CostmapLayer::updateWith*) --------------------------------------
def update_with_max(master: Costmap2D, layer: Costmap2D, i0: int, j0: int, i1: int, j1: int) -> None:
    m = master.data[j0:j1, i0:i1]
    s = layer.data[j0:j1, i0:i1]
    mask = (s != NO_INFORMATION) & ((m == NO_INFORMATION) | (m < s))
    m[mask] = s[mask]


def update_with_true_overwrite(
    master: Costmap2D, layer: Costmap2D, i0: int, j0: int, i1: int, j1: int
) -> None:
    master.data[j0:j1, i0:i1] = layer.data[j0:j1, i0:i1]


def update_with_overwrite(
    master: Costmap2D, layer: Costmap2D, i0: int, j0: int, i1: int, j1: int
) -> None:
    m = master.data[j0:j1, i0:i1]
    s = layer.data[j0:j1, i0:i1]
    mask = s != NO_INFORMATION
    m[mask] = s[mask]


def update_with_max_without_unknown_overwrite(
    master: Costmap2D, layer: Costmap2D, i0: int, j0: int, i1: int, j1: int
) -> None:
    m = master.data[j0:j1, i0:i1]
    s = layer.data[j0:j1, i0:i1]
    mask = (s != NO_INFORMATION) & (m < s) & (m != NO_INFORMATION)
    m[mask] = s[mask]


class Layer:
    """Base layer: holds its name and a back reference to the layered costmap."""

    clearable = False

    def __init__(self, name: str) -> None:
        self.name = name
        self.enabled = True
        self.current = True
        self._layered: LayeredCostmap | None = None

    @property
    def layered(self) -> LayeredCostmap:
        if self._layered is None:
            raise RuntimeError(f"layer {self.name} is not part of a layered costmap")
        return self._layered

    def initialize(self, layered: LayeredCostmap) -> None:
        self._layered = layered
        self.match_size()

    def match_size(self) -> None:
        """Resize own state to the master grid."""

    def update_origin(self, origin_x: float, origin_y: float) -> None:
        """Rolling window moved."""

    def update_bounds(self, robot_x: float, robot_y: float, robot_yaw: float, bounds: Bounds) -> None:
        """Grow ``bounds`` (in place) to cover what changed since the last update."""

    def update_costs(self, master: Costmap2D, i0: int, j0: int, i1: int, j1: int) -> None:
        """Write this layer's costs into window [i0, i1) x [j0, j1) of ``master``."""

    def reset(self) -> None:
        """Forget dynamic state (``Layer::reset``)."""

    def clear_area(self, i0: int, j0: int, i1: int, j1: int, invert: bool) -> None:
        """``CostmapLayer::clearArea``: unknown inside (invert) or outside the open box."""

    def on_footprint_changed(self) -> None:
        """Footprint / inscribed radius changed."""


class CostmapLayer(Layer):
    """A layer with its own grid aligned with the master."""

    def __init__(self, name: str) -> None:
        super().__init__(name)
        self.costmap = Costmap2D(0, 0, 1.0)
        self._extra: Bounds = empty_bounds()

    def _default_value(self) -> int:
        return NO_INFORMATION if self.layered.track_unknown_space else FREE_SPACE

    def match_size(self) -> None:
        m = self.layered.master
        self.costmap.default_value = self._default_value()
        self.costmap.resize(m.size_x, m.size_y, m.resolution, m.origin_x, m.origin_y)

    def update_origin(self, origin_x: float, origin_y: float) -> None:
        self.costmap.update_origin(origin_x, origin_y)

    def add_extra_bounds(self, x0: float, y0: float, x1: float, y1: float) -> None:
        touch(self._extra, x0, y0)
        touch(self._extra, x1, y1)

    def _use_extra_bounds(self, bounds: Bounds) -> None:
        if self._extra[0] <= self._extra[2]:
            merge_bounds(bounds, self._extra)
        self._extra = empty_bounds()

    def clear_area(self, i0: int, j0: int, i1: int, j1: int, invert: bool) -> None:
        self.current = False
        g = self.costmap.data
        ys, xs = np.mgrid[0:g.shape[0], 0:g.shape[1]]
        inside = (xs > i0) & (xs < i1) & (ys > j0) & (ys < j1)
        g[inside if invert else ~inside] = NO_INFORMATION
        self.add_extra_bounds(
            self.costmap.origin_x, self.costmap.origin_y,
            self.costmap.origin_x + g.shape[1] * self.costmap.resolution,
            self.costmap.origin_y + g.shape[0] * self.costmap.resolution,
        )


# --- static layer ------------------------------------------------------------------------
@dataclass(frozen=True)
class StaticLayerConfig:
    """``static_layer`` parameters (Jazzy code defaults)."""

    enabled: bool = True
    subscribe_to_updates: bool = False
    map_subscribe_transient_local: bool = True
    transform_tolerance: float = 0.0
    map_topic: str = ""
    footprint_clearing_enabled: bool = False
    restore_cleared_footprint: bool = True

    def validate(self, server: str = "static_layer") -> None:
        require(self.transform_tolerance >= 0.0, server, "transform_tolerance",
                self.transform_tolerance, "must be >= 0")


def interpret_static_value(
    data: npt.NDArray[np.int8],
    *,
    track_unknown_space: bool,
    lethal_cost_threshold: int,
    unknown_cost_value: int,
    trinary_costmap: bool,
) -> npt.NDArray[np.uint8]:
    """``StaticLayer::interpretValue`` over a whole OccupancyGrid array (values as uint8)."""
    v = np.asarray(data).astype(np.int8).view(np.uint8)
    out = np.empty(v.shape, dtype=np.uint8)
    unknown = v == (unknown_cost_value & 0xFF)
    lethal = (~unknown) & (v >= lethal_cost_threshold)
    rest = ~(unknown | lethal)
    if trinary_costmap:
        out[rest] = FREE_SPACE
    else:
        out[rest] = (v[rest].astype(np.float64) / lethal_cost_threshold * LETHAL_OBSTACLE).astype(
            np.uint8
        )
    out[lethal] = LETHAL_OBSTACLE
    out[unknown] = NO_INFORMATION if track_unknown_space else FREE_SPACE
    return out


class StaticLayer(CostmapLayer):
    """``nav2_costmap_2d::StaticLayer``: costs from an occupancy map.

    Non-rolling: the master is resized to the map and the layer's grid is combined with max
    (``use_maximum``) or true overwrite. Rolling: each master cell samples the map through
    ``map_to_global`` (pose of the map frame in the costmap's global frame, x/y m and yaw
    rad; whoever runs the costmap sets it before each update, None skips the layer).
    """

    def __init__(self, name: str = "static_layer", config: StaticLayerConfig | None = None) -> None:
        super().__init__(name)
        self.config = config or StaticLayerConfig()
        self.enabled = self.config.enabled
        self._map: OccupancyMap | None = None
        self._map_costs: npt.NDArray[np.uint8] | None = None
        self._has_updated_data = False
        self.map_to_global: npt.NDArray[np.float64] | None = np.zeros(3)

    @property
    def has_map(self) -> bool:
        return self._map is not None

    def match_size(self) -> None:
        layered = self.layered
        if self._map is not None and not layered.rolling_window:
            m = self._map
            self.costmap.default_value = self._default_value()
            self.costmap.resize(m.width, m.height, m.resolution, m.origin[0], m.origin[1])
            assert self._map_costs is not None
            self.costmap.data[:] = self._map_costs
        else:
            super().match_size()

    def set_map(self, occupancy_map: OccupancyMap) -> None:
        """New map (``incomingMap``)."""
        layered = self.layered
        self._map = occupancy_map
        self._map_costs = interpret_static_value(
            occupancy_map.data,
            track_unknown_space=layered.track_unknown_space,
            lethal_cost_threshold=layered.config.lethal_cost_threshold,
            unknown_cost_value=layered.config.unknown_cost_value,
            trinary_costmap=layered.config.trinary_costmap,
        )
        m = layered.master
        if not layered.rolling_window and (
            m.size_x != occupancy_map.width or m.size_y != occupancy_map.height
            or m.resolution != occupancy_map.resolution
            or m.origin_x != occupancy_map.origin[0] or m.origin_y != occupancy_map.origin[1]
        ):
            layered.resize_map(
                occupancy_map.width, occupancy_map.height, occupancy_map.resolution,
                occupancy_map.origin[0], occupancy_map.origin[1],
            )
        else:
            self.match_size()
        self._has_updated_data = True

    def reset(self) -> None:
        self._has_updated_data = True

    def update_bounds(self, robot_x: float, robot_y: float, robot_yaw: float, bounds: Bounds) -> None:
        if self._map is None:
            return
        if not self.layered.rolling_window and not (
            self._has_updated_data or self._extra[0] <= self._extra[2]
        ):
            return
        if self.layered.rolling_window and self.map_to_global is None:
            return
        self._use_extra_bounds(bounds)
        m = self._map
        if self.layered.rolling_window:
            assert self.map_to_global is not None
            x, y, th = self.map_to_global
            corners = np.array([[0, 0], [m.width, 0], [0, m.height], [m.width, m.height]],
                               dtype=np.float64) * m.resolution + np.array(m.origin[:2])
            c, s = math.cos(th), math.sin(th)
            for cx, cy in corners:
                touch(bounds, x + c * cx - s * cy, y + s * cx + c * cy)
        else:
            touch(bounds, m.origin[0], m.origin[1])
            touch(bounds, m.origin[0] + m.width * m.resolution, m.origin[1] + m.height * m.resolution)
        self._has_updated_data = False

    def update_costs(self, master: Costmap2D, i0: int, j0: int, i1: int, j1: int) -> None:
        if not self.enabled or self._map is None or self._map_costs is None:
            return
        if not self.layered.rolling_window:
            if self.layered.config.use_maximum:
                update_with_max(master, self.costmap, i0, j0, i1, j1)
            else:
                update_with_true_overwrite(master, self.costmap, i0, j0, i1, j1)
            return
        # Rolling window: sample the map at each master cell centre.
        if self.map_to_global is None:
            return
        m = self._map
        ii, jj = np.meshgrid(np.arange(i0, i1), np.arange(j0, j1))
        wx = master.origin_x + (ii + 0.5) * master.resolution
        wy = master.origin_y + (jj + 0.5) * master.resolution
        x, y, th = self.map_to_global
        c, s = math.cos(th), math.sin(th)
        mx_w = c * (wx - x) + s * (wy - y)
        my_w = -s * (wx - x) + c * (wy - y)
        mx = np.floor((mx_w - m.origin[0]) / m.resolution).astype(np.int64)
        my = np.floor((my_w - m.origin[1]) / m.resolution).astype(np.int64)
        ok = (mx >= 0) & (my >= 0) & (mx < m.width) & (my < m.height)
        win = master.data[j0:j1, i0:i1]
        win[ok] = self._map_costs[my[ok], mx[ok]]


# --- obstacle layer ----------------------------------------------------------------------
@dataclass(frozen=True)
class ObservationSourceConfig:
    """One entry of ``observation_sources`` (Jazzy code defaults)."""

    topic: str = ""
    sensor_frame: str = ""
    observation_persistence: float = 0.0
    expected_update_rate: float = 0.0
    data_type: str = "LaserScan"
    min_obstacle_height: float = 0.0
    max_obstacle_height: float = 2.0
    inf_is_valid: bool = False
    marking: bool = True
    clearing: bool = False
    obstacle_max_range: float = 2.5
    obstacle_min_range: float = 0.0
    raytrace_max_range: float = 3.0
    raytrace_min_range: float = 0.0

    def validate(self, server: str = "obstacle_layer") -> None:
        require(self.data_type in ("LaserScan", "PointCloud2"), server, "data_type",
                self.data_type, "must be LaserScan or PointCloud2")
        require(self.obstacle_max_range >= self.obstacle_min_range >= 0.0, server,
                "obstacle_max_range", self.obstacle_max_range, "needs max >= min >= 0")
        require(self.raytrace_max_range >= self.raytrace_min_range >= 0.0, server,
                "raytrace_max_range", self.raytrace_max_range, "needs max >= min >= 0")
        require(self.observation_persistence >= 0.0, server, "observation_persistence",
                self.observation_persistence, "must be >= 0")


@dataclass(frozen=True)
class ObstacleLayerConfig:
    """``obstacle_layer`` parameters (Jazzy code defaults); ``sources`` keyed by source name."""

    enabled: bool = True
    footprint_clearing_enabled: bool = True
    min_obstacle_height: float = 0.0
    max_obstacle_height: float = 2.0
    combination_method: int = 1
    observation_sources: str = ""
    sources: dict[str, ObservationSourceConfig] = field(default_factory=dict)

    def validate(self, server: str = "obstacle_layer") -> None:
        require(self.combination_method in (0, 1, 2), server, "combination_method",
                self.combination_method, "must be 0 (overwrite), 1 (max) or 2 (max without unknown overwrite)")
        for name in self.observation_sources.split():
            require(name in self.sources, server, "observation_sources", self.observation_sources,
                    f"source {name!r} has no parameters")


@dataclass(frozen=True)
class Observation:
    """A set of points in the costmap's global frame seen from ``origin`` (x, y, z; m).

    ``points`` are for marking; ``clearing_points`` (defaults to ``points``) are the ray ends
    for clearing (scans with ``inf_is_valid`` add max-range ends there). ``stamp_ns`` orders
    observations for ``observation_persistence``.
    """

    origin: npt.NDArray[np.float64]
    points: npt.NDArray[np.float64]
    clearing_points: npt.NDArray[np.float64] | None = None
    stamp_ns: int = 0


def scan_points(
    ranges: npt.ArrayLike,
    angle_min: float,
    angle_increment: float,
    range_min: float,
    range_max: float,
    sensor_pose: npt.ArrayLike,
    *,
    inf_is_valid: bool = False,
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Project a LaserScan into the global frame; returns (marking points, clearing points), N x 3.

    ``sensor_pose`` = (x, y, z, yaw) of the scan frame in the global frame. Ranges outside
    [range_min, range_max] and non-finite ones are dropped (laser_geometry); with
    ``inf_is_valid`` +inf becomes ``range_max - 1e-4`` (Nav2's laserScanValidInfCallback).
    """
    r = np.asarray(ranges, dtype=np.float64).copy()
    if inf_is_valid:
        r[np.isposinf(r)] = range_max - 1e-4
    ang = angle_min + angle_increment * np.arange(r.shape[0])
    ok = np.isfinite(r) & (r >= range_min) & (r <= range_max)
    sx, sy, sz, syaw = (float(v) for v in np.asarray(sensor_pose, dtype=np.float64)[:4])
    a = ang[ok] + syaw
    pts = np.empty((int(ok.sum()), 3))
    pts[:, 0] = sx + r[ok] * np.cos(a)
    pts[:, 1] = sy + r[ok] * np.sin(a)
    pts[:, 2] = sz
    return pts, pts


def scan_observation(
    ranges: npt.ArrayLike,
    angle_min: float,
    angle_increment: float,
    range_min: float,
    range_max: float,
    sensor_pose: npt.ArrayLike,
    *,
    inf_is_valid: bool = False,
    stamp_ns: int = 0,
) -> Observation:
    """An :class:`Observation` from LaserScan fields; see :func:`scan_points`."""
    mark, clear = scan_points(ranges, angle_min, angle_increment, range_min, range_max,
                              sensor_pose, inf_is_valid=inf_is_valid)
    sp = np.asarray(sensor_pose, dtype=np.float64)
    return Observation(np.array([sp[0], sp[1], sp[2]]), mark, clear, stamp_ns)


def cloud_observation(
    points_global: npt.ArrayLike, sensor_origin: npt.ArrayLike, stamp_ns: int = 0
) -> Observation:
    """An :class:`Observation` from a point cloud already in the global frame (N x 3, m)."""
    pts = np.asarray(points_global, dtype=np.float64).reshape(-1, 3)
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    return Observation(np.asarray(sensor_origin, dtype=np.float64)[:3].copy(), pts, None, stamp_ns)


class ObstacleLayer(CostmapLayer):
    """``nav2_costmap_2d::ObstacleLayer``: marking and ray-traced clearing from sensors.

    Also serves ``VoxelLayer`` configurations as a 2-D projection: points are gated by the
    per-source ``min/max_obstacle_height`` before marking, so a table top seen by the depth
    cloud marks its cells although the scan passes under it.
    """

    clearable = True

    def __init__(self, name: str = "obstacle_layer", config: ObstacleLayerConfig | None = None) -> None:
        super().__init__(name)
        self.config = config or ObstacleLayerConfig()
        self.config.validate(name)
        self.enabled = self.config.enabled
        self._buffers: dict[str, deque[Observation]] = {}
        self._footprint_world: npt.NDArray[np.float64] | None = None

    def source(self, name: str) -> ObservationSourceConfig:
        if name not in self.config.sources:
            # An undeclared source gets defaults (convenient for tests and tools).
            return ObservationSourceConfig(marking=True, clearing=True)
        return self.config.sources[name]

    def add_observation(self, source: str, obs: Observation) -> None:
        """Buffer an observation (``ObservationBuffer``): newest only, or those within
        ``observation_persistence`` seconds of the newest. Points outside the source's
        [min_obstacle_height, max_obstacle_height] are dropped from marking here."""
        cfg = self.source(source)
        pts = obs.points
        keep = (pts[:, 2] >= cfg.min_obstacle_height) & (pts[:, 2] <= cfg.max_obstacle_height)
        clearing = obs.clearing_points if obs.clearing_points is not None else obs.points
        if obs.clearing_points is None:
            clearing = clearing[keep]
        obs = Observation(obs.origin, np.ascontiguousarray(pts[keep]),
                          np.ascontiguousarray(clearing), obs.stamp_ns)
        buf = self._buffers.setdefault(source, deque())
        buf.append(obs)
        keep_ns = round(cfg.observation_persistence * 1e9)
        while len(buf) > 1 and (keep_ns == 0 or obs.stamp_ns - buf[0].stamp_ns > keep_ns):
            buf.popleft()

    def reset(self) -> None:
        self.costmap.reset_all()
        self._buffers.clear()
        self.current = True

    def update_bounds(self, robot_x: float, robot_y: float, robot_yaw: float, bounds: Bounds) -> None:
        if not self.enabled:
            return
        self._use_extra_bounds(bounds)
        cm = self.costmap
        for name, buf in self._buffers.items():
            cfg = self.source(name)
            if not cfg.clearing:
                continue
            for obs in buf:
                assert obs.clearing_points is not None
                if obs.clearing_points.shape[0] == 0:
                    continue
                b = _kernels.raytrace_many(
                    cm.data, float(obs.origin[0]), float(obs.origin[1]), obs.clearing_points,
                    cm.origin_x, cm.origin_y, cm.resolution,
                    cfg.raytrace_max_range, cfg.raytrace_min_range,
                )
                merge_bounds(bounds, b)
        for name, buf in self._buffers.items():
            cfg = self.source(name)
            if not cfg.marking:
                continue
            for obs in buf:
                if obs.points.shape[0] == 0:
                    continue
                b = _kernels.mark_points(
                    cm.data, obs.origin, obs.points, cm.origin_x, cm.origin_y, cm.resolution,
                    cfg.obstacle_max_range, cfg.obstacle_min_range, self.config.max_obstacle_height,
                )
                merge_bounds(bounds, b)
        if self.config.footprint_clearing_enabled:
            fp = transform_footprint((robot_x, robot_y, robot_yaw), self.layered.footprint)
            self._footprint_world = fp
            for x, y in fp:
                touch(bounds, float(x), float(y))

    def update_costs(self, master: Costmap2D, i0: int, j0: int, i1: int, j1: int) -> None:
        if not self.enabled:
            return
        if self.config.footprint_clearing_enabled and self._footprint_world is not None:
            self.costmap.set_convex_polygon_cost(self._footprint_world, FREE_SPACE)
        method = self.config.combination_method
        if method == 0:
            update_with_overwrite(master, self.costmap, i0, j0, i1, j1)
        elif method == 1:
            update_with_max(master, self.costmap, i0, j0, i1, j1)
        else:
            update_with_max_without_unknown_overwrite(master, self.costmap, i0, j0, i1, j1)


# --- range layer -------------------------------------------------------------------------
@dataclass(frozen=True)
class RangeLayerConfig:
    """``range_sensor_layer`` parameters (Jazzy code defaults)."""

    enabled: bool = True
    topics: tuple[str, ...] = ("",)
    phi: float = 1.2
    inflate_cone: float = 1.0
    no_readings_timeout: float = 0.0
    clear_threshold: float = 0.2
    mark_threshold: float = 0.8
    clear_on_max_reading: bool = False
    input_sensor_type: str = "ALL"
    # eddiebot: "probabilistic" (Nav2's model) or "deterministic" (see RangeLayer)
    sensor_model: str = "probabilistic"

    def validate(self, server: str = "range_layer") -> None:
        require(self.input_sensor_type in ("ALL", "VARIABLE", "FIXED"), server,
                "input_sensor_type", self.input_sensor_type, "must be ALL, VARIABLE or FIXED")
        require(self.inflate_cone >= 0.0, server, "inflate_cone", self.inflate_cone, "must be >= 0")
        require(self.sensor_model in ("probabilistic", "deterministic"), server, "sensor_model",
                self.sensor_model, "must be probabilistic or deterministic")
        require(0.0 <= self.clear_threshold <= 1.0, server, "clear_threshold",
                self.clear_threshold, "must be a probability in [0, 1]")
        require(0.0 <= self.mark_threshold <= 1.0, server, "mark_threshold",
                self.mark_threshold, "must be a probability in [0, 1]")


@dataclass(frozen=True)
class RangeReading:
    """A ``sensor_msgs/Range`` reading with its sensor pose (x, y, yaw) in the global frame."""

    pose: tuple[float, float, float]
    field_of_view: float
    min_range: float
    max_range: float
    range: float


class RangeLayer(CostmapLayer):
    """Sonar/IR cones (``nav2_costmap_2d::RangeSensorLayer``).

    ``sensor_model: probabilistic`` (the default) is Nav2's model: the layer keeps an
    occupancy probability per cell (``cost / 254``, unknown cells start at 0.5) and every
    reading updates the cells of its cone by Bayes' rule with the sensor model of
    ``sensor_model()`` -- a clearing zone up to ``r - 2·res·r``, a marking band
    ``r ± res·r`` (res = the costmap resolution in m, as upstream), both weighted by
    ``delta(phi) = 1 - (1 + tanh(2 (phi - phi_v))) / 2`` (less trust far away, ``phi``) and
    ``gamma(theta) = 1 - (theta / half_fov)^2`` (less trust at the cone's edge). The cell of
    the measured point is first set to 233. With ``inflate_cone`` < 1 only the cells inside
    the cone's triangle, grown by ``inflate_cone`` (upstream's barycentric test), are updated;
    at 1 the whole bounding box of the triangle is. Cells above ``mark_threshold`` write
    LETHAL into the master, cells below ``clear_threshold`` FREE (into unknown or lower
    master cells only). Fixed rangers (``min_range == max_range``) report -inf (object) or
    +inf (nothing); variable ones are ignored outside [min_range, max_range], and a
    max-range reading clears the cone (sensor probability 0) with ``clear_on_max_reading``
    and is otherwise an ordinary reading. ``no_readings_timeout`` > 0 makes the layer
    not current when no reading arrived for that long (needs :meth:`set_time`).

    ``sensor_model: deterministic`` (eddiebot): a reading inside [min_range, max_range)
    marks the cells on the arc at the measured range (within the cone half-angle
    ``field_of_view/2 · inflate_cone``) LETHAL and clears the cells of the cone nearer than
    the arc; a max-range reading clears the whole cone when ``clear_on_max_reading`` is set
    and is otherwise ignored; readings below min_range are ignored.
    """

    clearable = True

    def __init__(self, name: str = "range_layer", config: RangeLayerConfig | None = None) -> None:
        super().__init__(name)
        self.config = config or RangeLayerConfig()
        self.config.validate(name)
        self.enabled = self.config.enabled
        self._pending: list[RangeReading] = []
        self._probabilistic = self.config.sensor_model == "probabilistic"
        self._now_ns: int | None = None
        self._last_reading_ns: int | None = None
        self._buffered = 0
        self._was_reset = False

    def _default_value(self) -> int:
        if self._probabilistic:
            return _to_cost(0.5)  # upstream default_value_
        return super()._default_value()

    def add_reading(self, reading: RangeReading) -> None:
        self._pending.append(reading)

    def set_time(self, now_ns: int) -> None:
        """The clock for ``no_readings_timeout`` (upstream reads the node clock)."""
        self._now_ns = int(now_ns)
        if self._last_reading_ns is None:
            self._last_reading_ns = self._now_ns

    def reset(self) -> None:
        self.costmap.reset_all()
        self._pending.clear()
        self._was_reset = True

    def update_bounds(self, robot_x: float, robot_y: float, robot_yaw: float, bounds: Bounds) -> None:
        if not self.enabled:
            self._pending.clear()
            self.current = True
            return
        self._use_extra_bounds(bounds)
        for rd in self._pending:
            used = self._process(rd, bounds) if self._probabilistic else self._apply(rd, bounds)
            if used:
                self._buffered += 1
                if self._now_ns is not None:
                    self._last_reading_ns = self._now_ns
        self._pending.clear()
        timeout = self.config.no_readings_timeout
        if (self._buffered == 0 and timeout > 0.0 and self._now_ns is not None
                and self._last_reading_ns is not None
                and (self._now_ns - self._last_reading_ns) * 1e-9 > timeout):
            self.current = False

    # -- Nav2's probabilistic model ------------------------------------------------------------
    def _process(self, rd: RangeReading, bounds: Bounds) -> bool:
        r = rd.range
        fixed = self.config.input_sensor_type == "FIXED" or (
            self.config.input_sensor_type == "ALL" and rd.min_range == rd.max_range)
        clear = False
        if fixed:
            if not math.isinf(r):
                return False  # only -inf (object) and +inf (nothing) are valid
            if r > 0:
                if not self.config.clear_on_max_reading:
                    return False
                clear = True
            r = rd.min_range
        else:
            if not (rd.min_range <= r <= rd.max_range):
                return False  # also NaN
            clear = r >= rd.max_range and self.config.clear_on_max_reading
        self._update_cone(rd, r, clear, bounds)
        return True

    def _update_cone(self, rd: RangeReading, r: float, clear: bool, bounds: Bounds) -> None:
        cm = self.costmap
        res = cm.resolution
        ox, oy, theta = rd.pose
        half = 0.5 * rd.field_of_view
        tx, ty = ox + r * math.cos(theta), oy + r * math.sin(theta)
        o = cm.world_to_map_no_bounds(ox, oy)
        touch(bounds, ox, oy)
        hit = cm.world_to_map(tx, ty)
        if hit is not None:
            cm.data[hit[1], hit[0]] = 233
            touch(bounds, tx, ty)
        d = abs(r)
        ax, ay = ox + math.cos(theta - half) * d * 1.2, oy + math.sin(theta - half) * d * 1.2
        bx, by = ox + math.cos(theta + half) * d * 1.2, oy + math.sin(theta + half) * d * 1.2
        a = cm.world_to_map_no_bounds(ax, ay)
        b = cm.world_to_map_no_bounds(bx, by)
        touch(bounds, ax, ay)
        touch(bounds, bx, by)
        i0 = max(0, min(o[0], a[0], b[0]))
        j0 = max(0, min(o[1], a[1], b[1]))
        i1 = min(cm.size_x - 1, max(o[0], a[0], b[0]))  # upstream loops to size (then skips)
        j1 = min(cm.size_y - 1, max(o[1], a[1], b[1]))
        if i1 < i0 or j1 < j0:
            return
        ii, jj = np.meshgrid(np.arange(i0, i1 + 1), np.arange(j0, j1 + 1))
        if self.config.inflate_cone < 1.0:
            def orient(p: tuple[int, int], q: tuple[int, int]) -> npt.NDArray[np.int64]:
                return (q[0] - p[0]) * (jj - p[1]) - (q[1] - p[1]) * (ii - p[0])

            area = abs((a[0] * (b[1] - o[1]) + b[0] * (o[1] - a[1]) + o[0] * (a[1] - b[1])) / 2.0)
            th = -float(np.float32(self.config.inflate_cone)) * area
            sel = (orient(a, b) >= th) & (orient(b, o) >= th) & (orient(o, a) >= th)
        else:
            sel = np.ones(ii.shape, dtype=bool)
        cx = cm.origin_x + (ii + 0.5) * res
        cy = cm.origin_y + (jj + 0.5) * res
        dx, dy = cx - ox, cy - oy
        phi = np.hypot(dx, dy)
        ang = (np.arctan2(dy, dx) - theta + math.pi) % (2.0 * math.pi) - math.pi
        sensor = np.zeros(phi.shape) if clear else sensor_model(
            r, phi, ang, half, self.config.phi, res)
        win = cm.data[j0:j1 + 1, i0:i1 + 1]
        prior = win.astype(np.float64) / LETHAL_OBSTACLE
        occ = sensor * prior
        not_occ = (1.0 - sensor) * (1.0 - prior)
        with np.errstate(invalid="ignore", divide="ignore"):
            post = occ / (occ + not_occ)
        sel &= np.isfinite(post)
        win[sel] = _to_cost_array(post[sel])

    # -- eddiebot's deterministic rule ---------------------------------------------------------
    def _apply(self, rd: RangeReading, bounds: Bounds) -> bool:
        r = rd.range
        if not math.isfinite(r) or r < rd.min_range or r > rd.max_range:
            return False
        at_max = r >= rd.max_range
        if at_max and not self.config.clear_on_max_reading:
            return False
        cm = self.costmap
        res = cm.resolution
        sx, sy, syaw = rd.pose
        half = 0.5 * rd.field_of_view * self.config.inflate_cone
        reach = r + res
        xs = [sx, sx + reach * math.cos(syaw - half), sx + reach * math.cos(syaw + half),
              sx + reach * math.cos(syaw)]
        ys = [sy, sy + reach * math.sin(syaw - half), sy + reach * math.sin(syaw + half),
              sy + reach * math.sin(syaw)]
        i0, j0 = cm.world_to_map_enforce_bounds(min(xs) - res, min(ys) - res)
        i1, j1 = cm.world_to_map_enforce_bounds(max(xs) + res, max(ys) + res)
        ii, jj = np.meshgrid(np.arange(i0, i1 + 1), np.arange(j0, j1 + 1))
        cx = cm.origin_x + (ii + 0.5) * res
        cy = cm.origin_y + (jj + 0.5) * res
        d = np.hypot(cx - sx, cy - sy)
        ang = np.abs((np.arctan2(cy - sy, cx - sx) - syaw + math.pi) % (2 * math.pi) - math.pi)
        in_cone = ang <= half
        win = cm.data[j0:j1 + 1, i0:i1 + 1]
        if at_max:
            win[in_cone & (d <= r)] = FREE_SPACE
        else:
            win[in_cone & (d < r - 0.5 * res)] = FREE_SPACE
            win[in_cone & (np.abs(d - r) <= 0.5 * res)] = LETHAL_OBSTACLE
            hit = cm.world_to_map(sx + r * math.cos(syaw), sy + r * math.sin(syaw))
            if hit is not None:
                cm.data[hit[1], hit[0]] = LETHAL_OBSTACLE
        touch(bounds, min(xs), min(ys))
        touch(bounds, max(xs), max(ys))
        return True

    def update_costs(self, master: Costmap2D, i0: int, j0: int, i1: int, j1: int) -> None:
        if not self.enabled:
            return
        if self._probabilistic:
            self._update_costs_probabilistic(master, i0, j0, i1, j1)
        else:
            update_with_max(master, self.costmap, i0, j0, i1, j1)
        self._buffered = 0
        if not self.current and self._was_reset:
            self._was_reset = False
            self.current = True

    def _update_costs_probabilistic(self, master: Costmap2D, i0: int, j0: int, i1: int, j1: int
                                    ) -> None:
        s = self.costmap.data[j0:j1, i0:i1]
        m = master.data[j0:j1, i0:i1]
        mark = _to_cost(self.config.mark_threshold)
        clear = _to_cost(self.config.clear_threshold)
        known = s != NO_INFORMATION
        cur = np.full(s.shape, -1, dtype=np.int16)
        cur[known & (s > mark)] = LETHAL_OBSTACLE
        cur[known & (s < clear)] = FREE_SPACE
        write = (cur >= 0) & ((m == NO_INFORMATION) | (m.astype(np.int16) < cur))
        m[write] = cur[write].astype(np.uint8)


def _to_cost(p: float) -> int:
    """Upstream ``to_cost``: probability -> cost, truncated (``p · 254``)."""
    return int(p * LETHAL_OBSTACLE)


def _to_cost_array(p: npt.NDArray[np.float64]) -> npt.NDArray[np.uint8]:
    return np.clip(np.trunc(p * LETHAL_OBSTACLE), 0, 255).astype(np.uint8)


def sensor_model(r: float, phi: npt.ArrayLike, theta: npt.ArrayLike, half_fov: float,
                 phi_v: float = 1.2, resolution: float = 0.05) -> npt.NDArray[np.float64]:
    """Nav2 ``RangeSensorLayer::sensor_model``: occupancy probability of a cell at distance
    ``phi`` and bearing ``theta`` (rad, from the cone axis) for a reading ``r`` (m)."""
    phi = np.asarray(phi, dtype=np.float64)
    theta = np.asarray(theta, dtype=np.float64)
    gamma = np.where(np.abs(theta) > half_fov, 0.0,
                     1.0 - (theta / half_fov) ** 2 if half_fov > 0 else 0.0)
    lbda = (1.0 - (1.0 + np.tanh(2.0 * (phi - phi_v))) / 2.0) * gamma
    dr = resolution * r
    out = np.full(phi.shape, 0.5)
    if dr <= 0.0:  # upstream divides by zero here; keep the prior instead
        near = (phi >= 0.0) & (phi < r)
        out[near] = (1.0 - lbda[near]) * 0.5
        return out
    near = (phi >= 0.0) & (phi < r - 2.0 * dr)
    rise = ~near & (phi < r - dr)
    band = ~near & ~rise & (phi < r + dr)
    out[near] = (1.0 - lbda[near]) * 0.5
    out[rise] = (lbda[rise] * 0.5 * ((phi[rise] - (r - 2.0 * dr)) / dr) ** 2
                 + (1.0 - lbda[rise]) * 0.5)
    j = (r - phi[band]) / dr
    out[band] = lbda[band] * ((1.0 - 0.5 * j ** 2) - 0.5) + 0.5
    return out


# --- inflation layer ---------------------------------------------------------------------
@dataclass(frozen=True)
class InflationLayerConfig:
    """``inflation_layer`` parameters (Jazzy code defaults)."""

    enabled: bool = True
    inflation_radius: float = 0.55
    cost_scaling_factor: float = 10.0
    inflate_unknown: bool = False
    inflate_around_unknown: bool = False

    def validate(self, server: str = "inflation_layer") -> None:
        require(self.inflation_radius >= 0.0, server, "inflation_radius", self.inflation_radius,
                "must be >= 0")
        require(self.cost_scaling_factor >= 0.0, server, "cost_scaling_factor",
                self.cost_scaling_factor, "must be >= 0")


def inflation_cost(distance_cells: float, resolution: float, inscribed_radius: float,
                   cost_scaling_factor: float) -> int:
    """``InflationLayer::computeCost``: cost at a distance (cells) from the nearest obstacle."""
    if distance_cells == 0:
        return LETHAL_OBSTACLE
    d = distance_cells * resolution
    if d <= inscribed_radius:
        return INSCRIBED_INFLATED_OBSTACLE
    factor = math.exp(-1.0 * cost_scaling_factor * (d - inscribed_radius))
    return int((INSCRIBED_INFLATED_OBSTACLE - 1) * factor)


class InflationLayer(Layer):
    """``nav2_costmap_2d::InflationLayer`` (exponential decay, cached kernel, numba)."""

    def __init__(self, name: str = "inflation_layer", config: InflationLayerConfig | None = None) -> None:
        super().__init__(name)
        self.config = config or InflationLayerConfig()
        self.config.validate(name)
        self.enabled = self.config.enabled
        self._need_reinflation = True
        self._last_bounds: Bounds = empty_bounds()
        self._kernel: npt.NDArray[np.uint8] = np.zeros((1, 1), dtype=np.uint8)
        self._kernel_key: tuple[Any, ...] = ()
        self.cell_inflation_radius = 0

    @property
    def inscribed_radius(self) -> float:
        return self.layered.inscribed_radius

    def match_size(self) -> None:
        self._rebuild_kernel()
        self._need_reinflation = True

    def on_footprint_changed(self) -> None:
        self._rebuild_kernel()
        self._need_reinflation = True

    def reset(self) -> None:
        self._need_reinflation = True

    def _rebuild_kernel(self) -> None:
        res = self.layered.master.resolution
        key = (res, self.config.inflation_radius, self.config.cost_scaling_factor,
               self.inscribed_radius)
        if key == self._kernel_key:
            return
        self._kernel_key = key
        r = max(0, math.ceil(self.config.inflation_radius / res))
        self.cell_inflation_radius = r
        k = np.zeros((2 * r + 1, 2 * r + 1), dtype=np.uint8)
        for dy in range(-r, r + 1):
            for dx in range(-r, r + 1):
                d = math.hypot(dx, dy)
                if d <= r:
                    k[dy + r, dx + r] = inflation_cost(
                        d, res, self.inscribed_radius, self.config.cost_scaling_factor
                    )
        self._kernel = k

    def update_bounds(self, robot_x: float, robot_y: float, robot_yaw: float, bounds: Bounds) -> None:
        if self._need_reinflation:
            self._last_bounds = list(bounds)
            bounds[:] = [-math.inf, -math.inf, math.inf, math.inf]
            self._need_reinflation = False
            return
        tmp = list(bounds)
        merge_bounds(bounds, self._last_bounds)
        self._last_bounds = tmp
        r = self.config.inflation_radius
        bounds[0] -= r
        bounds[1] -= r
        bounds[2] += r
        bounds[3] += r

    def update_costs(self, master: Costmap2D, i0: int, j0: int, i1: int, j1: int) -> None:
        if not self.enabled or self.cell_inflation_radius == 0:
            return
        self._rebuild_kernel()
        _kernels.inflate(
            master.data, self._kernel, self.cell_inflation_radius, i0, j0, i1, j1,
            self.config.inflate_unknown, self.config.inflate_around_unknown,
        )


__all__ = [
    "Bounds",
    "CostmapLayer",
    "InflationLayer",
    "InflationLayerConfig",
    "Layer",
    "Observation",
    "ObservationSourceConfig",
    "ObstacleLayer",
    "ObstacleLayerConfig",
    "RangeLayer",
    "RangeLayerConfig",
    "RangeReading",
    "StaticLayer",
    "StaticLayerConfig",
    "cloud_observation",
    "inflation_cost",
    "interpret_static_value",
    "scan_observation",
    "scan_points",
    "sensor_model",
    "update_with_max",
    "update_with_overwrite",
    "update_with_true_overwrite",
]
