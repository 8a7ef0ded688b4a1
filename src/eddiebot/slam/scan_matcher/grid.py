"""The correlation grid: a reference point set rasterised with Karto's smear kernel, and the
max-pooled pyramid branch and bound searches it with.

A cell holds ``exp(-½ (d/σ)²)`` for the distance d to the nearest reference point (0 beyond
2σ); a scan's response at a pose is the mean grid value under its end points (0..1, Karto's
response scaled from 0..100). Level h of the pyramid holds the maximum of the 2^h × 2^h cells
from each cell: an upper bound of every finer candidate beneath it.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt
from numba import njit

if TYPE_CHECKING:
    from eddiebot.slam.scan_matcher.search import MatcherParams

FloatArray = npt.NDArray[np.float64]

#: deepest pyramid the search kernels take (level h pools 2^h cells)
_MAX_LEVELS = 6


@dataclass(frozen=True)
class CorrelationGrid:
    """Smeared likelihood of a reference point set, with its max-pooled pyramid.

    ``levels[h][row, col]`` = max of ``levels[0]`` over rows row..row+2^h-1 and columns
    col..col+2^h-1. Cell (0, 0)'s lower-left corner is at ``origin`` (map frame, m).
    """

    levels: tuple[npt.NDArray[np.float32], ...]
    origin: tuple[float, float]
    resolution: float

    @property
    def likelihood(self) -> npt.NDArray[np.float32]:
        """The full-resolution grid (rows along y)."""
        return self.levels[0]


@njit(cache=True)
def _splat(
    grid: npt.NDArray[np.float32],
    cols: npt.NDArray[np.int64],
    rows: npt.NDArray[np.int64],
    kernel: npt.NDArray[np.float32],
) -> None:
    """grid = max(grid, kernel centred on each (row, col)) — Karto's smear.

    Cells whose kernel misses the grid are skipped and a cell holding several points is
    splatted once (the max does not depend on order or repetition).
    """
    h, w = grid.shape
    k = kernel.shape[0] // 2
    stride = w + 2 * k
    seen = np.zeros((h + 2 * k) * stride, np.bool_)
    for i in range(cols.size):
        c0 = cols[i]
        r0 = rows[i]
        if c0 < -k or c0 >= w + k or r0 < -k or r0 >= h + k:
            continue
        key = (r0 + k) * stride + (c0 + k)
        if seen[key]:
            continue
        seen[key] = True
        # kernel columns lo..hi-1 land inside the grid
        lo = max(0, k - c0)
        hi = min(2 * k + 1, w - c0 + k)
        m = hi - lo
        for dr in range(-k, k + 1):
            r = r0 + dr
            if r < 0 or r >= h:
                continue
            cells = grid[r, c0 - k + lo :]
            weights = kernel[dr + k, lo:]
            for q in range(m):
                if weights[q] > cells[q]:
                    cells[q] = weights[q]


@functools.lru_cache(maxsize=8)
def _smear_kernel(resolution: float, smear_deviation: float) -> npt.NDArray[np.float32]:
    """The smear kernel (read-only: shared by every grid with the same resolution and σ)."""
    half = max(1, round(2.0 * smear_deviation / resolution))
    d = np.arange(-half, half + 1, dtype=np.float64) * resolution
    dist2 = d[None, :] ** 2 + d[:, None] ** 2
    kernel = np.exp(-0.5 * dist2 / (smear_deviation * smear_deviation))
    kernel[dist2 > (half * resolution) ** 2 + 1e-12] = 0.0
    out = kernel.astype(np.float32)
    out.flags.writeable = False
    return out


def build_correlation_grid(
    reference_points: FloatArray,
    bounds: tuple[float, float, float, float],
    resolution: float,
    smear_deviation: float,
    levels: int = 1,
) -> CorrelationGrid:
    """Rasterise reference points (N, 2, map frame) inside ``bounds`` = (xmin, ymin, xmax, ymax).

    Each point's cell gets value 1 and its neighbours ``exp(-½ (d/σ)²)`` out to 2σ (max over
    points). ``levels`` > 1 adds the max-pooled pyramid used by branch and bound.
    """
    xmin, ymin, xmax, ymax = bounds
    margin = 2.0 * smear_deviation + resolution
    xmin, ymin, xmax, ymax = xmin - margin, ymin - margin, xmax + margin, ymax + margin
    width = max(1, math.ceil((xmax - xmin) / resolution))
    height = max(1, math.ceil((ymax - ymin) / resolution))
    like = np.zeros((height, width), dtype=np.float32)
    pts = np.asarray(reference_points, dtype=np.float64)
    if pts.size:
        col = np.floor((pts[:, 0] - xmin) / resolution).astype(np.int64)
        row = np.floor((pts[:, 1] - ymin) / resolution).astype(np.int64)
        _splat(like, col, row, _smear_kernel(resolution, smear_deviation))
    pyramid = [like]
    for h in range(1, max(1, levels)):
        pyramid.append(_pool_level(pyramid[-1], 1 << (h - 1)))
    return CorrelationGrid(tuple(pyramid), (xmin, ymin), resolution)


@njit(cache=True)
def _pool_level(prev: npt.NDArray[np.float32], half: int) -> npt.NDArray[np.float32]:
    """The next pyramid level: the max of ``prev`` at (r, c), (r, c + half), (r + half, c)
    and (r + half, c + half) (0 past the edges), i.e. the max of the level below over the
    2·half × 2·half cells from (r, c) — what a dilation anchored at (0, 0) with a zero border
    gives, exactly (the grid holds no negative values), in three max passes per cell."""
    h, w = prev.shape
    out = np.empty((h, w), np.float32)
    for r in range(h):
        a = prev[r]
        for c in range(w - half):
            out[r, c] = max(a[c], a[c + half])
        for c in range(max(0, w - half), w):
            out[r, c] = max(a[c], np.float32(0.0))
    for r in range(h - half):
        b = out[r + half]
        o = out[r]
        for c in range(w):
            o[c] = max(o[c], b[c])
    return out


def pyramid_levels(params: MatcherParams) -> int:
    """Pyramid depth for a search window: 1 (plain grid search) for small windows, else ~log2."""
    half = max(1, round(0.5 * params.search_dimension / params.resolution))
    if half <= 40:
        return 1
    return max(1, min(_MAX_LEVELS, int(math.log2(2 * half + 1))))


@njit(cache=True)
def _score(
    grid: npt.NDArray[np.float32],
    px: npt.NDArray[np.int64],
    py: npt.NDArray[np.int64],
    dx: int,
    dy: int,
) -> float:
    h, w = grid.shape
    total = 0.0
    for i in range(px.size):
        c = px[i] + dx
        r = py[i] + dy
        if 0 <= c < w and 0 <= r < h:
            total += grid[r, c]
    return total / max(px.size, 1)
