"""Nav2-style layered costmaps: cost grid, layers, filters, global and rolling maps.

A :class:`LayeredCostmap` owns a master :class:`Costmap2D` and ordered layers (static,
obstacle, range, inflation) and filters (keepout, speed, binary), updated by bounds then costs as
Nav2 does. Build one from a costmap node's parameters with :func:`build_costmap`; publish it
with :func:`to_occupancy_grid` (Nav2's cost -> 0..100 translation).
"""

from eddiebot.nav.costmap.costmap2d import Costmap2D
from eddiebot.nav.costmap.filters import (
    NO_SPEED_LIMIT,
    BinaryFilter,
    CostmapFilter,
    CostmapFilterConfig,
    CostmapFilterInfo,
    KeepoutFilter,
    SpeedFilter,
    SpeedLimit,
)
from eddiebot.nav.costmap.footprint import (
    inscribed_and_circumscribed_radius,
    make_footprint_from_radius,
    pad_footprint,
    parse_footprint,
    transform_footprint,
)
from eddiebot.nav.costmap.layered import (
    COSTMAP_PLUGINS,
    CostmapConfig,
    LayeredCostmap,
    build_costmap,
    costmap_to_occupancy_map,
    to_occupancy_grid,
)
from eddiebot.nav.costmap.layers import (
    InflationLayer,
    InflationLayerConfig,
    Layer,
    Observation,
    ObservationSourceConfig,
    ObstacleLayer,
    ObstacleLayerConfig,
    RangeLayer,
    RangeLayerConfig,
    RangeReading,
    StaticLayer,
    StaticLayerConfig,
    cloud_observation,
    inflation_cost,
    interpret_static_value,
    scan_observation,
    scan_points,
)

__all__ = [
    "COSTMAP_PLUGINS",
    "NO_SPEED_LIMIT",
    "BinaryFilter",
    "Costmap2D",
    "CostmapConfig",
    "CostmapFilter",
    "CostmapFilterConfig",
    "CostmapFilterInfo",
    "InflationLayer",
    "InflationLayerConfig",
    "KeepoutFilter",
    "Layer",
    "LayeredCostmap",
    "Observation",
    "ObservationSourceConfig",
    "ObstacleLayer",
    "ObstacleLayerConfig",
    "RangeLayer",
    "RangeLayerConfig",
    "RangeReading",
    "SpeedFilter",
    "SpeedLimit",
    "StaticLayer",
    "StaticLayerConfig",
    "build_costmap",
    "cloud_observation",
    "costmap_to_occupancy_map",
    "inflation_cost",
    "inscribed_and_circumscribed_radius",
    "interpret_static_value",
    "make_footprint_from_radius",
    "pad_footprint",
    "parse_footprint",
    "scan_observation",
    "scan_points",
    "to_occupancy_grid",
    "transform_footprint",
]
