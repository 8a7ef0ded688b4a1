"""``Costmap2D``: a grid of uint8 costs with Nav2's indexing and world/map conversions.

``data[my, mx]`` holds the cost of cell (mx, my); row 0 is the lowest y, as in
nav_msgs/OccupancyGrid. The origin is the world position (m) of cell (0, 0)'s corner;
the grid is axis-aligned with the global frame.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from eddiebot.nav.cost_values import NO_INFORMATION, costs_to_occupancy
from eddiebot.nav.costmap import _kernels
from eddiebot.nav.errors import CostmapError


class Costmap2D:
    """A 2-D cost grid (``nav2_costmap_2d::Costmap2D``)."""

    def __init__(
        self,
        size_x: int,
        size_y: int,
        resolution: float,
        origin_x: float = 0.0,
        origin_y: float = 0.0,
        default_value: int = 0,
    ) -> None:
        if size_x < 0 or size_y < 0 or not resolution > 0.0:
            raise CostmapError(f"invalid costmap geometry {size_x}x{size_y} @ {resolution}")
        self.resolution = float(resolution)
        self.origin_x = float(origin_x)
        self.origin_y = float(origin_y)
        self.default_value = int(default_value)
        self.data: npt.NDArray[np.uint8] = np.full(
            (int(size_y), int(size_x)), self.default_value, dtype=np.uint8
        )

    # --- geometry ------------------------------------------------------------------------
    @property
    def size_x(self) -> int:
        return int(self.data.shape[1])

    @property
    def size_y(self) -> int:
        return int(self.data.shape[0])

    @property
    def size_in_meters_x(self) -> float:
        return (self.size_x - 1 + 0.5) * self.resolution

    @property
    def size_in_meters_y(self) -> float:
        return (self.size_y - 1 + 0.5) * self.resolution

    def resize(
        self, size_x: int, size_y: int, resolution: float, origin_x: float, origin_y: float
    ) -> None:
        self.resolution = float(resolution)
        self.origin_x = float(origin_x)
        self.origin_y = float(origin_y)
        self.data = np.full((int(size_y), int(size_x)), self.default_value, dtype=np.uint8)

    def copy(self) -> Costmap2D:
        c = Costmap2D(0, 0, self.resolution, self.origin_x, self.origin_y, self.default_value)
        c.data = self.data.copy()
        return c

    def world_to_map(self, wx: float, wy: float) -> tuple[int, int] | None:
        """Cell (mx, my) holding world point (wx, wy), or None when outside the grid."""
        if wx < self.origin_x or wy < self.origin_y:
            return None
        mx = int((wx - self.origin_x) / self.resolution)
        my = int((wy - self.origin_y) / self.resolution)
        if mx < self.size_x and my < self.size_y:
            return mx, my
        return None

    def world_to_map_no_bounds(self, wx: float, wy: float) -> tuple[int, int]:
        return (
            math.floor((wx - self.origin_x) / self.resolution),
            math.floor((wy - self.origin_y) / self.resolution),
        )

    def world_to_map_enforce_bounds(self, wx: float, wy: float) -> tuple[int, int]:
        mx, my = self.world_to_map_no_bounds(wx, wy)
        return min(max(mx, 0), self.size_x - 1), min(max(my, 0), self.size_y - 1)

    def map_to_world(self, mx: float, my: float) -> tuple[float, float]:
        """World coordinates (m) of the centre of cell (mx, my)."""
        return (
            self.origin_x + (mx + 0.5) * self.resolution,
            self.origin_y + (my + 0.5) * self.resolution,
        )

    def cell_distance(self, world_dist: float) -> int:
        """``Costmap2D::cellDistance``: ceil(d / resolution), at least 0."""
        return max(0, math.ceil(world_dist / self.resolution))

    # --- costs ---------------------------------------------------------------------------
    def get_cost(self, mx: int, my: int) -> int:
        return int(self.data[my, mx])

    def set_cost(self, mx: int, my: int, cost: int) -> None:
        self.data[my, mx] = cost

    def cost_at_world(self, wx: float, wy: float, outside: int = NO_INFORMATION) -> int:
        cell = self.world_to_map(wx, wy)
        if cell is None:
            return outside
        return int(self.data[cell[1], cell[0]])

    def reset_map(self, x0: int, y0: int, xn: int, yn: int) -> None:
        """Set cells [x0, xn) x [y0, yn) to the default value."""
        self.data[max(0, y0):max(0, yn), max(0, x0):max(0, xn)] = self.default_value

    def reset_all(self) -> None:
        self.data[:] = self.default_value

    def update_origin(self, new_origin_x: float, new_origin_y: float) -> None:
        """Move the grid, keeping the overlapping cells (``Costmap2D::updateOrigin``)."""
        cell_ox = int((new_origin_x - self.origin_x) / self.resolution)
        cell_oy = int((new_origin_y - self.origin_y) / self.resolution)
        if cell_ox == 0 and cell_oy == 0:
            return
        new_grid_ox = self.origin_x + cell_ox * self.resolution
        new_grid_oy = self.origin_y + cell_oy * self.resolution
        sx, sy = self.size_x, self.size_y
        lower_x = min(max(cell_ox, 0), sx)
        lower_y = min(max(cell_oy, 0), sy)
        upper_x = min(max(cell_ox + sx, 0), sx)
        upper_y = min(max(cell_oy + sy, 0), sy)
        new = np.full_like(self.data, self.default_value)
        if upper_x > lower_x and upper_y > lower_y:
            start_x = lower_x - cell_ox
            start_y = lower_y - cell_oy
            new[start_y:start_y + upper_y - lower_y, start_x:start_x + upper_x - lower_x] = (
                self.data[lower_y:upper_y, lower_x:upper_x]
            )
        self.data = new
        self.origin_x = new_grid_ox
        self.origin_y = new_grid_oy

    def set_convex_polygon_cost(self, polygon_world: npt.ArrayLike, cost: int) -> None:
        """Set every cell whose centre lies inside the polygon (world frame, m) to ``cost``."""
        poly = np.asarray(polygon_world, dtype=np.float64).reshape(-1, 2)
        cells = np.empty_like(poly)
        cells[:, 0] = (poly[:, 0] - self.origin_x) / self.resolution
        cells[:, 1] = (poly[:, 1] - self.origin_y) / self.resolution
        _kernels.fill_polygon(self.data, cells, int(cost))

    def footprint_cost(self, polygon_world: npt.ArrayLike) -> int:
        """Max cost along the polygon outline (Nav2 FootprintCollisionChecker); -1 if off-map."""
        poly = np.ascontiguousarray(np.asarray(polygon_world, dtype=np.float64).reshape(-1, 2))
        return int(_kernels.polygon_outline_cost(
            self.data, poly, self.origin_x, self.origin_y, self.resolution
        ))

    def to_occupancy(self) -> npt.NDArray[np.int8]:
        """Costs as OccupancyGrid values (Nav2's Costmap2DPublisher translation)."""
        return costs_to_occupancy(self.data)


__all__ = ["Costmap2D"]
