"""The inflation layer: costs decaying with distance from lethal cells, on the master grid."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from eddiebot.nav.cost_values import (
    INSCRIBED_INFLATED_OBSTACLE,
    LETHAL_OBSTACLE,
)
from eddiebot.nav.costmap import _kernels
from eddiebot.nav.costmap.costmap2d import Costmap2D
from eddiebot.nav.costmap.layers.base import (
    Bounds,
    Layer,
    empty_bounds,
    merge_bounds,
)
from eddiebot.nav.params import require


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
