"""The layer contract (`Layer`, `CostmapLayer` with its own grid), update bounds and the
ways a layer's grid combines into the master."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from eddiebot.nav.cost_values import (
    FREE_SPACE,
    NO_INFORMATION,
)
from eddiebot.nav.costmap.costmap2d import Costmap2D

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
