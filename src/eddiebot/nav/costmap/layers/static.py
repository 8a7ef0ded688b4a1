"""The static layer: the map server's occupancy grid, interpreted as Nav2's ``StaticLayer`` does."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from eddiebot.maps import OccupancyMap
from eddiebot.nav.cost_values import (
    FREE_SPACE,
    LETHAL_OBSTACLE,
    NO_INFORMATION,
)
from eddiebot.nav.costmap.costmap2d import Costmap2D
from eddiebot.nav.costmap.layers.base import (
    Bounds,
    CostmapLayer,
    touch,
    update_with_max,
    update_with_true_overwrite,
)
from eddiebot.nav.params import require


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
