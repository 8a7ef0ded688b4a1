"""Lookup tables the search reads: the grid cells of a scan's points under each candidate
heading, the thinned point set of the coarse pass, and the translation offsets of a window."""

from __future__ import annotations

import functools
import math

import numpy as np
import numpy.typing as npt
from numba import njit

from eddiebot.slam.scan_matcher.grid import CorrelationGrid

FloatArray = npt.NDArray[np.float64]


@njit(cache=True)
def _rotated_cells(
    points: FloatArray,
    cos_t: FloatArray,
    sin_t: FloatArray,
    x: float,
    y: float,
    ox: float,
    oy: float,
    res: float,
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """Grid cells (A, M) of the points turned by each heading and moved to (x, y)."""
    n_ang = cos_t.size
    m = points.shape[0]
    px = np.empty((n_ang, m), np.int64)
    py = np.empty((n_ang, m), np.int64)
    for a in range(n_ang):
        c = cos_t[a]
        s = sin_t[a]
        for i in range(m):
            wx = c * points[i, 0] - s * points[i, 1] + x
            wy = s * points[i, 0] + c * points[i, 1] + y
            px[a, i] = math.floor((wx - ox) / res)
            py[a, i] = math.floor((wy - oy) / res)
    return px, py


def _cells_for_angles(
    points: FloatArray, prior: FloatArray, thetas: FloatArray, grid: CorrelationGrid
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    # the sines and cosines from numpy (the values every caller has always used)
    return _rotated_cells(
        np.ascontiguousarray(points, dtype=np.float64),
        np.cos(thetas),
        np.sin(thetas),
        float(prior[0]),
        float(prior[1]),
        float(grid.origin[0]),
        float(grid.origin[1]),
        float(grid.resolution),
    )


#: the last `_thin` result per cell size, with the points it came from (bytes): one scan is
#: thinned alike by its sequential match, a slip search and every loop chain it verifies
_THIN_MEMO: dict[float, tuple[tuple[tuple[int, ...], str, bytes], FloatArray]] = {}


def _thin(points: FloatArray, cell: float) -> FloatArray:
    """One point per ``cell``-sized square (the first in scan order)."""
    if points.shape[0] < 2:
        return points
    key = (points.shape, points.dtype.str, points.tobytes())
    memo = _THIN_MEMO.get(cell)
    if memo is not None and memo[0] == key:
        return memo[1]
    keys = np.floor(points / cell).astype(np.int64)
    _, first = np.unique(keys[:, 0] * 1_000_003 + keys[:, 1], return_index=True)
    out = np.ascontiguousarray(points[np.sort(first)])
    out.flags.writeable = False
    _THIN_MEMO[cell] = (key, out)
    return out


@functools.lru_cache(maxsize=8)
def _window_offsets(window: int, res: float) -> FloatArray:
    """Translation offsets (m) of every candidate of a ±window search, flattened [ix, iy]
    (read-only: shared by every match with the same window)."""
    gx, gy = np.meshgrid(
        np.arange(-window, window + 1) * res, np.arange(-window, window + 1) * res, indexing="ij"
    )
    coords = np.stack([gx.ravel(), gy.ravel()], axis=-1)
    coords.flags.writeable = False
    return coords
