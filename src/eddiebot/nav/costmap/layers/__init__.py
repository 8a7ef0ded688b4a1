"""Costmap layers with Nav2's updateBounds/updateCosts contract.

A layer is told the robot pose and grows the update bounds (world frame, m) to cover what it
changed (``update_bounds``); the layered costmap then resets that window of the master grid
and lets each layer, in order, write its costs into it (``update_costs``, cell window
``[i0, i1) x [j0, j1)``). Static, obstacle and range layers keep their own grid and combine it
into the master; the inflation layer works on the master directly.
"""

from __future__ import annotations

from eddiebot.nav.costmap.layers.base import (
    Bounds,
    CostmapLayer,
    Layer,
    empty_bounds,
    merge_bounds,
    touch,
    update_with_max,
    update_with_max_without_unknown_overwrite,
    update_with_overwrite,
    update_with_true_overwrite,
)
from eddiebot.nav.costmap.layers.inflation import (
    InflationLayer,
    InflationLayerConfig,
    inflation_cost,
)
from eddiebot.nav.costmap.layers.obstacle import (
    Observation,
    ObservationSourceConfig,
    ObstacleLayer,
    ObstacleLayerConfig,
    cloud_observation,
    scan_observation,
    scan_points,
)
from eddiebot.nav.costmap.layers.range import (
    RangeLayer,
    RangeLayerConfig,
    RangeReading,
    sensor_model,
)
from eddiebot.nav.costmap.layers.static import (
    StaticLayer,
    StaticLayerConfig,
    interpret_static_value,
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
    "empty_bounds",
    "inflation_cost",
    "interpret_static_value",
    "merge_bounds",
    "scan_observation",
    "scan_points",
    "sensor_model",
    "touch",
    "update_with_max",
    "update_with_max_without_unknown_overwrite",
    "update_with_overwrite",
    "update_with_true_overwrite",
]
