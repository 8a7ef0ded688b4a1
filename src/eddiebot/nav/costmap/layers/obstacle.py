"""The obstacle layer: observations (laser scans, point clouds) marked and ray-traced clear, as
Nav2's ``ObstacleLayer``."""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from eddiebot.nav.cost_values import (
    FREE_SPACE,
)
from eddiebot.nav.costmap import _kernels
from eddiebot.nav.costmap.costmap2d import Costmap2D
from eddiebot.nav.costmap.footprint import transform_footprint
from eddiebot.nav.costmap.layers.base import (
    Bounds,
    CostmapLayer,
    merge_bounds,
    touch,
    update_with_max,
    update_with_max_without_unknown_overwrite,
    update_with_overwrite,
)
from eddiebot.nav.params import require


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
