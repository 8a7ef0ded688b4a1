"""Nav2 costmap cost values (``nav2_costmap_2d/cost_values.hpp``) and their translations."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

NO_INFORMATION = 255
LETHAL_OBSTACLE = 254
INSCRIBED_INFLATED_OBSTACLE = 253
MAX_NON_OBSTACLE = 252
FREE_SPACE = 0

# OccupancyGrid values.
OCC_GRID_UNKNOWN = -1
OCC_GRID_FREE = 0
OCC_GRID_OCCUPIED = 100


def _cost_translation_table() -> npt.NDArray[np.int8]:
    # Costmap2DPublisher: 0 -> 0, 253 -> 99, 254 -> 100, 255 -> -1,
    # 1..252 -> 1 + 97 * (i - 1) / 251 (integer arithmetic).
    table = np.zeros(256, dtype=np.int8)
    for i in range(1, 253):
        table[i] = 1 + (97 * (i - 1)) // 251
    table[INSCRIBED_INFLATED_OBSTACLE] = 99
    table[LETHAL_OBSTACLE] = 100
    table[NO_INFORMATION] = -1
    return table


COST_TO_OCCUPANCY: npt.NDArray[np.int8] = _cost_translation_table()


def costs_to_occupancy(costs: npt.NDArray[np.uint8]) -> npt.NDArray[np.int8]:
    """Translate costmap costs (0..255) to OccupancyGrid values (-1, 0..100) as Nav2 publishes them."""
    return COST_TO_OCCUPANCY[np.asarray(costs, dtype=np.uint8)]


def occupancy_to_mask_costs(data: npt.NDArray[np.int8]) -> npt.NDArray[np.uint8]:
    """Filter-mask translation (``getMaskCost``): -1 -> 255, v -> round(v * 254 / 100)."""
    d = np.asarray(data, dtype=np.int16)
    out = np.rint(np.clip(d, 0, 100) * (LETHAL_OBSTACLE - FREE_SPACE) / 100.0).astype(np.uint8)
    out[d < 0] = NO_INFORMATION
    return out


__all__ = [
    "COST_TO_OCCUPANCY",
    "FREE_SPACE",
    "INSCRIBED_INFLATED_OBSTACLE",
    "LETHAL_OBSTACLE",
    "MAX_NON_OBSTACLE",
    "NO_INFORMATION",
    "OCC_GRID_FREE",
    "OCC_GRID_OCCUPIED",
    "OCC_GRID_UNKNOWN",
    "costs_to_occupancy",
    "occupancy_to_mask_costs",
]
