"""Occupancy grid from posed scans: ray casting into hit / pass-through counts.

Each beam is traced (Bresenham, numba) from the sensor cell to its end cell; every traversed
cell, the end cell included, gains a pass; a valid end point (range <= ``max_laser_range``)
gains a hit. Beams longer than ``max_laser_range`` are cut there and leave no hit (Karto's
rule). A cell with at least ``min_pass_through`` passes is occupied when
hits / passes > ``occupancy_threshold``, otherwise free; cells with fewer passes are unknown.

Scans can be removed again (``weight=-1``) with the pose they were added at, so after an
optimisation only the nodes that moved are re-rasterised.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
from numba import njit

from eddiebot.maps import OccupancyMap

__all__ = ["OccupancyGridBuilder"]

FloatArray = npt.NDArray[np.float64]

_GROW_MARGIN = 5.0  # m added on every side when the grid grows


@njit(cache=True)
def _raycast(
    hits: npt.NDArray[np.int32],
    passes: npt.NDArray[np.int32],
    c0: int,
    r0: int,
    end_c: npt.NDArray[np.int64],
    end_r: npt.NDArray[np.int64],
    end_hit: npt.NDArray[np.bool_],
    weight: int,
) -> None:
    h, w = hits.shape
    for k in range(end_c.size):
        c1 = end_c[k]
        r1 = end_r[k]
        dc = abs(c1 - c0)
        dr = -abs(r1 - r0)
        sc = 1 if c0 < c1 else -1
        sr = 1 if r0 < r1 else -1
        err = dc + dr
        c = c0
        r = r0
        while True:
            if 0 <= c < w and 0 <= r < h:
                passes[r, c] += weight
            if c == c1 and r == r1:
                break
            e2 = 2 * err
            if e2 >= dr:
                err += dr
                c += sc
            if e2 <= dc:
                err += dc
                r += sr
        if end_hit[k] and 0 <= c1 < w and 0 <= r1 < h:
            hits[r1, c1] += weight


class OccupancyGridBuilder:
    """Hit / pass counts over a grid that grows to fit the scans added (map frame)."""

    def __init__(
        self,
        resolution: float = 0.05,
        max_laser_range: float = 25.0,
        *,
        occupancy_threshold: float = 0.1,
        min_pass_through: int = 2,
    ) -> None:
        if resolution <= 0:
            raise ValueError(f"resolution must be > 0, got {resolution}")
        self.resolution = float(resolution)
        self.max_laser_range = float(max_laser_range)
        self.occupancy_threshold = float(occupancy_threshold)
        self.min_pass_through = int(min_pass_through)
        self.clear()

    def clear(self) -> None:
        """Forget every scan."""
        # Cell (0, 0) is the global cell (offset_c, offset_r), whose corner is at
        # (offset_c * resolution, offset_r * resolution): integer offsets keep the lattice exact
        # when the grid grows, so a scan removed later hits exactly the cells it was added to.
        self._offset = (0, 0)
        self.hits = np.zeros((0, 0), dtype=np.int32)
        self.passes = np.zeros((0, 0), dtype=np.int32)

    @property
    def origin(self) -> tuple[float, float]:
        """Map-frame position (m) of the lower-left corner of cell (0, 0)."""
        return (self._offset[0] * self.resolution, self._offset[1] * self.resolution)

    @property
    def shape(self) -> tuple[int, int]:
        """(rows, columns)."""
        return (int(self.hits.shape[0]), int(self.hits.shape[1]))

    def _ensure(self, cmin: int, rmin: int, cmax: int, rmax: int) -> None:
        h, w = self.shape
        oc, orow = self._offset
        if h and w and cmin >= oc and rmin >= orow and cmax < oc + w and rmax < orow + h:
            return
        grow = math.ceil(_GROW_MARGIN / self.resolution)
        if h and w:
            nc0, nr0 = min(oc, cmin - grow), min(orow, rmin - grow)
            nc1, nr1 = max(oc + w, cmax + 1 + grow), max(orow + h, rmax + 1 + grow)
        else:
            nc0, nr0, nc1, nr1 = cmin - grow, rmin - grow, cmax + 1 + grow, rmax + 1 + grow
        hits = np.zeros((nr1 - nr0, nc1 - nc0), dtype=np.int32)
        passes = np.zeros_like(hits)
        if h and w:
            hits[orow - nr0 : orow - nr0 + h, oc - nc0 : oc - nc0 + w] = self.hits
            passes[orow - nr0 : orow - nr0 + h, oc - nc0 : oc - nc0 + w] = self.passes
        self.hits, self.passes, self._offset = hits, passes, (nc0, nr0)

    def add_scan(
        self,
        sensor_pose: npt.ArrayLike,
        ranges: npt.ArrayLike,
        angles: npt.ArrayLike,
        *,
        range_min: float = 0.0,
        range_max: float = math.inf,
        weight: int = 1,
    ) -> None:
        """Ray-cast one scan from ``sensor_pose`` (map frame); ``weight=-1`` removes it."""
        pose = np.asarray(sensor_pose, dtype=np.float64)
        r = np.asarray(ranges, dtype=np.float64)
        a = np.asarray(angles, dtype=np.float64)
        with np.errstate(invalid="ignore"):
            ok = np.isfinite(r) & (r > 0.0) & (r >= range_min) & (r < range_max)
        if not np.any(ok):
            return
        r, a = r[ok], a[ok]
        hit = r <= self.max_laser_range
        r = np.minimum(r, self.max_laser_range)
        th = pose[2] + a
        res = self.resolution
        end_c = np.floor((pose[0] + r * np.cos(th)) / res).astype(np.int64)
        end_r = np.floor((pose[1] + r * np.sin(th)) / res).astype(np.int64)
        c0 = math.floor(pose[0] / res)
        r0 = math.floor(pose[1] / res)
        self._ensure(
            min(int(end_c.min()), c0),
            min(int(end_r.min()), r0),
            max(int(end_c.max()), c0),
            max(int(end_r.max()), r0),
        )
        oc, orow = self._offset
        _raycast(
            self.hits, self.passes, c0 - oc, r0 - orow, end_c - oc, end_r - orow, hit, int(weight)
        )

    def occupancy(self) -> npt.NDArray[np.int8]:
        """Cells (rows along y): -1 unknown, 0 free, 100 occupied."""
        out = np.full(self.hits.shape, -1, dtype=np.int8)
        known = self.passes >= max(self.min_pass_through, 1)
        ratio = np.zeros(self.hits.shape, dtype=np.float64)
        np.divide(self.hits, self.passes, out=ratio, where=self.passes > 0)
        out[known] = 0
        out[known & (ratio > self.occupancy_threshold)] = 100
        return out

    def to_map(self, *, crop: bool = True, frame_id: str = "map") -> OccupancyMap:
        """The grid as an `OccupancyMap`, cropped to the known cells (plus one cell)."""
        data = self.occupancy()
        ox, oy = self.origin
        if crop and data.size:
            rows = np.flatnonzero(np.any(data >= 0, axis=1))
            cols = np.flatnonzero(np.any(data >= 0, axis=0))
            if rows.size and cols.size:
                r0, r1 = max(rows[0] - 1, 0), min(rows[-1] + 2, data.shape[0])
                c0, c1 = max(cols[0] - 1, 0), min(cols[-1] + 2, data.shape[1])
                data = data[r0:r1, c0:c1]
                ox += c0 * self.resolution
                oy += r0 * self.resolution
        if data.size == 0:
            data = np.full((1, 1), -1, dtype=np.int8)
        return OccupancyMap(
            data=data, resolution=self.resolution, origin=(ox, oy, 0.0), frame_id=frame_id
        )
