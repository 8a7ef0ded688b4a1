"""Nav2 collision monitor core (``nav2_collision_monitor``, Jazzy): stop / slowdown / limit /
approach zones over obstacle points from scan, point-cloud, range and polygon sources, and
(Nav2 Kilted's ``CostmapSource``) the obstacle cells of a costmap.

Zones are ``polygon`` (static ``points``, or a shape received on ``polygon_sub_topic`` / the
footprint topic for approach), ``circle`` (``radius``) and ``velocity_polygon`` (sub-polygons
chosen by the commanded velocity: ``linear_min/max``, ``theta_min/max`` and, with
``holonomic``, ``direction_start_angle/direction_end_angle``). Points are 2-D in the robot base
frame (m). :class:`CollisionMonitor.process` takes the incoming command and the current points
of every source (``None`` = no valid recent data) and returns what to publish, following
upstream's order of operations.
"""

from __future__ import annotations

import ast
import math
from dataclasses import dataclass, field
from enum import IntEnum
from typing import Any

import numpy as np
import numpy.typing as npt

from eddiebot.nav.cost_values import NO_INFORMATION
from eddiebot.nav.errors import ParameterError
from eddiebot.nav.params import from_params, require
from eddiebot.nav.types import Twist2D

Points = npt.NDArray[np.float64]


class ActionType(IntEnum):
    """``nav2_msgs/CollisionMonitorState`` action types."""

    DO_NOTHING = 0
    STOP = 1
    SLOWDOWN = 2
    APPROACH = 3
    LIMIT = 4


_ACTIONS = {"stop": ActionType.STOP, "slowdown": ActionType.SLOWDOWN,
            "approach": ActionType.APPROACH, "limit": ActionType.LIMIT,
            "none": ActionType.DO_NOTHING}


#: ``type`` values of a zone
ZONE_TYPES = ("polygon", "circle", "velocity_polygon")
#: ``type`` values of an observation source
SOURCE_TYPES = ("scan", "pointcloud", "range", "polygon", "costmap")
#: polygon name reported when an enabled source has no valid recent data
INVALID_SOURCE = "invalid source"


@dataclass(frozen=True)
class CollisionMonitorConfig:
    """Node parameters (Jazzy code defaults; ``use_realtime_priority`` is accepted and
    ignored: there is no real-time scheduling here)."""

    cmd_vel_in_topic: str = "cmd_vel_smoothed"
    cmd_vel_out_topic: str = "cmd_vel"
    state_topic: str = ""
    base_frame_id: str = "base_footprint"
    odom_frame_id: str = "odom"
    transform_tolerance: float = 0.1
    source_timeout: float = 2.0
    base_shift_correction: bool = True
    stop_pub_timeout: float = 1.0
    polygons: tuple[str, ...] = ()
    observation_sources: tuple[str, ...] = ()
    use_realtime_priority: bool = False

    def validate(self, server: str = "collision_monitor") -> None:
        require(len(self.polygons) > 0, server, "polygons", list(self.polygons),
                "needs at least one polygon")
        require(len(self.observation_sources) > 0, server, "observation_sources",
                list(self.observation_sources), "needs at least one source")


@dataclass(frozen=True)
class PolygonConfig:
    """Per-polygon parameters (Jazzy code defaults). ``points`` as Nav2's string
    ``"[[x, y], ...]"``; ``max_points`` (deprecated) N means ``min_points`` N + 1.
    ``velocity_polygons`` names the sub-polygons of a ``velocity_polygon`` (each a
    :class:`VelocitySubPolygon` under ``<polygon>.<name>``)."""

    type: str = "polygon"
    action_type: str = ""
    enabled: bool = True
    points: str = ""
    radius: float = 0.0
    min_points: int = 4
    max_points: int = -1
    slowdown_ratio: float = 0.5
    linear_limit: float = 0.5
    angular_limit: float = 0.5
    time_before_collision: float = 2.0
    simulation_time_step: float = 0.1
    visualize: bool = False
    polygon_pub_topic: str = ""
    footprint_topic: str = "local_costmap/published_footprint"
    polygon_sub_topic: str = ""
    sources_names: tuple[str, ...] = ()
    velocity_polygons: tuple[str, ...] = ()
    holonomic: bool = False

    def validate(self, server: str = "collision_monitor") -> None:
        require(self.type in ZONE_TYPES, server, "type", self.type,
                f"must be one of {list(ZONE_TYPES)}")
        require(self.action_type in _ACTIONS, server, "action_type", self.action_type,
                f"must be one of {sorted(_ACTIONS)}")
        require(0.0 <= self.slowdown_ratio <= 1.0, server, "slowdown_ratio", self.slowdown_ratio,
                "must be in [0, 1]")
        require(self.simulation_time_step > 0.0, server, "simulation_time_step",
                self.simulation_time_step, "must be > 0")


@dataclass(frozen=True)
class VelocitySubPolygon:
    """One sub-polygon of a ``velocity_polygon``: used while the command is in its ranges."""

    name: str
    points: tuple[tuple[float, float], ...]
    linear_min: float
    linear_max: float
    theta_min: float
    theta_max: float
    direction_end_angle: float = math.pi
    direction_start_angle: float = -math.pi

    def in_range(self, cmd: Twist2D, holonomic: bool) -> bool:
        """``VelocityPolygon::isInRange`` (Jazzy): ``vx`` in [linear_min, linear_max] and
        ``wz`` in [theta_min, theta_max]; holonomic robots also need the direction
        ``atan2(vy, vx)`` within [start, end] (a wrapped range when start > end)."""
        ok = (self.linear_min <= cmd.vx <= self.linear_max
              and self.theta_min <= cmd.wz <= self.theta_max)
        if holonomic:
            direction = math.atan2(cmd.vy, cmd.vx)
            if self.direction_start_angle <= self.direction_end_angle:
                ok = ok and self.direction_start_angle <= direction <= self.direction_end_angle
            else:
                ok = ok and (direction >= self.direction_start_angle
                             or direction <= self.direction_end_angle)
        return ok


def _sub_polygons(zone: str, config: PolygonConfig, params: dict[str, Any]) -> list[VelocitySubPolygon]:
    server = f"collision_monitor.{zone}"
    require(len(config.velocity_polygons) > 0, server, "velocity_polygons",
            list(config.velocity_polygons), "a velocity_polygon needs at least one sub-polygon")
    out = []
    for name in config.velocity_polygons:
        sub = params.get(name)
        if not isinstance(sub, dict):
            raise ParameterError(server, f"{name}.points", None, "missing sub-polygon parameters")
        for key in ("points", "linear_min", "linear_max", "theta_min", "theta_max"):
            if key not in sub:
                raise ParameterError(server, f"{name}.{key}", None, "missing (no default upstream)")
        pts = sub["points"]
        poly = _parse_points(str(pts) if isinstance(pts, list) else pts, server)
        try:
            nums = {k: float(sub[k]) for k in ("linear_min", "linear_max", "theta_min", "theta_max")}
            end = float(sub.get("direction_end_angle", math.pi))
            start = float(sub.get("direction_start_angle", -math.pi))
        except (TypeError, ValueError) as exc:
            raise ParameterError(server, name, sub, f"not a number: {exc}") from exc
        out.append(VelocitySubPolygon(name, tuple((float(x), float(y)) for x, y in poly),
                                      direction_end_angle=end, direction_start_angle=start, **nums))
    return out


def _parse_points(text: str, server: str) -> Points:
    try:
        arr = np.asarray(ast.literal_eval(text), dtype=np.float64)
    except (ValueError, SyntaxError) as exc:
        raise ParameterError(server, "points", text, f"not a list of points: {exc}") from exc
    if arr.ndim != 2 or arr.shape[1] != 2 or arr.shape[0] < 3:
        raise ParameterError(server, "points", text, "needs at least 3 [x, y] points")
    return arr


def points_in_polygon(poly: Points, pts: Points) -> npt.NDArray[np.bool_]:
    """Even-odd ray-crossing test as upstream's ``Polygon::isPointInside``."""
    inside = np.zeros(pts.shape[0], dtype=bool)
    n = poly.shape[0]
    j = n - 1
    x = pts[:, 0]
    y = pts[:, 1]
    for i in range(n):
        xi, yi = poly[i]
        xj, yj = poly[j]
        crosses = (yi > y) != (yj > y)
        with np.errstate(divide="ignore", invalid="ignore"):
            xc = (xj - xi) * (y - yi) / (yj - yi) + xi
        inside ^= crosses & (x < xc)
        j = i
    return inside


class Zone:
    """One polygon, circle or velocity polygon with its action.

    A polygon without ``points`` takes its shape from ``polygon_sub_topic`` (or, for an
    approach zone, from the footprint topic): :attr:`dynamic_topic` names it, the node feeds
    :meth:`set_polygon`, and until then the zone is skipped (``isShapeSet``)."""

    def __init__(self, name: str, config: PolygonConfig, footprint: Points | None = None,
                 sub_polygons: list[VelocitySubPolygon] | None = None) -> None:
        self.name = name
        self.config = config
        config.validate(f"collision_monitor.{name}")
        self.action = _ACTIONS[config.action_type]
        self.min_points = config.max_points + 1 if config.max_points >= 0 else config.min_points
        self.poly: Points | None = None
        self.dynamic_topic = ""
        self.sub_polygons = sub_polygons or []
        self.active_sub_polygon = ""
        if config.type == "polygon":
            if config.points:
                self.poly = _parse_points(config.points, f"collision_monitor.{name}")
            elif footprint is not None:
                self.poly = np.asarray(footprint, dtype=np.float64)
            elif config.polygon_sub_topic:
                self.dynamic_topic = config.polygon_sub_topic
            elif self.action == ActionType.APPROACH and config.footprint_topic:
                self.dynamic_topic = config.footprint_topic
            else:
                raise ParameterError(f"collision_monitor.{name}", "points", config.points,
                                     "polygon needs points or polygon_sub_topic (or a "
                                     "footprint topic for approach)")
        elif config.type == "velocity_polygon":
            if not self.sub_polygons:
                raise ParameterError(f"collision_monitor.{name}", "velocity_polygons",
                                     list(config.velocity_polygons), "no sub-polygons")
        elif config.radius <= 0.0:
            raise ParameterError(f"collision_monitor.{name}", "radius", config.radius,
                                 "circle needs radius > 0")

    @property
    def shape_set(self) -> bool:
        """``isShapeSet``: circles always; polygons once they have >= 3 points."""
        if self.config.type == "circle":
            return True
        return self.poly is not None and self.poly.shape[0] >= 3

    def set_polygon(self, points: npt.ArrayLike) -> None:
        """New shape (base frame) from the polygon or footprint topic."""
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        self.poly = pts if pts.shape[0] >= 3 else None

    def update_polygon(self, cmd: Twist2D) -> None:
        """``updatePolygon``: a velocity polygon takes the first sub-polygon whose ranges hold
        ``cmd``; when none does, it keeps the previous one (none yet: no shape)."""
        for sub in self.sub_polygons:
            if sub.in_range(cmd, self.config.holonomic):
                if sub.name != self.active_sub_polygon:
                    self.poly = np.asarray(sub.points, dtype=np.float64)
                    self.active_sub_polygon = sub.name
                return

    def count_inside(self, pts: Points) -> int:
        if pts.shape[0] == 0:
            return 0
        if self.config.type == "circle":
            r = self.config.radius
            return int(np.count_nonzero(pts[:, 0] ** 2 + pts[:, 1] ** 2 < r * r))
        if self.poly is None:
            return 0
        return int(np.count_nonzero(points_in_polygon(self.poly, pts)))

    def collision_time(self, cmd: Twist2D, pts: Points) -> float:
        """``getCollisionTime``: seconds until ``min_points`` enter the zone moving with
        ``cmd``; 0 if already inside; -1 if none within ``time_before_collision``."""
        if self.count_inside(pts) >= self.min_points:
            return 0.0
        dt = self.config.simulation_time_step
        x = y = th = 0.0
        vx, vy = cmd.vx, cmd.vy
        t = 0.0
        while t <= self.config.time_before_collision:
            x += vx * dt
            y += vy * dt
            th += cmd.wz * dt
            c, s = math.cos(cmd.wz * dt), math.sin(cmd.wz * dt)
            vx, vy = vx * c - vy * s, vx * s + vy * c
            ct, st = math.cos(th), math.sin(th)
            dx = pts[:, 0] - x
            dy = pts[:, 1] - y
            local = np.stack([ct * dx + st * dy, -st * dx + ct * dy], axis=-1)
            if self.count_inside(local) >= self.min_points:
                return t
            t += dt
        return -1.0


@dataclass
class MonitorOutput:
    """Result of one :meth:`CollisionMonitor.process` call."""

    publish: Twist2D | None
    action: ActionType
    polygon_name: str
    state_changed: bool
    """True when the active polygon changed (publish CollisionMonitorState)."""


@dataclass
class _State:
    last_name: str = ""
    zero_since_ns: int | None = None
    released: bool = True
    extra: dict[str, Any] = field(default_factory=dict)


class CollisionMonitor:
    def __init__(self, config: CollisionMonitorConfig, zones: list[Zone]) -> None:
        config.validate()
        self.config = config
        self.zones = zones
        for z in zones:
            for s in z.config.sources_names:
                if s not in config.observation_sources:
                    raise ParameterError(f"collision_monitor.{z.name}", "sources_names",
                                         list(z.config.sources_names), f"unknown source {s!r}")
        self._state = _State()

    def _points_for(self, zone: Zone, sources: dict[str, Points | None]) -> Points:
        names = zone.config.sources_names or self.config.observation_sources
        arrays = [sources[n] for n in names if sources.get(n) is not None]
        if not arrays:
            return np.zeros((0, 2))
        return np.concatenate([np.asarray(a, dtype=np.float64).reshape(-1, 2) for a in arrays])

    def zone(self, name: str) -> Zone:
        for z in self.zones:
            if z.name == name:
                return z
        raise KeyError(name)

    def _stop_zone_hit(self, cmd: Twist2D, sources: dict[str, Points | None]) -> bool:
        for zone in self.zones:
            if not zone.config.enabled or zone.action != ActionType.STOP:
                continue
            zone.update_polygon(cmd)
            if zone.shape_set and zone.count_inside(self._points_for(zone, sources)) >= zone.min_points:
                return True
        return False

    def process(self, cmd: Twist2D, sources: dict[str, Points | None], now_ns: int,
                stop_reason: str = "") -> MonitorOutput:
        """One incoming command. ``stop_reason`` (not upstream): stop for a reason outside the
        zones (lost localization), reported as the polygon name like ``invalid source``. Only
        translation stops then: a turn in place sweeps no new ground for a round base and is
        how a particle filter that updates on rotation (``update_min_a``) recovers, so the
        recovery spin still gets through -- unless a stop zone or an invalid source also
        holds, which stop everything."""
        action = ActionType.DO_NOTHING
        name = ""
        request = cmd
        invalid = [n for n in self.config.observation_sources
                   if n in sources and sources[n] is None]
        if stop_reason:
            action, name, request = ActionType.STOP, stop_reason, Twist2D(0.0, 0.0, cmd.wz)
            if invalid or self._stop_zone_hit(request, sources):
                request = Twist2D()
        elif invalid:
            action, name, request = ActionType.STOP, INVALID_SOURCE, Twist2D()
        else:
            for zone in self.zones:
                if not zone.config.enabled:
                    continue
                zone.update_polygon(cmd)
                if not zone.shape_set:
                    continue
                pts = self._points_for(zone, sources)
                if zone.action == ActionType.STOP:
                    if zone.count_inside(pts) >= zone.min_points:
                        action, name, request = ActionType.STOP, zone.name, Twist2D()
                        break
                    continue
                candidate: Twist2D | None = None
                if zone.action == ActionType.SLOWDOWN:
                    if zone.count_inside(pts) >= zone.min_points:
                        r = zone.config.slowdown_ratio
                        candidate = Twist2D(cmd.vx * r, cmd.vy * r, cmd.wz * r)
                elif zone.action == ActionType.LIMIT:
                    if zone.count_inside(pts) >= zone.min_points:
                        ratio = 1.0
                        lin = math.hypot(cmd.vx, cmd.vy)
                        if lin != 0.0:
                            ratio = min(ratio, zone.config.linear_limit / lin)
                        if cmd.wz != 0.0:
                            ratio = min(ratio, zone.config.angular_limit / abs(cmd.wz))
                        ratio = min(max(ratio, 0.0), 1.0)
                        candidate = Twist2D(cmd.vx * ratio, cmd.vy * ratio, cmd.wz * ratio)
                elif zone.action == ActionType.APPROACH:
                    t = zone.collision_time(cmd, pts)
                    if t >= 0.0:
                        r = t / zone.config.time_before_collision
                        candidate = Twist2D(cmd.vx * r, cmd.vy * r, cmd.wz * r)
                if candidate is not None and (
                    candidate.vx ** 2 + candidate.vy ** 2 + candidate.wz ** 2
                    < request.vx ** 2 + request.vy ** 2 + request.wz ** 2
                ):
                    request, action, name = candidate, zone.action, zone.name
        changed = name != self._state.last_name
        self._state.last_name = name
        publish: Twist2D | None = request
        if request.is_zero():
            if self._state.zero_since_ns is None:
                self._state.zero_since_ns = now_ns
            elif (now_ns - self._state.zero_since_ns) * 1e-9 > self.config.stop_pub_timeout:
                publish = None
        else:
            self._state.zero_since_ns = None
        return MonitorOutput(publish, action, name, changed)


def build_collision_monitor(params: dict[str, Any], footprint: Points | None = None,
                            server: str = "collision_monitor") -> CollisionMonitor:
    """From the node's ``ros__parameters`` (polygons and sources as nested dicts)."""
    flat = {k: v for k, v in params.items() if not isinstance(v, dict)}
    cfg = from_params(CollisionMonitorConfig, flat, server=server)
    zones = []
    for name in cfg.polygons:
        sub = dict(params.get(name, {}) or {})
        if isinstance(sub.get("points"), list):
            sub["points"] = str(sub["points"])
        pcfg = from_params(PolygonConfig, {k: v for k, v in sub.items() if not isinstance(v, dict)},
                           server=f"{server}.{name}", validate=lambda c, s: None)
        subs = _sub_polygons(name, pcfg, sub) if pcfg.type == "velocity_polygon" else None
        zones.append(Zone(name, pcfg, footprint, subs))
    return CollisionMonitor(cfg, zones)


# --- sources -------------------------------------------------------------------------------
def scan_source_points(ranges: npt.ArrayLike, angle_min: float, angle_increment: float,
                       range_min: float, range_max: float,
                       sensor_pose: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> Points:
    """LaserScan -> base-frame points (``Scan::getData``: finite ranges in [min, max])."""
    r = np.asarray(ranges, dtype=np.float64)
    a = angle_min + angle_increment * np.arange(r.shape[0])
    ok = np.isfinite(r) & (r >= range_min) & (r <= range_max)
    sx, sy, syaw = sensor_pose
    xs = r[ok] * np.cos(a[ok] + syaw) + sx
    ys = r[ok] * np.sin(a[ok] + syaw) + sy
    return np.stack([xs, ys], axis=-1)


def cloud_source_points(points_base: npt.ArrayLike, min_height: float = 0.05,
                        max_height: float = 0.5) -> Points:
    """PointCloud2 (already in the base frame, N x 3) -> points with z in [min_height, max_height]."""
    p = np.asarray(points_base, dtype=np.float64).reshape(-1, 3)
    ok = np.all(np.isfinite(p), axis=1) & (p[:, 2] >= min_height) & (p[:, 2] <= max_height)
    return p[ok, :2].copy()


def range_source_points(range_m: float, min_range: float, max_range: float,
                        field_of_view: float, sensor_pose: tuple[float, float, float],
                        obstacles_angle: float = math.pi / 180.0) -> Points:
    """Range -> points on the arc at the measured distance, every ``obstacles_angle``
    across the field of view (``Range::getData``); nothing outside [min_range, max_range]
    (upstream's test) or for a non-finite range (REP 117's "nothing detected")."""
    if not math.isfinite(range_m) or range_m < min_range or range_m > max_range:
        return np.zeros((0, 2))
    half = field_of_view / 2.0
    angles = np.arange(-half, half, obstacles_angle)
    angles = np.append(angles, half)
    sx, sy, syaw = sensor_pose
    xs = sx + range_m * np.cos(angles + syaw)
    ys = sy + range_m * np.sin(angles + syaw)
    return np.stack([xs, ys], axis=-1)


def polygon_source_points(polygons: list[npt.ArrayLike], sampling_distance: float = 0.1) -> Points:
    """PolygonInstanceStamped shapes (base frame) -> points along their closed outlines, each
    edge split into ``ceil(length / sampling_distance)`` (>= 1) equal steps, both ends
    included (``PolygonSource::convertPolygonStampedToPoints``)."""
    out: list[Points] = []
    for poly in polygons:
        p = np.asarray(poly, dtype=np.float64).reshape(-1, 2)
        if p.shape[0] == 0:
            continue
        nxt = np.roll(p, -1, axis=0)
        for a, b in zip(p, nxt):
            n = max(math.ceil(math.hypot(*(b - a)) / sampling_distance), 1)
            t = np.arange(n + 1)[:, None] / n
            out.append(a + t * (b - a))
    return np.concatenate(out) if out else np.zeros((0, 2))


def costmap_source_points(data: npt.ArrayLike, size_x: int, size_y: int, resolution: float,
                          origin: tuple[float, float], cost_threshold: int = 253,
                          treat_unknown_as_obstacle: bool = True,
                          frame_pose: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> Points:
    """nav2_msgs/Costmap -> base-frame points at the centres of its obstacle cells
    (``CostmapSource::getSourceData``, Nav2 Kilted+): cost in [``cost_threshold``, 255), or
    255 (no information) with ``treat_unknown_as_obstacle``. ``frame_pose`` is the costmap
    frame in the base frame."""
    d = np.asarray(data, dtype=np.uint8).reshape(size_y, size_x)
    hit = (d >= cost_threshold) & (d < NO_INFORMATION)
    if treat_unknown_as_obstacle:
        hit |= d == NO_INFORMATION
    rows, cols = np.nonzero(hit)
    wx = origin[0] + (cols + 0.5) * resolution
    wy = origin[1] + (rows + 0.5) * resolution
    fx, fy, fyaw = frame_pose
    c, s = math.cos(fyaw), math.sin(fyaw)
    return np.stack([fx + c * wx - s * wy, fy + s * wx + c * wy], axis=-1)


__all__ = [
    "INVALID_SOURCE",
    "SOURCE_TYPES",
    "ZONE_TYPES",
    "ActionType",
    "CollisionMonitor",
    "CollisionMonitorConfig",
    "MonitorOutput",
    "PolygonConfig",
    "VelocitySubPolygon",
    "Zone",
    "build_collision_monitor",
    "cloud_source_points",
    "costmap_source_points",
    "points_in_polygon",
    "polygon_source_points",
    "range_source_points",
    "scan_source_points",
]
