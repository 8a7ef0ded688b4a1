"""Costmap filters (``nav2_costmap_2d/costmap_filters``): keepout zones, speed limits, a
binary state.

A filter is fed a mask (an ``OccupancyGrid`` from a filter mask server, here an
:class:`~eddiebot.maps.OccupancyMap`) and the ``nav2_msgs/CostmapFilterInfo`` that tells how
to read it (:class:`CostmapFilterInfo`: ``type``, ``base``, ``multiplier``). Masks may lie in
another frame than the costmap: the node hands each filter the transform of the costmap's
global frame into the mask frame before an update (:meth:`CostmapFilter.set_mask_transform`).

- :class:`KeepoutFilter` raises master costs to the mask's (occupancy ``v`` ->
  ``round(v · 254 / 100)``, never lowering them); with ``override_lethal_cost`` a robot
  standing in a lethal part of the zone sees ``lethal_override_cost`` instead, so it can
  drive out.
- :class:`SpeedFilter` reads the mask under the robot: ``limit = base + multiplier · v``
  (percent of maximum speed for type 1, m/s for type 2); mask 0 means no limit, an unknown
  cell or a robot outside the mask changes nothing. A changed limit becomes ``pending``
  (the node publishes ``nav2_msgs/SpeedLimit``).
- :class:`BinaryFilter` flips its state from ``default_state`` while
  ``base + multiplier · v > flip_threshold`` under the robot, and back outside the mask;
  each change becomes ``pending`` (the node publishes ``std_msgs/Bool``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar, NamedTuple

import numpy as np
import numpy.typing as npt

from eddiebot.maps import OccupancyMap
from eddiebot.nav.cost_values import (
    FREE_SPACE,
    INSCRIBED_INFLATED_OBSTACLE,
    LETHAL_OBSTACLE,
    MAX_NON_OBSTACLE,
    NO_INFORMATION,
    OCC_GRID_UNKNOWN,
    occupancy_to_mask_costs,
)
from eddiebot.nav.costmap.costmap2d import Costmap2D
from eddiebot.nav.costmap.layers.base import Bounds, Layer, touch

# nav2_msgs/CostmapFilterInfo type values (filter_values.hpp).
KEEPOUT_FILTER = 0
SPEED_FILTER_PERCENT = 1
SPEED_FILTER_ABSOLUTE = 2
BINARY_FILTER = 3
BASE_DEFAULT = 0.0
MULTIPLIER_DEFAULT = 1.0

#: nav2_msgs/SpeedLimit: 0.0 means "no limit".
NO_SPEED_LIMIT = 0.0

#: (x, y, yaw): a point p in the costmap's global frame is R(yaw) p + (x, y) in the mask frame.
Transform2D = tuple[float, float, float]


@dataclass(frozen=True)
class CostmapFilterInfo:
    """``nav2_msgs/CostmapFilterInfo`` fields."""

    type: int = KEEPOUT_FILTER
    base: float = BASE_DEFAULT
    multiplier: float = MULTIPLIER_DEFAULT
    filter_mask_topic: str = ""


@dataclass(frozen=True)
class CostmapFilterConfig:
    """Parameters every filter takes (``CostmapFilter::onInitialize``, Jazzy defaults);
    ``transform_tolerance`` in s."""

    enabled: bool = True
    filter_info_topic: str = ""
    transform_tolerance: float = 0.1


@dataclass(frozen=True)
class KeepoutFilterConfig(CostmapFilterConfig):
    override_lethal_cost: bool = False
    lethal_override_cost: int = MAX_NON_OBSTACLE


@dataclass(frozen=True)
class SpeedFilterConfig(CostmapFilterConfig):
    speed_limit_topic: str = "speed_limit"


@dataclass(frozen=True)
class BinaryFilterConfig(CostmapFilterConfig):
    default_state: bool = False
    binary_state_topic: str = "binary_state"
    flip_threshold: float = 50.0


class SpeedLimit(NamedTuple):
    """``nav2_msgs/SpeedLimit``: ``percentage`` true -> limit is % of maximum speed."""

    percentage: bool
    speed_limit: float


class CostmapFilter(Layer):
    """What every filter shares: the mask, its info, the frame transform, the robot pose."""

    config_class: ClassVar[type[CostmapFilterConfig]] = CostmapFilterConfig
    #: the ``CostmapFilterInfo.type`` values this filter reads
    info_types: ClassVar[tuple[int, ...]] = (KEEPOUT_FILTER,)

    def __init__(self, name: str, config: CostmapFilterConfig | None = None) -> None:
        super().__init__(name)
        self.config = config or self.config_class()
        self.enabled = self.config.enabled
        self.mask: OccupancyMap | None = None
        self.info = CostmapFilterInfo(self.info_types[0])
        self._mask_tf: Transform2D | None = None
        self._tf_ok = True
        self.latest_pose = (0.0, 0.0, 0.0)
        self._new_mask = False

    # --- inputs ----------------------------------------------------------------------------
    def info_problem(self, info: CostmapFilterInfo) -> str:
        """Why ``info`` cannot drive this filter ('' when it can)."""
        if info.type not in self.info_types:
            return (f"{type(self).__name__} {self.name}: filter info type {info.type} is not "
                    f"supported (expects {' or '.join(map(str, self.info_types))})")
        return ""

    def set_filter_info(self, info: CostmapFilterInfo) -> str:
        """Take ``info`` unless its type does not fit; returns the problem ('' if none)."""
        problem = self.info_problem(info)
        if not problem:
            self.info = info
        return problem

    def set_mask(self, mask: OccupancyMap, info: CostmapFilterInfo | None = None) -> None:
        if info is not None:
            self.set_filter_info(info)
        self.mask = mask
        self._new_mask = True

    def set_mask_transform(self, transform: Transform2D | None, ok: bool = True) -> None:
        """The costmap's global frame into the mask frame (None: same frame); ``ok`` False
        when the transform is unknown (the filter then sits the update out, as Nav2's)."""
        self._mask_tf = transform
        self._tf_ok = ok

    @property
    def active(self) -> bool:
        return self.mask is not None

    # --- toggle_filter ---------------------------------------------------------------------
    @property
    def filter_enabled(self) -> bool:
        """Whether the filter is switched on (``enabled``, then ``toggle_filter``)."""
        return self.enabled

    def set_enabled(self, enabled: bool) -> str:
        """``CostmapFilter::enableCallback``, served on ``<filter>/toggle_filter``
        (``std_srvs/SetBool``): switch the filter on or off at run time; returns the service's
        message, ``Enabled`` or ``Disabled``. A switched-off filter reads nothing: a speed
        filter publishes no new limit and a binary filter keeps its state, as Nav2's."""
        self.enabled = bool(enabled)
        return "Enabled" if enabled else "Disabled"

    # --- geometry --------------------------------------------------------------------------
    def _to_mask_frame(self, wx: npt.NDArray[np.floating], wy: npt.NDArray[np.floating]
                       ) -> tuple[npt.NDArray[np.floating], npt.NDArray[np.floating]]:
        if self._mask_tf is None:
            return wx, wy
        tx, ty, yaw = self._mask_tf
        c, s = math.cos(yaw), math.sin(yaw)
        return tx + c * wx - s * wy, ty + s * wx + c * wy

    def _mask_cells(self, wx: npt.NDArray[np.floating], wy: npt.NDArray[np.floating]
                    ) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64], npt.NDArray[np.bool_]]:
        """Mask cells (column, row, inside) of global-frame points (``worldToMask``)."""
        assert self.mask is not None
        m = self.mask
        px, py = self._to_mask_frame(wx, wy)
        dx, dy = px - m.origin[0], py - m.origin[1]
        c, s = math.cos(m.origin[2]), math.sin(m.origin[2])
        mx = np.floor((c * dx + s * dy) / m.resolution).astype(np.int64)
        my = np.floor((-s * dx + c * dy) / m.resolution).astype(np.int64)
        ok = (mx >= 0) & (my >= 0) & (mx < m.width) & (my < m.height)
        return mx, my, ok

    def mask_value_at(self, wx: float, wy: float) -> int | None:
        """The mask's occupancy value (-1, 0..100) at a global-frame point; None outside."""
        if self.mask is None:
            return None
        mx, my, ok = self._mask_cells(np.array([wx]), np.array([wy]))
        if not ok[0]:
            return None
        return int(self.mask.data[my[0], mx[0]])

    def mask_bounds(self) -> tuple[float, float, float, float]:
        """The mask's extent in the costmap's global frame (min x, min y, max x, max y)."""
        assert self.mask is not None
        m = self.mask
        w, h = m.width * m.resolution, m.height * m.resolution
        c, s = math.cos(m.origin[2]), math.sin(m.origin[2])
        corners = np.array([[0.0, 0.0], [w, 0.0], [0.0, h], [w, h]])
        px = m.origin[0] + c * corners[:, 0] - s * corners[:, 1]
        py = m.origin[1] + s * corners[:, 0] + c * corners[:, 1]
        if self._mask_tf is not None:  # mask frame -> global frame: the inverse transform
            tx, ty, yaw = self._mask_tf
            c, s = math.cos(yaw), math.sin(yaw)
            dx, dy = px - tx, py - ty
            px, py = c * dx + s * dy, -s * dx + c * dy
        return float(px.min()), float(py.min()), float(px.max()), float(py.max())

    def update_bounds(self, robot_x: float, robot_y: float, robot_yaw: float, bounds: Bounds) -> None:
        self.latest_pose = (robot_x, robot_y, robot_yaw)

    def reset(self) -> None:
        self._new_mask = self.mask is not None


class KeepoutFilter(CostmapFilter):
    """``KeepoutFilter``: mask cells raise master costs (never lower them)."""

    config_class = KeepoutFilterConfig
    config: KeepoutFilterConfig

    def __init__(self, name: str = "keepout_filter", config: CostmapFilterConfig | None = None) -> None:
        super().__init__(name, config)
        self._mask_costs: npt.NDArray[np.uint8] | None = None
        self._pose_lethal = False
        self._last_pose_lethal = False
        self._on = self.config.enabled

    def info_problem(self, info: CostmapFilterInfo) -> str:
        # Nav2 reads any type here and only warns about base/multiplier
        if info.base != BASE_DEFAULT or info.multiplier != MULTIPLIER_DEFAULT:
            return (f"KeepoutFilter {self.name}: base and multiplier should be {BASE_DEFAULT} and "
                    f"{MULTIPLIER_DEFAULT} (got {info.base} and {info.multiplier})")
        return ""

    def set_filter_info(self, info: CostmapFilterInfo) -> str:
        self.info = info
        return self.info_problem(info)

    def set_mask(self, mask: OccupancyMap, info: CostmapFilterInfo | None = None) -> None:
        super().set_mask(mask, info)
        self._mask_costs = occupancy_to_mask_costs(mask.data)

    @property
    def lethal_override_cost(self) -> int:
        return int(np.clip(self.config.lethal_override_cost, FREE_SPACE, MAX_NON_OBSTACLE))

    @property
    def filter_enabled(self) -> bool:
        return self._on

    def set_enabled(self, enabled: bool) -> str:
        """As :meth:`CostmapFilter.set_enabled`; a switch redraws the zone's area in the next
        update, so switching off clears the zone from the costmap (Nav2's filter only stops
        drawing it: the zone lingers until the master is reset there) and switching on paints
        it at once."""
        enabled = bool(enabled)
        if enabled != self._on:
            self._on = enabled
            self._new_mask = self.mask is not None
            self.enabled = True  # take part in the next update, which redraws the area
        return "Enabled" if enabled else "Disabled"

    def update_bounds(self, robot_x: float, robot_y: float, robot_yaw: float, bounds: Bounds) -> None:
        super().update_bounds(robot_x, robot_y, robot_yaw, bounds)
        if not self._on:  # switched off: clear the zone once, then sit the updates out
            if self.mask is not None and self._new_mask:
                if not self._tf_ok:
                    return
                x0, y0, x1, y1 = self.mask_bounds()
                touch(bounds, x0, y0)
                touch(bounds, x1, y1)
                self._new_mask = False
            self.enabled = False
            return
        if self.mask is None or not self._tf_ok:
            return
        self._last_pose_lethal = self._pose_lethal
        self._pose_lethal = False
        if self.config.override_lethal_cost:
            v = self.mask_value_at(robot_x, robot_y)
            if v is not None and v != OCC_GRID_UNKNOWN:
                cost = occupancy_to_mask_costs(np.array([v]))[0]
                self._pose_lethal = cost in (INSCRIBED_INFLATED_OBSTACLE, LETHAL_OBSTACLE)
        rolling = self._layered is not None and self.layered.rolling_window
        # the whole zone is redrawn when the mask is new, when the robot enters or leaves a
        # lethal part of it (override), and every cycle in a rolling window (cells roll in)
        if not (self._new_mask or rolling or self._pose_lethal or self._last_pose_lethal):
            return
        x0, y0, x1, y1 = self.mask_bounds()
        touch(bounds, x0, y0)
        touch(bounds, x1, y1)
        self._new_mask = False

    def update_costs(self, master: Costmap2D, i0: int, j0: int, i1: int, j1: int) -> None:
        if not self._on or self.mask is None or self._mask_costs is None or not self._tf_ok:
            return
        if i1 <= i0 or j1 <= j0:
            return
        ii, jj = np.meshgrid(np.arange(i0, i1), np.arange(j0, j1))
        wx = master.origin_x + (ii + 0.5) * master.resolution
        wy = master.origin_y + (jj + 0.5) * master.resolution
        mx, my, ok = self._mask_cells(wx, wy)
        if not ok.any():
            return
        data = np.full(wx.shape, NO_INFORMATION, dtype=np.uint8)
        data[ok] = self._mask_costs[my[ok], mx[ok]]
        win = master.data[j0:j1, i0:i1]
        write = (data != NO_INFORMATION) & ((data > win) | (win == NO_INFORMATION))
        if self.config.override_lethal_cost and self._pose_lethal:
            win[write] = self.lethal_override_cost
        else:
            win[write] = data[write]


class SpeedFilter(CostmapFilter):
    """``SpeedFilter``: speed limit from the mask value under the robot (see the module)."""

    config_class = SpeedFilterConfig
    info_types = (SPEED_FILTER_PERCENT, SPEED_FILTER_ABSOLUTE)
    config: SpeedFilterConfig

    def __init__(self, name: str = "speed_filter", config: CostmapFilterConfig | None = None) -> None:
        super().__init__(name, config)
        self._current = NO_SPEED_LIMIT
        self.pending: SpeedLimit | None = None

    @property
    def percentage(self) -> bool:
        return self.info.type == SPEED_FILTER_PERCENT

    def speed_limit_at(self, wx: float, wy: float) -> float | None:
        """Speed limit at a global-frame point (% or m/s; ``NO_SPEED_LIMIT`` 0.0 for none);
        None where the mask says nothing (outside it, or an unknown cell)."""
        v = self.mask_value_at(wx, wy)
        if v is None or v == OCC_GRID_UNKNOWN:
            return None
        if v == 0:
            return NO_SPEED_LIMIT
        limit = v * self.info.multiplier + self.info.base
        if self.percentage:
            if limit < 0.0 or limit > 100.0:
                return NO_SPEED_LIMIT
        elif limit < 0.0:
            return NO_SPEED_LIMIT
        return float(limit)

    def update(self, robot_x: float, robot_y: float) -> SpeedLimit | None:
        """The new limit if the robot's position changes it, else None."""
        if not self.enabled or not self._tf_ok:
            return None
        limit = self.speed_limit_at(robot_x, robot_y)
        if limit is None or math.isclose(limit, self._current):
            return None
        self._current = limit
        return SpeedLimit(self.percentage, limit)

    def update_bounds(self, robot_x: float, robot_y: float, robot_yaw: float, bounds: Bounds) -> None:
        super().update_bounds(robot_x, robot_y, robot_yaw, bounds)
        self.pending = self.update(robot_x, robot_y) or self.pending

    @property
    def speed_limit(self) -> float:
        """The limit in force (% or m/s, 0.0: none)."""
        return self._current


class BinaryFilter(CostmapFilter):
    """``BinaryFilter``: a boolean that flips while the robot is in the mask's zone."""

    config_class = BinaryFilterConfig
    info_types = (BINARY_FILTER,)
    config: BinaryFilterConfig

    def __init__(self, name: str = "binary_filter", config: CostmapFilterConfig | None = None) -> None:
        super().__init__(name, config)
        self.state = self.config.default_state
        #: state changes not yet published, oldest first (the initial state first of all)
        self.pending: list[bool] = [self.state]

    def _change(self, state: bool) -> None:
        self.state = state
        self.pending.append(state)

    def update(self, robot_x: float, robot_y: float) -> None:
        if not self.enabled or not self._tf_ok or self.mask is None:
            return
        default = self.config.default_state
        v = self.mask_value_at(robot_x, robot_y)
        if v is None:  # outside the mask: back to the default state
            if self.state != default:
                self._change(default)
            return
        if v == OCC_GRID_UNKNOWN:
            return
        if self.info.base + v * self.info.multiplier > self.config.flip_threshold:
            if self.state == default:
                self._change(not default)
        elif self.state != default:
            self._change(default)

    def update_bounds(self, robot_x: float, robot_y: float, robot_yaw: float, bounds: Bounds) -> None:
        super().update_bounds(robot_x, robot_y, robot_yaw, bounds)
        self.update(robot_x, robot_y)


#: costmap filter plugins by Nav2 name
FILTER_PLUGINS: dict[str, type[CostmapFilter]] = {
    "nav2_costmap_2d::KeepoutFilter": KeepoutFilter,
    "nav2_costmap_2d::SpeedFilter": SpeedFilter,
    "nav2_costmap_2d::BinaryFilter": BinaryFilter,
}

__all__ = [
    "BASE_DEFAULT",
    "BINARY_FILTER",
    "FILTER_PLUGINS",
    "KEEPOUT_FILTER",
    "MULTIPLIER_DEFAULT",
    "NO_SPEED_LIMIT",
    "SPEED_FILTER_ABSOLUTE",
    "SPEED_FILTER_PERCENT",
    "BinaryFilter",
    "BinaryFilterConfig",
    "CostmapFilter",
    "CostmapFilterConfig",
    "CostmapFilterInfo",
    "KeepoutFilter",
    "KeepoutFilterConfig",
    "SpeedFilter",
    "SpeedFilterConfig",
    "SpeedLimit",
    "Transform2D",
]
