"""Layered costmaps (``Costmap2DROS`` + ``LayeredCostmap``), global or rolling.

:func:`build_costmap` turns a costmap node's ``ros__parameters`` (Nav2 YAML layout: ``plugins``
and ``filters`` list names, each name's dict has ``plugin:``) into a :class:`LayeredCostmap`.
:meth:`LayeredCostmap.update_map` runs one update cycle for a robot pose; the node calls it at
``update_frequency`` and publishes :func:`to_occupancy_grid`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import Any

import numpy as np
import numpy.typing as npt

from eddiebot.maps import OccupancyMap
from eddiebot.nav.cost_values import FREE_SPACE, NO_INFORMATION
from eddiebot.nav.costmap.costmap2d import Costmap2D
from eddiebot.nav.costmap.filters import FILTER_PLUGINS, SpeedFilter
from eddiebot.nav.costmap.footprint import (
    inscribed_and_circumscribed_radius,
    make_footprint_from_radius,
    pad_footprint,
    parse_footprint,
    transform_footprint,
)
from eddiebot.nav.costmap.layers import (
    Bounds,
    InflationLayer,
    InflationLayerConfig,
    Layer,
    ObservationSourceConfig,
    ObstacleLayer,
    ObstacleLayerConfig,
    RangeLayer,
    RangeLayerConfig,
    StaticLayer,
    StaticLayerConfig,
    empty_bounds,
)
from eddiebot.nav.errors import ParameterError
from eddiebot.nav.params import from_params, require
from eddiebot.nav.plugins import PluginContext, PluginFactory, registry


@dataclass(frozen=True)
class CostmapConfig:
    """``Costmap2DROS`` parameters with Jazzy code defaults (sizes in m, frequencies in Hz)."""

    always_send_full_costmap: bool = False
    footprint_padding: float = 0.01
    footprint: str = "[]"
    global_frame: str = "map"
    height: int = 5
    width: int = 5
    lethal_cost_threshold: int = 100
    map_topic: str = "map"
    origin_x: float = 0.0
    origin_y: float = 0.0
    publish_frequency: float = 1.0
    resolution: float = 0.1
    robot_base_frame: str = "base_link"
    robot_radius: float = 0.1
    rolling_window: bool = False
    track_unknown_space: bool = False
    transform_tolerance: float = 0.3
    trinary_costmap: bool = True
    unknown_cost_value: int = 255
    update_frequency: float = 5.0
    use_maximum: bool = False
    plugins: tuple[str, ...] = ("static_layer", "obstacle_layer", "inflation_layer")
    filters: tuple[str, ...] = ()

    def validate(self, server: str = "costmap") -> None:
        require(self.resolution > 0.0, server, "resolution", self.resolution, "must be > 0")
        require(self.width > 0, server, "width", self.width, "must be > 0")
        require(self.height > 0, server, "height", self.height, "must be > 0")
        require(self.robot_radius >= 0.0, server, "robot_radius", self.robot_radius, "must be >= 0")
        require(self.update_frequency > 0.0, server, "update_frequency", self.update_frequency,
                "must be > 0")
        require(0 <= self.lethal_cost_threshold <= 255, server, "lethal_cost_threshold",
                self.lethal_cost_threshold, "must be in 0..255")
        parse_footprint(self.footprint, server)


class LayeredCostmap:
    """Master grid plus ordered layers and filters (``nav2_costmap_2d::LayeredCostmap``).

    The footprint is ``footprint`` if given, else the 16-gon of ``robot_radius``, padded by
    ``footprint_padding`` in both cases; the inscribed and circumscribed radii (used by the
    inflation layer and the controllers) are computed from that polygon, as upstream does.
    """

    def __init__(self, config: CostmapConfig | None = None, name: str = "costmap") -> None:
        self.config = config or CostmapConfig()
        self.name = name
        self.config.validate(name)
        cfg = self.config
        self.rolling_window = cfg.rolling_window
        self.track_unknown_space = cfg.track_unknown_space
        default = NO_INFORMATION if cfg.track_unknown_space else FREE_SPACE
        self.master = Costmap2D(
            int(cfg.width / cfg.resolution), int(cfg.height / cfg.resolution), cfg.resolution,
            cfg.origin_x, cfg.origin_y, default,
        )
        self.layers: list[Layer] = []
        self.filters: list[Layer] = []
        poly = parse_footprint(cfg.footprint, name)
        self.use_radius = poly is None
        unpadded = make_footprint_from_radius(cfg.robot_radius) if poly is None else poly
        self.footprint = pad_footprint(unpadded, cfg.footprint_padding)
        self.inscribed_radius, self.circumscribed_radius = inscribed_and_circumscribed_radius(
            self.footprint
        )
        self.bounds: Bounds = empty_bounds()
        self.window = (0, 0, 0, 0)
        self.robot_pose = np.zeros(3)
        self._initialized_origin = False

    # --- composition ---------------------------------------------------------------------
    def add_layer(self, layer: Layer) -> Layer:
        self.layers.append(layer)
        layer.initialize(self)
        return layer

    def add_filter(self, layer: Layer) -> Layer:
        self.filters.append(layer)
        layer.initialize(self)
        return layer

    def layer(self, name: str) -> Layer:
        for lay in (*self.layers, *self.filters):
            if lay.name == name:
                return lay
        raise KeyError(name)

    def set_footprint(self, footprint: npt.ArrayLike) -> None:
        self.footprint = np.asarray(footprint, dtype=np.float64).reshape(-1, 2)
        self.inscribed_radius, self.circumscribed_radius = inscribed_and_circumscribed_radius(
            self.footprint
        )
        for lay in (*self.layers, *self.filters):
            lay.on_footprint_changed()

    def resize_map(self, size_x: int, size_y: int, resolution: float, origin_x: float,
                   origin_y: float) -> None:
        self.master.resize(size_x, size_y, resolution, origin_x, origin_y)
        for lay in (*self.layers, *self.filters):
            lay.match_size()

    def set_static_map(self, occupancy_map: OccupancyMap) -> None:
        """Hand a map to every static layer (what the ``/map`` subscription does)."""
        for lay in self.layers:
            if isinstance(lay, StaticLayer):
                lay.set_map(occupancy_map)

    # --- update cycle --------------------------------------------------------------------
    def update_map(self, robot_pose: npt.ArrayLike) -> tuple[int, int, int, int]:
        """One update cycle at robot pose (x, y, yaw) in the global frame.

        Returns the updated cell window (x0, y0, xn, yn), half-open.
        """
        rx, ry, ryaw = (float(v) for v in np.asarray(robot_pose, dtype=np.float64)[:3])
        self.robot_pose = np.array([rx, ry, ryaw])
        m = self.master
        if self.rolling_window:
            new_ox = rx - m.size_in_meters_x / 2.0
            new_oy = ry - m.size_in_meters_y / 2.0
            if not self._initialized_origin:
                m.origin_x, m.origin_y = new_ox, new_oy
                for lay in (*self.layers, *self.filters):
                    lay.match_size()
                self._initialized_origin = True
            else:
                m.update_origin(new_ox, new_oy)
                for lay in (*self.layers, *self.filters):
                    lay.update_origin(m.origin_x, m.origin_y)
        bounds = empty_bounds()
        for lay in self.layers:
            if lay.enabled:
                lay.update_bounds(rx, ry, ryaw, bounds)
        for lay in self.filters:
            if lay.enabled:
                lay.update_bounds(rx, ry, ryaw, bounds)
        self.bounds = bounds
        if bounds[0] > bounds[2] or bounds[1] > bounds[3]:
            self.window = (0, 0, 0, 0)
            return self.window
        big = 1e12
        b = [min(max(v, -big), big) for v in bounds]
        x0, y0 = m.world_to_map_enforce_bounds(b[0], b[1])
        xn, yn = m.world_to_map_enforce_bounds(b[2], b[3])
        x0, y0 = max(0, x0), max(0, y0)
        xn, yn = min(m.size_x, xn + 1), min(m.size_y, yn + 1)
        if xn < x0 or yn < y0:
            self.window = (0, 0, 0, 0)
            return self.window
        m.reset_map(x0, y0, xn, yn)
        for lay in self.layers:
            if lay.enabled:
                lay.update_costs(m, x0, y0, xn, yn)
        for lay in self.filters:
            if lay.enabled:
                lay.update_costs(m, x0, y0, xn, yn)
        self.window = (x0, y0, xn, yn)
        return self.window

    # --- clearing (nav2_costmap_2d ClearCostmapService) ---------------------------------
    def clear_entirely(self) -> None:
        """``clear_entirely_<costmap>``: reset every layer and the master grid."""
        self.master.reset_all()
        for lay in (*self.layers, *self.filters):
            lay.reset()

    def _clear_region(self, robot_pose: npt.ArrayLike, reset_distance: float, invert: bool) -> None:
        x, y = (float(v) for v in np.asarray(robot_pose, dtype=np.float64)[:2])
        h = reset_distance / 2.0
        for lay in self.layers:
            if lay.clearable:
                cm = getattr(lay, "costmap", self.master)
                i0, j0 = cm.world_to_map_enforce_bounds(x - h, y - h)
                i1, j1 = cm.world_to_map_enforce_bounds(x + h, y + h)
                lay.clear_area(i0, j0, i1, j1, invert)

    def clear_around_robot(self, robot_pose: npt.ArrayLike, reset_distance: float) -> None:
        """``clear_around_<costmap>``: clear obstacle/range layers inside the square around the robot."""
        self._clear_region(robot_pose, reset_distance, invert=True)

    def clear_except_region(self, robot_pose: npt.ArrayLike, reset_distance: float) -> None:
        """``clear_except_<costmap>``: clear obstacle/range layers outside the square."""
        self._clear_region(robot_pose, reset_distance, invert=False)

    # --- queries -------------------------------------------------------------------------
    def footprint_at(self, pose: npt.ArrayLike) -> npt.NDArray[np.float64]:
        return transform_footprint(pose, self.footprint)

    def speed_limit_changes(self) -> list[Any]:
        out = []
        for f in self.filters:
            if isinstance(f, SpeedFilter) and f.pending is not None:
                out.append(f.pending)
                f.pending = None
        return out


# --- plugins -----------------------------------------------------------------------------
#: the ``costmap_layers`` registry: layers and filters (``plugins`` and ``filters`` lists)
COSTMAP_PLUGINS = registry("costmap_layers")

_DEFAULT_TYPES = {
    "static_layer": "nav2_costmap_2d::StaticLayer",
    "obstacle_layer": "nav2_costmap_2d::ObstacleLayer",
    "inflation_layer": "nav2_costmap_2d::InflationLayer",
}


def _configured(cls: type[Any], config_cls: type[Any]) -> PluginFactory:
    """Factory of a layer built as ``cls(name, config)``."""

    def factory(params: dict[str, Any], name: str, context: PluginContext) -> Any:
        return cls(name, from_params(config_cls, params, server=context.where))

    return factory


def _obstacle_layer(params: dict[str, Any], name: str, context: PluginContext) -> Any:
    where = context.where
    known = {f.name for f in fields(ObservationSourceConfig)}
    sources: dict[str, ObservationSourceConfig] = {}
    for src in str(params.get("observation_sources", "")).split():
        sp = dict(params.get(src, {}) or {})
        sources[src] = from_params(
            ObservationSourceConfig, {k: v for k, v in sp.items() if k in known},
            server=f"{where}.{src}",
        )
    plain = {k: v for k, v in params.items() if k != "sources" and not isinstance(v, dict)}
    cfg = from_params(ObstacleLayerConfig, plain, server=where, validate=lambda c, s: None)
    cfg = ObstacleLayerConfig(**{**cfg.__dict__, "sources": sources})
    cfg.validate(where)
    return ObstacleLayer(name, cfg)


def _register_built_in_layers() -> None:
    layers: dict[str, tuple[type[Any], type[Any]]] = {
        "nav2_costmap_2d::StaticLayer": (StaticLayer, StaticLayerConfig),
        "nav2_costmap_2d::InflationLayer": (InflationLayer, InflationLayerConfig),
        "nav2_costmap_2d::RangeSensorLayer": (RangeLayer, RangeLayerConfig),
        **{t: (c, c.config_class) for t, c in FILTER_PLUGINS.items()},
    }
    for type_name, (cls, config_cls) in layers.items():
        COSTMAP_PLUGINS.register(type_name, _configured(cls, config_cls), config_cls,
                                 source="built-in")
    # the obstacle layer's observation sources nest: its config dataclass does not list them
    for type_name in ("nav2_costmap_2d::ObstacleLayer", "nav2_costmap_2d::VoxelLayer"):
        COSTMAP_PLUGINS.register(type_name, _obstacle_layer, source="built-in")


_register_built_in_layers()


def _layer_from_params(name: str, params: Mapping[str, Any], config: CostmapConfig,
                       server: str) -> Layer:
    sub = params.get(name, {}) or {}
    plugin = sub.get("plugin", _DEFAULT_TYPES.get(name))
    if plugin is None:
        raise ParameterError(server, f"{name}.plugin", None, "missing plugin type")
    layer: Layer = COSTMAP_PLUGINS.create(str(plugin), sub, name,
                                          PluginContext(server, name, config))
    return layer


def build_costmap(params: Mapping[str, Any] | None = None, name: str = "costmap") -> LayeredCostmap:
    """Build a layered costmap from a costmap node's ``ros__parameters`` dict."""
    params = dict(params or {})
    flat = {k: v for k, v in params.items() if not isinstance(v, dict)}
    for key in ("plugins", "filters"):
        if key in flat and isinstance(flat[key], str):
            flat[key] = flat[key].split()
    if isinstance(flat.get("footprint"), list):
        flat["footprint"] = str(flat["footprint"])
    config = from_params(CostmapConfig, flat, server=name)
    costmap = LayeredCostmap(config, name)
    for lname in config.plugins:
        costmap.add_layer(_layer_from_params(lname, params, config, name))
    for fname in config.filters:
        costmap.add_filter(_layer_from_params(fname, params, config, name))
    return costmap


def to_occupancy_grid(
    costmap: Costmap2D, frame_id: str = "map", stamp_ns: int = 0
) -> Any:
    """``nav_msgs/OccupancyGrid`` of a costmap with Nav2's cost translation."""
    from eddiebot.msgs.builtin_interfaces import Time
    from eddiebot.msgs.geometry_msgs import Point, Pose, Quaternion
    from eddiebot.msgs.nav_msgs import MapMetaData, OccupancyGrid
    from eddiebot.msgs.std_msgs import Header

    stamp = Time(sec=int(stamp_ns // 1_000_000_000), nanosec=int(stamp_ns % 1_000_000_000))
    info = MapMetaData(
        map_load_time=stamp,
        resolution=float(costmap.resolution),
        width=costmap.size_x,
        height=costmap.size_y,
        origin=Pose(position=Point(x=costmap.origin_x, y=costmap.origin_y, z=0.0),
                    orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)),
    )
    return OccupancyGrid(
        header=Header(stamp=stamp, frame_id=frame_id),
        info=info,
        data=costmap.to_occupancy().reshape(-1).copy(),
    )


def costmap_to_occupancy_map(costmap: Costmap2D, frame_id: str = "map") -> OccupancyMap:
    """The costmap as an :class:`~eddiebot.maps.OccupancyMap` (Nav2 cost translation)."""
    return OccupancyMap(costmap.to_occupancy(), costmap.resolution,
                        (costmap.origin_x, costmap.origin_y, 0.0), frame_id)


__all__ = [
    "COSTMAP_PLUGINS",
    "CostmapConfig",
    "LayeredCostmap",
    "build_costmap",
    "costmap_to_occupancy_map",
    "to_occupancy_grid",
]
