"""Occupancy maps and their nav2 map_server files.

`OccupancyMap` is the in-memory grid (int8 cells -1 unknown / 0..100, row 0 at the lowest
y as in ``nav_msgs/OccupancyGrid``). `load_map` and `save_map` read and write the nav2
map_server format (``.pgm``/``.png`` image + ``.yaml``) in its trinary, scale and raw modes
with the same thresholds, negate flag and pixel rules as ``nav2_map_server``; writes are
atomic (temporary file, then rename). Maps are saved with ``free_thresh`` 0.196 so that
unknown cells (grey 205) reload as unknown; files an older eddiebot wrote with 0.25 load
with their unknown cells kept and a `LegacyMapWarning`. `map_to_msg` / `map_from_msg` convert to and from
``nav_msgs/OccupancyGrid``; `world_to_map` / `map_to_world` convert coordinates.
"""

from eddiebot.maps.errors import LegacyMapWarning, MapError, MapFormatError, MapWriteError
from eddiebot.maps.grid import (
    FREE,
    OCCUPIED,
    UNKNOWN,
    OccupancyMap,
    is_inside,
    map_from_msg,
    map_to_msg,
    map_to_world,
    world_to_map,
)
from eddiebot.maps.io import (
    DEFAULT_FREE_THRESH,
    DEFAULT_OCCUPIED_THRESH,
    MapAnchor,
    MapMode,
    MapYaml,
    image_to_map,
    load_map,
    map_to_image,
    read_anchor,
    read_map_yaml,
    save_anchor,
    save_map,
    write_image,
)

__all__ = [
    "DEFAULT_FREE_THRESH",
    "DEFAULT_OCCUPIED_THRESH",
    "FREE",
    "OCCUPIED",
    "UNKNOWN",
    "LegacyMapWarning",
    "MapAnchor",
    "MapError",
    "MapFormatError",
    "MapMode",
    "MapWriteError",
    "MapYaml",
    "OccupancyMap",
    "image_to_map",
    "is_inside",
    "load_map",
    "map_from_msg",
    "map_to_image",
    "map_to_msg",
    "map_to_world",
    "read_anchor",
    "read_map_yaml",
    "save_anchor",
    "save_map",
    "world_to_map",
    "write_image",
]
