"""Ground-truth occupancy maps of a world, for judging SLAM and navigation.

Two maps at 0.05 m (by default), both `eddiebot.maps.OccupancyMap` (0 free, 100 occupied):

* `scan_slice_map`: what a 2-D SLAM can see — prisms cut by the horizontal plane at the
  scan's height (the Kinect's, 0.6083 m). Tables whose top is above it and low boxes are
  absent, as they are from the scan.
* `footprint_map`: what the robot can hit — every prism with a part between the ground
  clearance (0.02 m) and the robot's height (0.65 m).

A cell is occupied when its centre lies within half a cell of a prism's outline, so thin
things (table legs) are never lost between cell centres. `cached_ground_truth` keeps the
maps as nav2 map files under ``~/.cache/eddiebot/ground_truth`` (or ``$EDDIE_CACHE_DIR``).
"""

from __future__ import annotations

import hashlib
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from eddiebot.maps import OccupancyMap, load_map, save_map
from eddiebot.sim.world import GROUND_CLEARANCE, ROBOT_HEIGHT, Prism, World

__all__ = [
    "SCAN_HEIGHT",
    "GroundTruthMaps",
    "cache_dir",
    "cached_ground_truth",
    "footprint_map",
    "ground_truth_maps",
    "rasterize",
    "scan_slice_map",
]

SCAN_HEIGHT = 0.6083
"""Height of camera_depth_frame above the floor (m): the scan plane."""


@dataclass(frozen=True)
class GroundTruthMaps:
    scan: OccupancyMap
    footprint: OccupancyMap


def rasterize(world: World, prisms: tuple[Prism, ...], resolution: float = 0.05,
              margin: float = 1.0) -> OccupancyMap:
    """Occupancy grid over the world's bounds plus ``margin`` with ``prisms`` occupied."""
    xmin, ymin, xmax, ymax = world.bounds
    x0 = math.floor((xmin - margin) / resolution) * resolution
    y0 = math.floor((ymin - margin) / resolution) * resolution
    w = math.ceil((xmax + margin - x0) / resolution)
    h = math.ceil((ymax + margin - y0) / resolution)
    data = np.zeros((h, w), np.int8)
    half = resolution / 2
    for p in prisms:
        bx0, by0, bx1, by1 = p.bbox()
        c0 = max(0, math.floor((bx0 - x0) / resolution) - 1)
        c1 = min(w, math.ceil((bx1 - x0) / resolution) + 1)
        r0 = max(0, math.floor((by0 - y0) / resolution) - 1)
        r1 = min(h, math.ceil((by1 - y0) / resolution) + 1)
        if c1 <= c0 or r1 <= r0:
            continue
        cx = x0 + (np.arange(c0, c1) + 0.5) * resolution
        cy = y0 + (np.arange(r0, r1) + 0.5) * resolution
        gx, gy = np.meshgrid(cx, cy)
        pts = np.column_stack([gx.ravel(), gy.ravel()])
        inside = (p.distance(pts) <= half).reshape(gx.shape)
        data[r0:r1, c0:c1][inside] = 100
    return OccupancyMap(data=data, resolution=resolution, origin=(x0, y0, 0.0))


def scan_slice_map(world: World, height: float = SCAN_HEIGHT, resolution: float = 0.05) -> OccupancyMap:
    """Prisms cut by the plane z = ``height`` (what the scan sees)."""
    return rasterize(world, tuple(p for p in world.prisms if p.bottom <= height <= p.top), resolution)


def footprint_map(world: World, z_low: float = GROUND_CLEARANCE, z_high: float = ROBOT_HEIGHT,
                  resolution: float = 0.05) -> OccupancyMap:
    """Prisms with any part between ``z_low`` and ``z_high`` (what the robot can hit)."""
    return rasterize(world, world.prisms_between(z_low, z_high), resolution)


def ground_truth_maps(world: World, resolution: float = 0.05) -> GroundTruthMaps:
    """Both maps, computed now."""
    return GroundTruthMaps(scan_slice_map(world, resolution=resolution),
                           footprint_map(world, resolution=resolution))


def cache_dir() -> Path:
    """``$EDDIE_CACHE_DIR/ground_truth`` or ``~/.cache/eddiebot/ground_truth``."""
    base = os.environ.get("EDDIE_CACHE_DIR")
    root = Path(base) if base else Path.home() / ".cache" / "eddiebot"
    return root / "ground_truth"


def _key(world: World, resolution: float) -> str:
    h = hashlib.sha256()
    h.update(repr((resolution, SCAN_HEIGHT, GROUND_CLEARANCE, ROBOT_HEIGHT)).encode())
    for p in world.prisms:
        h.update(repr((p.bottom, p.top, p.quad, p.circle)).encode())
    return f"{world.name}-{h.hexdigest()[:16]}"


def cached_ground_truth(world: World, resolution: float = 0.05,
                        directory: Path | None = None) -> GroundTruthMaps:
    """Both maps, from the cache when the world is unchanged; computed and stored
    (as nav2 ``.pgm`` + ``.yaml``, written atomically) otherwise."""
    directory = directory or cache_dir()
    key = _key(world, resolution)
    scan_p, foot_p = directory / f"{key}-scan", directory / f"{key}-footprint"
    if scan_p.with_suffix(".yaml").exists() and foot_p.with_suffix(".yaml").exists():
        try:
            return GroundTruthMaps(load_map(scan_p.with_suffix(".yaml")),
                                   load_map(foot_p.with_suffix(".yaml")))
        except Exception:  # a corrupt cache entry is recomputed
            pass
    maps = ground_truth_maps(world, resolution)
    directory.mkdir(parents=True, exist_ok=True)
    save_map(maps.scan, scan_p)
    save_map(maps.footprint, foot_p)
    return maps
