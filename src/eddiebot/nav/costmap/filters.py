"""Costmap filters (``nav2_costmap_2d/costmap_filters``): keepout zones and speed limits.

Masks are occupancy maps (map_server files, read with :func:`eddiebot.maps.load_map`)
in the mask's own frame, assumed here to coincide with the costmap's global frame. The
filter-info message fields (``type``, ``base``, ``multiplier``) come in a
:class:`CostmapFilterInfo`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from eddiebot.maps import OccupancyMap
from eddiebot.nav.cost_values import NO_INFORMATION, occupancy_to_mask_costs
from eddiebot.nav.costmap.costmap2d import Costmap2D
from eddiebot.nav.costmap.layers.base import Bounds, Layer

# nav2_msgs/CostmapFilterInfo type values.
KEEPOUT_FILTER = 0
SPEED_FILTER_PERCENT = 1
SPEED_FILTER_ABSOLUTE = 2
BINARY_FILTER = 3

#: nav2_msgs/SpeedLimit: 0.0 means "no limit".
NO_SPEED_LIMIT = 0.0


@dataclass(frozen=True)
class CostmapFilterInfo:
    """``nav2_msgs/CostmapFilterInfo`` fields."""

    type: int = KEEPOUT_FILTER
    base: float = 0.0
    multiplier: float = 1.0


@dataclass(frozen=True)
class CostmapFilterConfig:
    """Common filter parameters (Jazzy code defaults)."""

    enabled: bool = True
    filter_info_topic: str = ""
    transform_tolerance: float = 0.1


class SpeedLimit(NamedTuple):
    """``nav2_msgs/SpeedLimit``: ``percentage`` true -> limit is % of maximum speed."""

    percentage: bool
    speed_limit: float


def _mask_index(mask: OccupancyMap, wx: npt.NDArray[np.floating], wy: npt.NDArray[np.floating]
                ) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64], npt.NDArray[np.bool_]]:
    mx = np.floor((wx - mask.origin[0]) / mask.resolution).astype(np.int64)
    my = np.floor((wy - mask.origin[1]) / mask.resolution).astype(np.int64)
    ok = (mx >= 0) & (my >= 0) & (mx < mask.width) & (my < mask.height)
    return mx, my, ok


class KeepoutFilter(Layer):
    """``KeepoutFilter``: mask cells raise master costs (never lower them)."""

    def __init__(self, name: str = "keepout_filter", config: CostmapFilterConfig | None = None) -> None:
        super().__init__(name)
        self.config = config or CostmapFilterConfig()
        self.enabled = self.config.enabled
        self._mask: OccupancyMap | None = None
        self._mask_costs: npt.NDArray[np.uint8] | None = None
        self._new_mask = False

    def set_mask(self, mask: OccupancyMap, info: CostmapFilterInfo | None = None) -> None:
        self._mask = mask
        self._mask_costs = occupancy_to_mask_costs(mask.data)
        self._new_mask = True

    def update_bounds(self, robot_x: float, robot_y: float, robot_yaw: float, bounds: Bounds) -> None:
        if self._mask is None or not self._new_mask:
            return
        m = self._mask
        bounds[0] = min(bounds[0], m.origin[0])
        bounds[1] = min(bounds[1], m.origin[1])
        bounds[2] = max(bounds[2], m.origin[0] + m.width * m.resolution)
        bounds[3] = max(bounds[3], m.origin[1] + m.height * m.resolution)
        self._new_mask = False

    def update_costs(self, master: Costmap2D, i0: int, j0: int, i1: int, j1: int) -> None:
        if not self.enabled or self._mask is None or self._mask_costs is None:
            return
        ii, jj = np.meshgrid(np.arange(i0, i1), np.arange(j0, j1))
        wx = master.origin_x + (ii + 0.5) * master.resolution
        wy = master.origin_y + (jj + 0.5) * master.resolution
        mx, my, ok = _mask_index(self._mask, wx, wy)
        data = np.full(wx.shape, NO_INFORMATION, dtype=np.uint8)
        data[ok] = self._mask_costs[my[ok], mx[ok]]
        win = master.data[j0:j1, i0:i1]
        write = (data != NO_INFORMATION) & ((data > win) | (win == NO_INFORMATION))
        win[write] = data[write]


class SpeedFilter(Layer):
    """``SpeedFilter``: speed limit from the mask value under the robot.

    ``speed_limit = base + multiplier · mask`` (mask 0..100); mask 0 or unknown -> no limit;
    percentages outside (0, 100] and negative absolute limits -> no limit. :meth:`update`
    returns a new :class:`SpeedLimit` only when the limit changes (the node publishes it).
    """

    def __init__(self, name: str = "speed_filter", config: CostmapFilterConfig | None = None) -> None:
        super().__init__(name)
        self.config = config or CostmapFilterConfig()
        self.enabled = self.config.enabled
        self._mask: OccupancyMap | None = None
        self._info = CostmapFilterInfo(SPEED_FILTER_PERCENT)
        self._current = NO_SPEED_LIMIT
        self.pending: SpeedLimit | None = None

    def set_mask(self, mask: OccupancyMap, info: CostmapFilterInfo | None = None) -> None:
        self._mask = mask
        if info is not None:
            self._info = info

    @property
    def percentage(self) -> bool:
        return self._info.type == SPEED_FILTER_PERCENT

    def speed_limit_at(self, wx: float, wy: float) -> float:
        """Speed limit at a world point (% or m/s); ``NO_SPEED_LIMIT`` (0.0) when none."""
        if self._mask is None:
            return NO_SPEED_LIMIT
        mx, my, ok = _mask_index(self._mask, np.array([wx]), np.array([wy]))
        if not ok[0]:
            return NO_SPEED_LIMIT
        v = int(self._mask.data[my[0], mx[0]])
        if v <= 0:
            return NO_SPEED_LIMIT
        limit = v * self._info.multiplier + self._info.base
        if self.percentage:
            if limit < 0.0 or limit > 100.0:
                return NO_SPEED_LIMIT
        elif limit < 0.0:
            return NO_SPEED_LIMIT
        return float(limit)

    def update(self, robot_x: float, robot_y: float) -> SpeedLimit | None:
        if not self.enabled:
            return None
        limit = self.speed_limit_at(robot_x, robot_y)
        if math.isclose(limit, self._current):
            return None
        self._current = limit
        return SpeedLimit(self.percentage, limit)

    def update_bounds(self, robot_x: float, robot_y: float, robot_yaw: float, bounds: Bounds) -> None:
        self.pending = self.update(robot_x, robot_y) or self.pending


__all__ = [
    "BINARY_FILTER",
    "KEEPOUT_FILTER",
    "NO_SPEED_LIMIT",
    "SPEED_FILTER_ABSOLUTE",
    "SPEED_FILTER_PERCENT",
    "CostmapFilterConfig",
    "CostmapFilterInfo",
    "KeepoutFilter",
    "SpeedFilter",
    "SpeedLimit",
]
