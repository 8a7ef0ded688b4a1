"""Correlative scan-to-map matching, multi-resolution (Olson 2009), with sub-cell refinement.

A reference point set (the local map) is rasterised into a *correlation grid* whose cells hold
``exp(-½ (d/σ)²)`` for the distance d to the nearest reference point (Karto's smear kernel,
computed with a Euclidean distance transform; 0 beyond 2σ). A scan's response at a pose is the
mean grid value under its end points (0..1, Karto's response scaled from 0..100).

The search covers a translation window around the prior at the grid's resolution and
headings ``prior ± coarse_search_angle_offset`` in ``coarse_angle_resolution`` steps.
Translations are searched by branch and bound over precomputed max-pooled grids
(Olson's multi-resolution idea in Cartographer's form: level h holds the maximum of the
2^h × 2^h cells it covers, an upper bound on every finer candidate beneath it), so wide
windows cost little. The best coarse candidate is refined on a fine angular step
(``fine_search_angle_offset``) over ±½ coarse step and ±2 cells (optionally re-centred while
its best sits on the box's edge: ``fine_search_climb``), then to sub-cell accuracy by
Gauss–Newton on the bilinearly interpolated grid. Karto's distance/angle penalties are
applied to candidate responses when ``penalize`` is set (sequential matching).

The covariance follows Karto's recipe: the response-weighted spread of every translation
candidate at the best heading whose response is within 0.1 of the best, floored and scaled by
1/response; the heading variance likewise over the fine headings.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
from numba import njit

from eddiebot.geometry import wrap_angle
from eddiebot.geometry.grid import bucket_grid

__all__ = [
    "CorrelationGrid",
    "MatchResult",
    "MatcherParams",
    "build_correlation_grid",
    "match_scan",
    "point_normals",
    "pyramid_levels",
    "refine_icp",
    "refine_icp_with_covariance",
    "score_pose",
]

FloatArray = npt.NDArray[np.float64]

_MAX_LEVELS = 6


@dataclass(frozen=True)
class MatcherParams:
    """One search set-up (slam_toolbox names in brackets)."""

    search_dimension: float = 0.5
    """Side of the square translation window, m [correlation_search_space_dimension]."""
    resolution: float = 0.01
    """Correlation grid cell, m [correlation_search_space_resolution]."""
    smear_deviation: float = 0.1
    """σ of the smear kernel, m [correlation_search_space_smear_deviation]."""
    coarse_angle_offset: float = 0.349
    """± heading range, rad [coarse_search_angle_offset]."""
    coarse_angle_resolution: float = 0.0349
    """Coarse heading step, rad [coarse_angle_resolution]."""
    fine_angle_step: float = 0.00349
    """Fine heading step, rad [fine_search_angle_offset]."""
    penalize: bool = True
    distance_variance_penalty: float = 0.5
    angle_variance_penalty: float = 1.0
    minimum_distance_penalty: float = 0.05
    minimum_angle_penalty: float = 0.9
    use_response_expansion: bool = True
    refine: bool = True
    """Sub-cell Gauss–Newton refinement after the discrete search."""
    fine_search_climb: int = 0
    """Re-centre the fine search on its best up to this many times while that best lies on
    the edge of its translation box (0: one box around the coarse best, as Karto)."""
    coarse_heading_variance: bool = False
    """Heading variance from every coarse heading's best response over the whole window
    (headings within 0.1 of the best count), not only the fine headings next to the best:
    a narrow scan can fit nearly as well several degrees off."""


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


@dataclass(frozen=True)
class MatchResult:
    """Best pose (map frame, m/rad), its response (0..1) and covariance (3×3, m², rad²)."""

    pose: FloatArray
    response: float
    covariance: FloatArray


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


@njit(cache=True)
def _penalty(
    dx: float, dy: float, dth: float, dvp: float, avp: float, mdp: float, map_: float
) -> float:
    dist_pen = 1.0 - 0.2 * (dx * dx + dy * dy) / dvp
    if dist_pen < mdp:
        dist_pen = mdp
    ang_pen = 1.0 - 0.2 * dth * dth / avp
    if ang_pen < map_:
        ang_pen = map_
    return dist_pen * ang_pen


@njit(cache=True)
def _top_level_scores(
    grid: npt.NDArray[np.float32],
    px: npt.NDArray[np.int64],
    py: npt.NDArray[np.int64],
    window: int,
    step: int,
) -> npt.NDArray[np.float64]:
    """Scores on a pyramid level of every (angle, dx, dy) candidate ``step`` cells apart,
    flattened as ((a · n_side) + ix) · n_side + iy."""
    n_ang = px.shape[0]
    n_side = (2 * window + 1 + step - 1) // step
    out = np.empty(n_ang * n_side * n_side)
    k = 0
    for a in range(n_ang):
        for ix in range(n_side):
            for iy in range(n_side):
                out[k] = _score(grid, px[a], py[a], -window + ix * step, -window + iy * step)
                k += 1
    return out


@njit(cache=True)
def _branch_and_bound(
    g0: npt.NDArray[np.float32],
    g1: npt.NDArray[np.float32],
    g2: npt.NDArray[np.float32],
    g3: npt.NDArray[np.float32],
    g4: npt.NDArray[np.float32],
    g5: npt.NDArray[np.float32],
    n_levels: int,
    px: npt.NDArray[np.int64],
    py: npt.NDArray[np.int64],
    dth: npt.NDArray[np.float64],
    window: int,
    res: float,
    penalize: bool,
    dvp: float,
    avp: float,
    mdp: float,
    map_: float,
    top_scores: npt.NDArray[np.float64],
    order: npt.NDArray[np.int64],
) -> tuple[int, int, int, float]:
    """Best (angle index, dx, dy, penalised response) over the window, depth-first B&B.

    ``top_scores`` are `_top_level_scores` on the coarsest grid, ``order`` their ascending
    argsort (done outside: numba's sort costs seconds of compilation).
    """
    grids = (g0, g1, g2, g3, g4, g5)
    top = n_levels - 1
    step = 1 << top
    n_ang = px.shape[0]
    span = 2 * window + 1
    n_side = (span + step - 1) // step
    cap = n_ang * n_side * n_side + 8 * n_levels + 8
    s_a = np.empty(cap, np.int64)
    s_x = np.empty(cap, np.int64)
    s_y = np.empty(cap, np.int64)
    s_h = np.empty(cap, np.int64)
    s_s = np.empty(cap, np.float64)
    # top level candidates (scored and ordered by the caller), ascending so the best is
    # popped first
    n = 0
    for k in range(order.size):
        flat = order[k]
        a = flat // (n_side * n_side)
        ix = (flat // n_side) % n_side
        iy = flat % n_side
        s_a[n] = a
        s_x[n] = -window + ix * step
        s_y[n] = -window + iy * step
        s_h[n] = top
        s_s[n] = top_scores[flat]
        n += 1
    best_a, best_x, best_y, best_s = -1, 0, 0, 0.0
    c_a = np.empty(4, np.int64)
    c_x = np.empty(4, np.int64)
    c_y = np.empty(4, np.int64)
    c_s = np.empty(4, np.float64)
    while n > 0:
        n -= 1
        a, x, y, h, s = s_a[n], s_x[n], s_y[n], s_h[n], s_s[n]
        if s <= best_s:
            continue
        if h == 0:
            if penalize:
                s = s * _penalty(x * res, y * res, dth[a], dvp, avp, mdp, map_)
            if s > best_s:
                best_a, best_x, best_y, best_s = a, x, y, s
            continue
        half = 1 << (h - 1)
        m = 0
        for ox in (0, half):
            for oy in (0, half):
                cx = x + ox
                cy = y + oy
                if cx > window or cy > window:
                    continue
                c_a[m] = a
                c_x[m] = cx
                c_y[m] = cy
                c_s[m] = _score(grids[h - 1], px[a], py[a], cx, cy)
                m += 1
        # push in ascending order of score
        for _ in range(m):
            k_min = -1
            v_min = 1e300
            for k in range(m):
                if c_s[k] >= 0.0 and c_s[k] < v_min:
                    v_min = c_s[k]
                    k_min = k
            if k_min < 0:
                break
            if v_min > best_s:
                s_a[n] = c_a[k_min]
                s_x[n] = c_x[k_min]
                s_y[n] = c_y[k_min]
                s_h[n] = h - 1
                s_s[n] = v_min
                n += 1
            c_s[k_min] = -1.0
    return best_a, best_x, best_y, best_s


@njit(cache=True)
def _response_block(
    grid: npt.NDArray[np.float32],
    px: npt.NDArray[np.int64],
    py: npt.NDArray[np.int64],
    x0: int,
    y0: int,
    n: int,
    step: int,
) -> npt.NDArray[np.float64]:
    """Mean grid value under the points for translations x0 + step·ix, y0 + step·iy (n × n).

    Loops run point → row → column so that each point reads short runs of one grid row
    (cache-friendly; the naive candidate-major order is several times slower). The sums are
    kept row-major in (iy, ix) and each point's in-grid column range is found once, so the
    innermost loop is a branch-free strided read; every candidate still adds the points in
    scan order (the same sums, bit for bit).
    """
    h, w = grid.shape
    acc = np.zeros((n, n))
    for i in range(px.size):
        c0 = px[i] + x0
        # candidates ix in [lo, hi) read columns c0 + step·ix inside 0..w-1
        lo = 0 if c0 >= 0 else (step - 1 - c0) // step
        hi = min(n, (w - 1 - c0) // step + 1) if c0 <= w - 1 else 0
        if lo >= hi:
            continue
        r0 = py[i] + y0
        m = hi - lo
        for iy in range(n):
            r = r0 + step * iy
            if r < 0 or r >= h:
                continue
            # slices indexed from 0 carry no negative-index wraparound, so the contiguous
            # case compiles to vector adds
            run = grid[r, c0 + step * lo :]
            out_run = acc[iy, lo:hi]
            if step == 1:
                for k in range(m):
                    out_run[k] += run[k]
            else:
                for k in range(m):
                    out_run[k] += run[step * k]
    inv = 1.0 / max(px.size, 1)
    out = np.empty((n, n))
    for ix in range(n):
        for iy in range(n):
            out[ix, iy] = acc[iy, ix] * inv
    return out


@njit(cache=True)
def _column_phases(grid: npt.NDArray[np.float32], step: int) -> npt.NDArray[np.float32]:
    """The grid's columns split by phase: ``out[p, r, j] = grid[r, step·j + p]`` (zero past
    the last column), so a run of every ``step``-th column is contiguous in one phase."""
    h, w = grid.shape
    wq = (w + step - 1) // step
    out = np.empty((step, h, wq), np.float32)
    for p in range(step):
        n = (w - p + step - 1) // step
        for r in range(h):
            src = grid[r, p:]
            dst = out[p, r]
            for j in range(n):
                dst[j] = src[step * j]
            for j in range(n, wq):
                dst[j] = 0.0
    return out


@njit(cache=True)
def _response_block_phased(
    phases: npt.NDArray[np.float32],
    w: int,
    px: npt.NDArray[np.int64],
    py: npt.NDArray[np.int64],
    x0: int,
    y0: int,
    n: int,
    step: int,
) -> npt.NDArray[np.float64]:
    """`_response_block` for ``step`` > 1 on `_column_phases` of a grid ``w`` columns wide:
    the same candidates, points and sums in the same order (the same values bit for bit),
    read from contiguous runs."""
    h = phases.shape[1]
    acc = np.zeros((n, n))
    for i in range(px.size):
        c0 = px[i] + x0
        lo = 0 if c0 >= 0 else (step - 1 - c0) // step
        hi = min(n, (w - 1 - c0) // step + 1) if c0 <= w - 1 else 0
        if lo >= hi:
            continue
        c = c0 + step * lo
        plane = phases[c % step]
        j0 = c // step
        r0 = py[i] + y0
        m = hi - lo
        for iy in range(n):
            r = r0 + step * iy
            if r < 0 or r >= h:
                continue
            run = plane[r, j0:]
            out_run = acc[iy, lo:hi]
            for k in range(m):
                out_run[k] += run[k]
    inv = 1.0 / max(px.size, 1)
    out = np.empty((n, n))
    for ix in range(n):
        for iy in range(n):
            out[ix, iy] = acc[iy, ix] * inv
    return out


@njit(cache=True)
def _coarse_grid_search(
    g0: npt.NDArray[np.float32],
    px: npt.NDArray[np.int64],
    py: npt.NDArray[np.int64],
    dth: npt.NDArray[np.float64],
    window: int,
    step: int,
    res: float,
    penalize: bool,
    dvp: float,
    avp: float,
    mdp: float,
    map_: float,
    profile: npt.NDArray[np.float64],
) -> tuple[int, int, int, float]:
    """Karto's coarse pass: every heading, translations every ``step`` cells.

    Also writes each heading's best (penalised) response into ``profile`` (what
    `_heading_profile` returns for the same arguments), so the heading variance needs no
    second pass over the window.
    """
    best_a, best_x, best_y, best_s = -1, 0, 0, 0.0
    n = 2 * (window // step) + 1
    x0 = -(window // step) * step
    phases = _column_phases(g0, step)
    for a in range(px.shape[0]):
        block = _response_block_phased(phases, g0.shape[1], px[a], py[a], x0, x0, n, step)
        best_h = 0.0
        for ix in range(n):
            for iy in range(n):
                s = block[ix, iy]
                # the penalty is at most 1: a raw response at or below both bests cannot win
                if s <= best_s and s <= best_h:
                    continue
                dx = x0 + step * ix
                dy = x0 + step * iy
                if penalize:
                    s *= _penalty(dx * res, dy * res, dth[a], dvp, avp, mdp, map_)
                if s > best_h:
                    best_h = s
                if s > best_s:
                    best_a, best_x, best_y, best_s = a, dx, dy, s
        profile[a] = best_h
    return best_a, best_x, best_y, best_s


@njit(cache=True)
def _heading_profile(
    g0: npt.NDArray[np.float32],
    px: npt.NDArray[np.int64],
    py: npt.NDArray[np.int64],
    dth: npt.NDArray[np.float64],
    window: int,
    step: int,
    res: float,
    penalize: bool,
    dvp: float,
    avp: float,
    mdp: float,
    map_: float,
) -> npt.NDArray[np.float64]:
    """Best (penalised) response per heading over the window, translations every ``step``."""
    n = 2 * (window // step) + 1
    x0 = -(window // step) * step
    out = np.zeros(px.shape[0])
    for a in range(px.shape[0]):
        block = _response_block(g0, px[a], py[a], x0, x0, n, step)
        best = 0.0
        for ix in range(n):
            for iy in range(n):
                v = block[ix, iy]
                if v <= best:
                    continue
                if penalize:
                    v *= _penalty(
                        (x0 + step * ix) * res, (x0 + step * iy) * res, dth[a], dvp, avp, mdp, map_
                    )
                if v > best:
                    best = v
        out[a] = best
    return out


@njit(cache=True)
def _exhaustive(
    g0: npt.NDArray[np.float32],
    px: npt.NDArray[np.int64],
    py: npt.NDArray[np.int64],
    dth: npt.NDArray[np.float64],
    cx: int,
    cy: int,
    radius: int,
    res: float,
    penalize: bool,
    dvp: float,
    avp: float,
    mdp: float,
    map_: float,
) -> npt.NDArray[np.float64]:
    """Penalised responses (n_angles, 2r+1, 2r+1) around cell offset (cx, cy); [a, ix, iy]."""
    n_ang = px.shape[0]
    side = 2 * radius + 1
    out = np.zeros((n_ang, side, side))
    for a in range(n_ang):
        block = _response_block(g0, px[a], py[a], cx - radius, cy - radius, side, 1)
        for ix in range(side):
            for iy in range(side):
                s = block[ix, iy]
                if penalize and s > 0.0:
                    s *= _penalty(
                        (cx - radius + ix) * res,
                        (cy - radius + iy) * res,
                        dth[a],
                        dvp,
                        avp,
                        mdp,
                        map_,
                    )
                out[a, ix, iy] = s
    return out


@njit(cache=True)
def _bounded_score(
    grid: npt.NDArray[np.float32],
    px: npt.NDArray[np.int64],
    py: npt.NDArray[np.int64],
    x: int,
    y: int,
    size: int,
    inv: float,
) -> float:
    """Mean of a pyramid level under the points moved by (x, y): on level 0 (``size`` 1) a
    candidate's response exactly as `_response_block` sums it (point order, times 1/n); on a
    coarser level an upper bound of every candidate in the size × size block from (x, y),
    a point whose anchor falls off the grid while its block still overlaps it counting 1
    (no cell exceeds 1). Rounding is monotone, so the bound holds in floating point too."""
    h, w = grid.shape
    total = 0.0
    for i in range(px.size):
        c = px[i] + x
        r = py[i] + y
        if 0 <= c < w and 0 <= r < h:
            total += grid[r, c]
        elif size > 1 and c + size > 0 and c < w and r + size > 0 and r < h:
            total += 1.0
    return total * inv


@njit(cache=True)
def _window_near_best(
    g0: npt.NDArray[np.float32],
    g1: npt.NDArray[np.float32],
    g2: npt.NDArray[np.float32],
    g3: npt.NDArray[np.float32],
    g4: npt.NDArray[np.float32],
    g5: npt.NDArray[np.float32],
    n_levels: int,
    px: npt.NDArray[np.int64],
    py: npt.NDArray[np.int64],
    dth: float,
    window: int,
    seed_x: int,
    seed_y: int,
    res: float,
    penalize: bool,
    dvp: float,
    avp: float,
    mdp: float,
    map_: float,
) -> npt.NDArray[np.float64]:
    """One heading's (penalised) responses over the ±window, [ix, iy] as `_exhaustive` gives
    them, where they can matter to the covariance: every candidate within 0.1 of the window's
    best holds `_exhaustive`'s value bit for bit (and so does the best), the others hold
    either their value or -1. Two passes over the pyramid: branch and bound for the best
    (seeded with the candidate at ``seed_x``, ``seed_y``), then every block whose bound
    reaches best - 0.1 down to its cells."""
    grids = (g0, g1, g2, g3, g4, g5)
    side = 2 * window + 1
    out = np.full((side, side), -1.0)
    inv = 1.0 / max(px.size, 1)
    top = n_levels - 1
    step = 1 << top
    n_side = (side + step - 1) // step
    cap = n_side * n_side + 4 * n_levels + 8
    s_x = np.empty(cap, np.int64)
    s_y = np.empty(cap, np.int64)
    s_h = np.empty(cap, np.int64)
    s_b = np.empty(cap, np.float64)
    best = -1.0
    if abs(seed_x) <= window and abs(seed_y) <= window:
        best = _bounded_score(g0, px, py, seed_x, seed_y, 1, inv)
        if penalize and best > 0.0:
            best *= _penalty(seed_x * res, seed_y * res, dth, dvp, avp, mdp, map_)
    for phase in range(2):
        thresh = best - 0.1
        n = 0
        for ix in range(n_side):
            for iy in range(n_side):
                x = -window + ix * step
                y = -window + iy * step
                b = _bounded_score(grids[top], px, py, x, y, step, inv)
                if (phase == 0 and b > best) or (phase == 1 and b >= thresh):
                    s_x[n], s_y[n], s_h[n], s_b[n] = x, y, top, b
                    n += 1
        while n > 0:
            n -= 1
            x, y, h, b = s_x[n], s_y[n], s_h[n], s_b[n]
            if phase == 0 and b <= best:
                continue
            if h == 0:
                v = b
                if penalize and v > 0.0:
                    v *= _penalty(x * res, y * res, dth, dvp, avp, mdp, map_)
                if phase == 0:
                    best = max(best, v)
                else:
                    out[x + window, y + window] = v
                continue
            half = 1 << (h - 1)
            for ox in (0, half):
                for oy in (0, half):
                    cx = x + ox
                    cy = y + oy
                    if cx > window or cy > window:
                        continue
                    cb = _bounded_score(grids[h - 1], px, py, cx, cy, half, inv)
                    if (phase == 0 and cb > best) or (phase == 1 and cb >= thresh):
                        s_x[n], s_y[n], s_h[n], s_b[n] = cx, cy, h - 1, cb
                        n += 1
    return out


@njit(cache=True)
def _bilinear(grid: npt.NDArray[np.float32], u: float, v: float) -> tuple[float, float, float]:
    """Value and gradient (d/du, d/dv) at continuous cell coordinates (cell centres at k+0.5)."""
    h, w = grid.shape
    fu = u - 0.5
    fv = v - 0.5
    c0 = math.floor(fu)
    r0 = math.floor(fv)
    if c0 < 0 or r0 < 0 or c0 + 1 >= w or r0 + 1 >= h:
        return 0.0, 0.0, 0.0
    tu = fu - c0
    tv = fv - r0
    v00 = grid[r0, c0]
    v01 = grid[r0, c0 + 1]
    v10 = grid[r0 + 1, c0]
    v11 = grid[r0 + 1, c0 + 1]
    val = (1 - tv) * ((1 - tu) * v00 + tu * v01) + tv * ((1 - tu) * v10 + tu * v11)
    du = (1 - tv) * (v01 - v00) + tv * (v11 - v10)
    dv = (1 - tu) * (v10 - v00) + tu * (v11 - v01)
    return val, du, dv


@njit(cache=True)
def _solve3(
    a00: float,
    a01: float,
    a02: float,
    a11: float,
    a12: float,
    a22: float,
    b0: float,
    b1: float,
    b2: float,
) -> tuple[float, float, float]:
    """Solve the symmetric 3×3 system A x = b by Cramer's rule (A positive definite).

    Written out rather than ``np.linalg.solve``: LAPACK's binding costs seconds of JIT
    compilation in every fresh process without a numba cache.
    """
    c00 = a11 * a22 - a12 * a12
    c01 = a02 * a12 - a01 * a22
    c02 = a01 * a12 - a02 * a11
    det = a00 * c00 + a01 * c01 + a02 * c02
    if abs(det) < 1e-300:
        return 0.0, 0.0, 0.0
    c11 = a00 * a22 - a02 * a02
    c12 = a01 * a02 - a00 * a12
    c22 = a00 * a11 - a01 * a01
    inv = 1.0 / det
    return (
        (c00 * b0 + c01 * b1 + c02 * b2) * inv,
        (c01 * b0 + c11 * b1 + c12 * b2) * inv,
        (c02 * b0 + c12 * b1 + c22 * b2) * inv,
    )


@njit(cache=True)
def _refine(
    grid: npt.NDArray[np.float32],
    pts: npt.NDArray[np.float64],
    x: float,
    y: float,
    th: float,
    ox: float,
    oy: float,
    res: float,
    iterations: int,
) -> tuple[float, float, float, float]:
    """Gauss–Newton on Σ (1 - f(T p))² (Hector-style); returns pose and mean f."""
    n = pts.shape[0]
    for _ in range(iterations):
        c = math.cos(th)
        s = math.sin(th)
        h00 = h01 = h02 = h11 = h12 = h22 = 0.0
        g0 = g1 = g2 = 0.0
        for i in range(n):
            px = pts[i, 0]
            py = pts[i, 1]
            wx = c * px - s * py + x
            wy = s * px + c * py + y
            val, du, dv = _bilinear(grid, (wx - ox) / res, (wy - oy) / res)
            if val <= 0.0:
                continue
            gx = du / res
            gy = dv / res
            gth = gx * (-s * px - c * py) + gy * (c * px - s * py)
            r = 1.0 - val
            g0 += gx * r
            g1 += gy * r
            g2 += gth * r
            h00 += gx * gx
            h01 += gx * gy
            h02 += gx * gth
            h11 += gy * gy
            h12 += gy * gth
            h22 += gth * gth
        h00 += 1e-9 + 1e-3 * h00
        h11 += 1e-9 + 1e-3 * h11
        h22 += 1e-9 + 1e-3 * h22
        d0, d1, d2 = _solve3(h00, h01, h02, h11, h12, h22, g0, g1, g2)
        x += d0
        y += d1
        th += d2
        if abs(d0) < 1e-5 and abs(d1) < 1e-5 and abs(d2) < 1e-6:
            break
    c = math.cos(th)
    s = math.sin(th)
    total = 0.0
    for i in range(n):
        wx = c * pts[i, 0] - s * pts[i, 1] + x
        wy = s * pts[i, 0] + c * pts[i, 1] + y
        val, _, _ = _bilinear(grid, (wx - ox) / res, (wy - oy) / res)
        total += val
    return x, y, th, total / max(n, 1)


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


def score_pose(points: FloatArray, pose: FloatArray, grid: CorrelationGrid) -> float:
    """Response (0..1) of scan points (sensor frame) at ``pose`` (map frame) on ``grid``."""
    px, py = _cells_for_angles(points, np.asarray(pose, float), np.array([pose[2]], float), grid)
    return float(_score(grid.likelihood, px[0], py[0], 0, 0))


@njit(cache=True)
def _block_sum(a: FloatArray, lo: int, n: int) -> float:
    """numpy's pairwise-sum leaf (n <= 128): eight accumulators, then the tail."""
    if n < 8:
        res = 0.0
        for i in range(n):
            res += a[lo + i]
        return res
    r0, r1, r2, r3 = a[lo], a[lo + 1], a[lo + 2], a[lo + 3]
    r4, r5, r6, r7 = a[lo + 4], a[lo + 5], a[lo + 6], a[lo + 7]
    i = 8
    end = n - n % 8
    while i < end:
        r0 += a[lo + i]
        r1 += a[lo + i + 1]
        r2 += a[lo + i + 2]
        r3 += a[lo + i + 3]
        r4 += a[lo + i + 4]
        r5 += a[lo + i + 5]
        r6 += a[lo + i + 6]
        r7 += a[lo + i + 7]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res += a[lo + i]
        i += 1
    return res


@njit(cache=True)
def _pairwise_sum(a: FloatArray, lo: int, n: int) -> float:
    """``a[lo:lo + n].sum()`` as numpy sums a contiguous float64 run: halves (the first a
    multiple of 8 long) split until at most 128 long, leaves by `_block_sum`, the halves'
    sums added up the tree — the same value to the last bit (an explicit stack: numba's
    cache does not take recursive functions)."""
    if n <= 128:
        return _block_sum(a, lo, n)
    s_lo = np.empty(64, np.int64)
    s_n = np.empty(64, np.int64)
    s_stage = np.empty(64, np.int64)
    vals = np.empty(64)
    depth = 1
    nv = 0
    s_lo[0], s_n[0], s_stage[0] = lo, n, 0
    while depth > 0:
        t = depth - 1
        m = s_n[t]
        if m <= 128:
            vals[nv] = _block_sum(a, s_lo[t], m)
            nv += 1
            depth -= 1
            continue
        half = m // 2
        half -= half % 8
        if s_stage[t] == 0:
            s_stage[t] = 1
            s_lo[depth], s_n[depth], s_stage[depth] = s_lo[t], half, 0
            depth += 1
        elif s_stage[t] == 1:
            s_stage[t] = 2
            s_lo[depth], s_n[depth], s_stage[depth] = s_lo[t] + half, m - half, 0
            depth += 1
        else:
            right = vals[nv - 1]
            left = vals[nv - 2]
            nv -= 2
            vals[nv] = left + right
            nv += 1
            depth -= 1
    return vals[0]


@njit(cache=True)
def _weighted_covariance(
    values: FloatArray, coords: FloatArray, best: float, floor: FloatArray
) -> FloatArray:
    """Response-weighted covariance (D, D) of the candidates within 0.1 of ``best``, plus
    ``diag(floor)``; ``coords`` (K, D). The sums run in numpy's order for the expressions
    ``w.sum()``, ``(w[:, None] * c).sum(axis=0)`` and ``(w · d dᵀ).sum(axis=0)`` (pairwise
    for the first, in candidate order for the others), so the values are numpy's bit for bit.
    """
    dim = coords.shape[1]
    thresh = best - 0.1
    keep = np.empty(values.size, np.int64)
    w = np.empty(values.size)
    k = 0
    for i in range(values.size):
        if values[i] >= thresh:
            keep[k] = i
            w[k] = values[i]
            k += 1
    out = np.zeros((dim, dim))
    norm = _pairwise_sum(w, 0, k)
    if norm <= 1e-12:
        for j in range(dim):
            out[j, j] = floor[j]
        return out
    mean = np.zeros(dim)
    if dim == 1:
        # a (K, 1) reduction is a contiguous run to numpy: summed pairwise
        prod = np.empty(k)
        for q in range(k):
            prod[q] = w[q] * coords[keep[q], 0]
        mean[0] = _pairwise_sum(prod, 0, k) / norm
        for q in range(k):
            dq = coords[keep[q], 0] - mean[0]
            prod[q] = w[q] * dq * dq
        out[0, 0] = _pairwise_sum(prod, 0, k)
    else:
        # (K, D) and (K, D, D) reductions over K: one candidate after another
        for j in range(dim):
            acc = w[0] * coords[keep[0], j]
            for q in range(1, k):
                acc += w[q] * coords[keep[q], j]
            mean[j] = acc / norm
        d = np.empty(dim)
        for q in range(k):
            for j in range(dim):
                d[j] = coords[keep[q], j] - mean[j]
            for j in range(dim):
                wd = w[q] * d[j]
                for m in range(dim):
                    if q == 0:
                        out[j, m] = wd * d[m]
                    else:
                        out[j, m] += wd * d[m]
    for j in range(dim):
        for m in range(dim):
            out[j, m] = out[j, m] / norm + (floor[j] if j == m else 0.0)
    return out


def match_scan(
    points: FloatArray,
    grid: CorrelationGrid,
    prior: FloatArray,
    params: MatcherParams,
    *,
    reject_below: float | None = None,
) -> MatchResult:
    """Match scan end points (M, 2, sensor frame) to ``grid`` around ``prior`` (sensor pose).

    With a single-level grid the translations are searched as Karto does (every second to
    fourth cell, then every cell around the best); with a pyramid (`build_correlation_grid(levels=n)`,
    n ≈ log2 of the window in cells) by branch and bound, exactly, at every cell.

    ``reject_below``: for a caller that discards a match whose response is below it, such a
    match returns as soon as its response is known, with the fine search's discrete pose and
    no covariance (``diag(1e3)``); the response is the one the full match would return.
    """
    prior = np.asarray(prior, dtype=np.float64)
    pts = np.ascontiguousarray(points, dtype=np.float64)
    res = grid.resolution
    if pts.shape[0] == 0:
        return MatchResult(prior.copy(), 0.0, np.diag([1e3, 1e3, 1e3]))
    window = max(1, round(0.5 * params.search_dimension / res))
    levels = list(grid.levels[:_MAX_LEVELS])
    while len(levels) < _MAX_LEVELS:
        levels.append(levels[-1])
    n_levels = min(len(grid.levels), _MAX_LEVELS)
    offset = params.coarse_angle_offset
    step = max(params.coarse_angle_resolution, 1e-6)
    best = (-1, 0, 0, 0.0)
    dth = np.zeros(1)
    # The coarse pass scores a thinned point set (one point per half-σ cell): the smear
    # makes nearby points nearly redundant there; fine pass, covariance and refinement use all.
    coarse_pts = _thin(pts, max(0.5 * params.smear_deviation, 2.0 * res))
    # Karto steps 2 cells; a wide smear (σ >= 10 cells) is smooth enough for up to 4, and the
    # fine pass below covers ±(step/2 + 1) cells around the coarse best.
    coarse_step = int(max(2, min(4, math.floor(params.smear_deviation / (2.5 * res)))))
    # per-heading best of the plain coarse pass (None after branch and bound)
    profile: FloatArray | None = None
    for attempt in range(4 if params.use_response_expansion else 1):
        n_half = math.floor(offset / step + 1e-9)
        dth = step * np.arange(-n_half, n_half + 1, dtype=np.float64)
        px, py = _cells_for_angles(coarse_pts, prior, prior[2] + dth, grid)
        penalties = (
            params.penalize,
            params.distance_variance_penalty,
            params.angle_variance_penalty,
            params.minimum_distance_penalty,
            params.minimum_angle_penalty,
        )
        if n_levels > 1:
            top_step = 1 << (n_levels - 1)
            top_scores = _top_level_scores(levels[n_levels - 1], px, py, window, top_step)
            order = np.argsort(top_scores, kind="stable").astype(np.int64)
            best = _branch_and_bound(
                levels[0],
                levels[1],
                levels[2],
                levels[3],
                levels[4],
                levels[5],
                n_levels,
                px,
                py,
                dth,
                window,
                res,
                *penalties,
                top_scores,
                order,
            )
        else:
            profile = np.zeros(dth.size)
            best = _coarse_grid_search(
                grid.likelihood, px, py, dth, window, coarse_step, res, *penalties, profile
            )
        if best[3] > 0.0 or attempt == 3:
            break
        offset += 0.349  # slam_toolbox widens by 20° per retry
    a_idx, bx, by, coarse_score = best
    if a_idx < 0:
        return MatchResult(prior.copy(), 0.0, np.diag([1e3, 1e3, 1e3]))
    # fine headings around the coarse best
    fine = max(params.fine_angle_step, 1e-6)
    n_fine = math.floor(0.5 * step / fine + 1e-9)
    fdth = dth[a_idx] + fine * np.arange(-n_fine, n_fine + 1, dtype=np.float64)
    fpx, fpy = _cells_for_angles(pts, prior, prior[2] + fdth, grid)
    radius = coarse_step // 2 + 1 if n_levels == 1 else 1
    penalties = (
        params.penalize,
        params.distance_variance_penalty,
        params.angle_variance_penalty,
        params.minimum_distance_penalty,
        params.minimum_angle_penalty,
    )
    resp = _exhaustive(grid.likelihood, fpx, fpy, fdth, bx, by, radius, res, *penalties)
    fa, fix, fiy = np.unravel_index(int(np.argmax(resp)), resp.shape)
    # Heading and translation are coupled (the scan turns about the sensor, metres away from
    # most end points): the best fine heading can want a translation outside the box around
    # the coarse best. Follow the best to the box's edge until it is inside (bounded).
    for _ in range(params.fine_search_climb):
        at_edge = fix in (0, 2 * radius) or fiy in (0, 2 * radius)
        if not at_edge:
            break
        nx, ny = bx - radius + int(fix), by - radius + int(fiy)
        if max(abs(nx), abs(ny)) > window:
            break
        bx, by = nx, ny
        resp = _exhaustive(grid.likelihood, fpx, fpy, fdth, bx, by, radius, res, *penalties)
        fa, fix, fiy = np.unravel_index(int(np.argmax(resp)), resp.shape)
    best_resp = float(resp[fa, fix, fiy])
    dx = bx - radius + int(fix)
    dy = by - radius + int(fiy)
    pose = np.array([prior[0] + dx * res, prior[1] + dy * res, prior[2] + fdth[fa]])
    if reject_below is not None and best_resp < reject_below:
        return MatchResult(pose, best_resp, np.diag([1e3, 1e3, 1e3]))
    # covariance: translation spread over the whole window at the best heading (thinned
    # points: the spread, not the exact values, matters here)
    cpx, cpy = _cells_for_angles(coarse_pts, prior, prior[2] + fdth[fa : fa + 1], grid)
    if n_levels > 1:
        # wide window: only the candidates that can come within 0.1 of the best (the ones
        # the covariance keeps) are scored, found through the pyramid's bounds
        full = _window_near_best(
            levels[0],
            levels[1],
            levels[2],
            levels[3],
            levels[4],
            levels[5],
            n_levels,
            cpx[0],
            cpy[0],
            float(fdth[fa]),
            window,
            dx,
            dy,
            res,
            *penalties,
        )
    else:
        full = _exhaustive(
            grid.likelihood,
            cpx,
            cpy,
            fdth[fa : fa + 1],
            0,
            0,
            window,
            res,
            *penalties,
        )[0]
    coords = _window_offsets(window, res)
    ref = float(full.max())
    xy_cov = _weighted_covariance(full.ravel(), coords, ref, np.full(2, 0.1 * res * res))
    ang_vals = resp[:, fix, fiy]
    th_cov = _weighted_covariance(ang_vals, fdth[:, None], best_resp, np.array([0.1 * fine * fine]))
    cov = np.zeros((3, 3))
    cov[:2, :2] = xy_cov
    cov[2, 2] = th_cov[0, 0]
    if params.coarse_heading_variance and dth.size > 1:
        if profile is None:
            # branch and bound scores only part of the window: one full pass per heading
            profile = _heading_profile(
                grid.likelihood, px, py, dth, window, coarse_step, res, *penalties
            )
        coarse_th = _weighted_covariance(
            profile, dth[:, None], float(profile.max()), np.array([0.1 * fine * fine])
        )
        cov[2, 2] = max(cov[2, 2], float(coarse_th[0, 0]))
    cov /= max(best_resp, 1e-3)
    if params.refine and best_resp > 0.0:
        rx, ry, rth, rscore = _refine(
            grid.likelihood, pts, pose[0], pose[1], pose[2], grid.origin[0], grid.origin[1], res, 10
        )
        # Trust the refinement near the discrete optimum (within one smear σ: the penalty can
        # hold the discrete pose that far from the best fit) and only when its mean response
        # is at least the discrete pose's: on sparse reference points (beams centimetres apart
        # on a far wall) the smeared grid is bumpy along walls and Σ(1 - f)² can pull the
        # heading off while the mean response drops.
        raw = score_pose(pts, pose, grid)
        if (
            math.hypot(rx - pose[0], ry - pose[1]) <= max(2.0 * res, params.smear_deviation)
            and abs(rth - pose[2]) <= 0.5 * step
            and rscore >= raw
        ):
            pose = np.array([rx, ry, rth])
    pose[2] = float(wrap_angle(pose[2]))
    del coarse_score
    return MatchResult(pose, best_resp, cov)


#: cells per ICP pairing distance in the nearest-neighbour buckets (cell = 5 cm at 0.2 m; any
#: count gives the same pairs, a finer one fewer distance checks per point)
_ICP_CELLS_PER_RANGE = 4


@njit(cache=True)
def _icp_pairs(
    points: FloatArray,
    reference: FloatArray,
    normals: FloatArray,
    planar: npt.NDArray[np.bool_],
    pose: FloatArray,
    max_distance: float,
    x0: float,
    y0: float,
    nx: int,
    ny: int,
    start: npt.NDArray[np.int64],
    order: npt.NDArray[np.int64],
    jac: FloatArray,
    r: FloatArray,
    jac_w: FloatArray,
    w: FloatArray,
) -> int:
    """Point-to-line pairs at ``pose``: each point's nearest reference point closer than
    ``max_distance`` (searched ring by ring over cells of ``max_distance`` /
    `_ICP_CELLS_PER_RANGE`, stopping once no outer cell can hold a nearer one), kept when that
    point's normal is line-like. Writes, in point order, each
    pair's Jacobian row (n, n·R'p) into ``jac``, its residual n·(world − q) into ``r``, its
    Huber weight (5 cm) into ``w`` and the weighted row into ``jac_w`` (the values the numpy
    expressions gave, element by element);
    returns the number of pairs."""
    c = math.cos(pose[2])
    s = math.sin(pose[2])
    md2 = max_distance * max_distance
    cell = max_distance / _ICP_CELLS_PER_RANGE
    rings = _ICP_CELLS_PER_RANGE
    count = 0
    for i in range(points.shape[0]):
        px = points[i, 0]
        py = points[i, 1]
        wx = pose[0] + c * px - s * py
        wy = pose[1] + s * px + c * py
        cx = math.floor((wx - x0) / cell)
        cy = math.floor((wy - y0) / cell)
        best = -1
        best_d2 = md2
        for ring in range(rings + 1):
            for iy in range(max(cy - ring, 0), min(cy + ring + 1, ny)):
                edge = iy == cy - ring or iy == cy + ring
                step = 1 if edge else 2 * ring
                for ix in range(cx - ring, cx + ring + 1, max(step, 1)):
                    if ix < 0 or ix >= nx:
                        continue
                    k = iy * nx + ix
                    for m in range(start[k], start[k + 1]):
                        j = order[m]
                        dx = wx - reference[j, 0]
                        dy = wy - reference[j, 1]
                        d2 = dx * dx + dy * dy
                        if d2 < best_d2 or (d2 == best_d2 and best >= 0 and j < best):
                            best_d2 = d2
                            best = j
            # anything in an outer ring is at least ring·cell away
            if best >= 0 and best_d2 < (ring * cell) ** 2:
                break
            # ... and at least as far as the searched square's nearest side that has cells
            # beyond it (less a margin for the buckets' rounding): most points stop after
            # the cell they fall in
            gap = math.inf
            if cx - ring - 1 >= 0:
                gap = min(gap, wx - (x0 + (cx - ring) * cell))
            if cx + ring + 1 <= nx - 1:
                gap = min(gap, x0 + (cx + ring + 1) * cell - wx)
            if cy - ring - 1 >= 0:
                gap = min(gap, wy - (y0 + (cy - ring) * cell))
            if cy + ring + 1 <= ny - 1:
                gap = min(gap, y0 + (cy + ring + 1) * cell - wy)
            gap -= 1e-9
            if gap > 0.0 and (gap >= max_distance or (best >= 0 and best_d2 < gap * gap)):
                break
        if best < 0 or not planar[best]:
            continue
        n0 = normals[best, 0]
        n1 = normals[best, 1]
        r[count] = n0 * (wx - reference[best, 0]) + n1 * (wy - reference[best, 1])
        jac[count, 0] = n0
        jac[count, 1] = n1
        jac[count, 2] = n0 * (-s * px - c * py) + n1 * (c * px - s * py)
        wk = min(1.0, 0.05 / max(abs(r[count]), 1e-9))
        w[count] = wk
        jac_w[count, 0] = n0 * wk
        jac_w[count, 1] = n1 * wk
        jac_w[count, 2] = jac[count, 2] * wk
        count += 1
    return count

def pyramid_levels(params: MatcherParams) -> int:
    """Pyramid depth for a search window: 1 (plain grid search) for small windows, else ~log2."""
    half = max(1, round(0.5 * params.search_dimension / params.resolution))
    if half <= 40:
        return 1
    return max(1, min(_MAX_LEVELS, int(math.log2(2 * half + 1))))


@njit(cache=True)
def _insert_neighbour(
    best_d: FloatArray, best_i: npt.NDArray[np.int64], filled: int, d: float, j: int
) -> int:
    """Insert candidate j at squared distance d into the sorted k-best lists; new fill."""
    k = best_d.size
    if filled == k and d >= best_d[k - 1]:
        return filled
    pos = filled if filled < k else k - 1
    while pos > 0 and best_d[pos - 1] > d:
        if pos < k:
            best_d[pos] = best_d[pos - 1]
            best_i[pos] = best_i[pos - 1]
        pos -= 1
    best_d[pos] = d
    best_i[pos] = j
    return filled + 1 if filled < k else filled


@njit(cache=True)
def _nearest_sweep(
    points: FloatArray, by_x: npt.NDArray[np.int64], k: int
) -> npt.NDArray[np.int64]:
    """Indices (M, k) of each point's k nearest points (itself included), nearest first.

    ``by_x`` orders the points by x; each point's search walks outwards in that order and
    stops on either side once the x gap alone exceeds its k-th best distance (exact).
    """
    m = points.shape[0]
    out = np.empty((m, k), np.int64)
    best_d = np.empty(k)
    best_i = np.empty(k, np.int64)
    for p in range(m):
        i = by_x[p]
        xi = points[i, 0]
        yi = points[i, 1]
        filled = 0
        q = p
        while q >= 0:
            j = by_x[q]
            dx = points[j, 0] - xi
            if filled == k and dx * dx > best_d[k - 1]:
                break
            dy = points[j, 1] - yi
            filled = _insert_neighbour(best_d, best_i, filled, dx * dx + dy * dy, j)
            q -= 1
        q = p + 1
        while q < m:
            j = by_x[q]
            dx = points[j, 0] - xi
            if filled == k and dx * dx > best_d[k - 1]:
                break
            dy = points[j, 1] - yi
            filled = _insert_neighbour(best_d, best_i, filled, dx * dx + dy * dy, j)
            q += 1
        for q in range(k):
            out[i, q] = best_i[q]
    return out


#: LAPACK's machine constants (dlamch 'E', 'S', 'P') and the thresholds dsyevd / dsteqr
#: derive from them
_LA_EPS = 2.0**-53
_LA_SAFMIN = 2.0**-1022
_LA_EPS2 = _LA_EPS * _LA_EPS
_LA_SSFMAX = math.sqrt(1.0 / _LA_SAFMIN) / 3.0
_LA_SSFMIN = math.sqrt(_LA_SAFMIN) / _LA_EPS2
_LA_RMIN = math.sqrt(_LA_SAFMIN / 2.0**-52)
_LA_RMAX = math.sqrt(1.0 / (_LA_SAFMIN / 2.0**-52))


@njit(cache=True)
def _dlaev2(a: float, b: float, c: float) -> tuple[float, float, float, float]:
    """LAPACK dlaev2: eigen-decomposition of [[a, b], [b, c]] as (rt1, rt2, cs1, sn1),
    |rt1| >= |rt2|, (cs1, sn1) the unit eigenvector of rt1 (operation for operation)."""
    sm = a + c
    df = a - c
    adf = abs(df)
    tb = b + b
    ab = abs(tb)
    if abs(a) > abs(c):
        acmx, acmn = a, c
    else:
        acmx, acmn = c, a
    if adf > ab:
        q = ab / adf
        rt = adf * math.sqrt(1.0 + q * q)
    elif adf < ab:
        q = adf / ab
        rt = ab * math.sqrt(1.0 + q * q)
    else:
        rt = ab * math.sqrt(2.0)
    if sm < 0.0:
        rt1 = 0.5 * (sm - rt)
        sgn1 = -1
        rt2 = (acmx / rt1) * acmn - (b / rt1) * b
    elif sm > 0.0:
        rt1 = 0.5 * (sm + rt)
        sgn1 = 1
        rt2 = (acmx / rt1) * acmn - (b / rt1) * b
    else:
        rt1 = 0.5 * rt
        rt2 = -0.5 * rt
        sgn1 = 1
    if df >= 0.0:
        cs = df + rt
        sgn2 = 1
    else:
        cs = df - rt
        sgn2 = -1
    if abs(cs) > ab:
        ct = -tb / cs
        sn1 = 1.0 / math.sqrt(1.0 + ct * ct)
        cs1 = ct * sn1
    elif ab == 0.0:
        cs1 = 1.0
        sn1 = 0.0
    else:
        tn = -cs / tb
        cs1 = 1.0 / math.sqrt(1.0 + tn * tn)
        sn1 = tn * cs1
    if sgn1 == sgn2:
        tn = cs1
        cs1 = -sn1
        sn1 = tn
    return rt1, rt2, cs1, sn1


@njit(cache=True)
def _eigh2(
    a11: float, a21: float, a22: float
) -> tuple[float, float, float, float, float, float, bool]:
    """``np.linalg.eigh`` of the symmetric [[a11, a21], [a21, a22]], bit for bit: the path
    LAPACK's dsyevd ('V', lower) takes for n = 2 (dsytrd leaves a 2×2 as it is, dstedc hands
    it to dsteqr, which splits off a negligible a21 or applies dlaev2's rotation to the
    identity, then sorts ascending). Returns (w0, w1, z00, z10, z01, z11, ok): eigenvalues
    ascending, column k of Z the eigenvector of w_k; ok is False for matrices LAPACK would
    rescale first (norms below ~1e-146 or above ~1e146), which this does not replicate."""
    anrm = max(abs(a11), abs(a21), abs(a22))
    if (anrm > 0.0 and anrm < _LA_RMIN) or anrm > _LA_RMAX:
        return 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, False
    d1, d2, e = a11, a22, a21
    z11, z21, z12, z22 = 1.0, 0.0, 0.0, 1.0
    split = abs(e) == 0.0 or abs(e) <= (math.sqrt(abs(d1)) * math.sqrt(abs(d2))) * _LA_EPS
    if not split:
        anorm = max(abs(d1), abs(d2), abs(e))
        if anorm > _LA_SSFMAX or anorm < _LA_SSFMIN:
            return 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, False
        # dsteqr's QR (|d2| < |d1|) or QL sweep: its own negligibility test first
        if abs(d2) < abs(d1):
            split = e * e <= (_LA_EPS2 * abs(d2)) * abs(d1) + _LA_SAFMIN
        else:
            split = e * e <= (_LA_EPS2 * abs(d1)) * abs(d2) + _LA_SAFMIN
    if not split:
        rt1, rt2, c, s = _dlaev2(d1, e, d2)
        # dlasr's plane rotation of the identity's two columns, as evaluated there
        temp = z12
        z12 = c * temp - s * z11
        z11 = s * temp + c * z11
        temp = z22
        z22 = c * temp - s * z21
        z21 = s * temp + c * z21
        d1, d2 = rt1, rt2
    if d2 < d1:
        d1, d2 = d2, d1
        z11, z12 = z12, z11
        z21, z22 = z22, z21
    return d1, d2, z11, z21, z12, z22, True


@njit(cache=True)
def _pca_normals(
    points: FloatArray, nn: npt.NDArray[np.int64]
) -> tuple[FloatArray, bool]:
    """`point_normals`' PCA step compiled, with numpy's values bit for bit: each
    neighbourhood's mean (summed in neighbour order, divided by k), its scatter matrix
    (einsum's sums in neighbour order) and `_eigh2`. False when a matrix needs LAPACK's
    rescaling (the caller then takes numpy's path)."""
    m, k = nn.shape
    out = np.empty((m, 2))
    ce = np.empty((k, 2))
    for p in range(m):
        s0 = points[nn[p, 0], 0]
        s1 = points[nn[p, 0], 1]
        for q in range(1, k):
            s0 += points[nn[p, q], 0]
            s1 += points[nn[p, q], 1]
        m0 = s0 / k
        m1 = s1 / k
        for q in range(k):
            ce[q, 0] = points[nn[p, q], 0] - m0
            ce[q, 1] = points[nn[p, q], 1] - m1
        c00 = 0.0
        c10 = 0.0
        c11 = 0.0
        for q in range(k):
            c00 += ce[q, 0] * ce[q, 0]
            c10 += ce[q, 1] * ce[q, 0]
            c11 += ce[q, 1] * ce[q, 1]
        w0, w1, z00, z10, _, _, ok = _eigh2(c00, c10, c11)
        if not ok:
            return out, False
        if w0 < 0.1 * w1 + 1e-12:
            out[p, 0] = z00
            out[p, 1] = z10
        else:
            out[p, 0] = np.nan
            out[p, 1] = np.nan
    return out, True


def point_normals(
    points: FloatArray, tree: Any = None, neighbours: int = 6
) -> FloatArray:
    """Unit normals (M, 2) from a PCA of each point's nearest neighbours; NaN where the
    neighbourhood is not line-like (corners, clutter). Without a ``tree`` the neighbours are
    found by a compiled sweep along x (exact, nearest first, as a k-d tree query) and the PCA
    is compiled too (`_pca_normals`: numpy's values bit for bit)."""
    points = np.ascontiguousarray(points, dtype=np.float64)
    if points.shape[0] < neighbours:
        return np.full(points.shape, np.nan)
    if tree is None:
        by_x = np.argsort(points[:, 0], kind="stable").astype(np.int64)
        nn = _nearest_sweep(points, by_x, neighbours)
        normals, ok = _pca_normals(points, nn)
        if ok:
            return normals
    else:
        _, nn = tree.query(points, k=neighbours)
    nb = points[nn]
    centred = nb - nb.mean(axis=1, keepdims=True)
    cov = np.einsum("mki,mkj->mij", centred, centred)
    vals, vecs = np.linalg.eigh(cov)
    normals = vecs[:, :, 0].copy()
    normals[~(vals[:, 0] < 0.1 * vals[:, 1] + 1e-12)] = np.nan
    return normals


def refine_icp(
    points: FloatArray,
    reference: FloatArray,
    pose: FloatArray,
    *,
    max_distance: float = 0.2,
    iterations: int = 10,
    normal_neighbours: int = 6,
    reference_normals: FloatArray | None = None,
) -> tuple[FloatArray, float]:
    """Point-to-line ICP from ``pose`` (sensor pose, map frame) onto reference points (map).

    Normals come from a PCA of each reference point's nearest neighbours; pairs farther than
    ``max_distance`` are ignored and the rest weighted by a Huber kernel (5 cm). Returns the
    refined pose and the inlier share (0..1). The correlative search finds the basin; this
    polishes the pose below the search grid's and the smear's resolution.
    """
    pose_out, share, _ = refine_icp_with_covariance(
        points,
        reference,
        pose,
        max_distance=max_distance,
        iterations=iterations,
        normal_neighbours=normal_neighbours,
        reference_normals=reference_normals,
    )
    return pose_out, share


def refine_icp_with_covariance(
    points: FloatArray,
    reference: FloatArray,
    pose: FloatArray,
    *,
    max_distance: float = 0.2,
    iterations: int = 10,
    normal_neighbours: int = 6,
    reference_normals: FloatArray | None = None,
) -> tuple[FloatArray, float, FloatArray | None]:
    """`refine_icp`, also returning the fit's covariance (3×3, map frame, m², rad²).

    The covariance is the Gauss–Newton one at the final pose: the inverse of the weighted
    point-to-line Hessian JᵀWJ scaled by the weighted residual variance Σwr²/(Σw − 3). It is
    small along directions the scan's lines pin down and large along those no line observes
    (a corridor's length: the Hessian is nearly singular there). None when fewer than 10
    pairs match.
    """
    pose = np.asarray(pose, dtype=np.float64).copy()
    if points.shape[0] < 10 or reference.shape[0] < normal_neighbours + 1:
        return pose, 0.0, None
    points = np.ascontiguousarray(points, dtype=np.float64)
    reference = np.ascontiguousarray(reference, dtype=np.float64)
    if reference_normals is None:
        normals = point_normals(reference, neighbours=normal_neighbours)
    else:
        normals = reference_normals
    planar = np.isfinite(normals[:, 0])
    normals = np.ascontiguousarray(np.where(planar[:, None], normals, 0.0), dtype=np.float64)
    x0, y0, nx, ny, start, order = bucket_grid(reference, max_distance / _ICP_CELLS_PER_RANGE)
    jac_buf = np.empty((points.shape[0], 3))
    jac_w_buf = np.empty((points.shape[0], 3))
    r_buf = np.empty(points.shape[0])
    w_buf = np.empty(points.shape[0])
    damping = 1e-9 * np.eye(3)
    inlier_share = 0.0
    fit: tuple[FloatArray, float] | None = None
    for it in range(iterations + 1):
        count = _icp_pairs(
            points, reference, normals, planar, pose, max_distance,
            x0, y0, nx, ny, start, order, jac_buf, r_buf, jac_w_buf, w_buf,
        )
        inlier_share = float(count) / points.shape[0]
        if count < 10:
            fit = None
            break
        # normal equations with numpy (BLAS), as the results were established with
        jac = jac_buf[:count]
        r = r_buf[:count]
        w = w_buf[:count]
        wr = w * r
        h = jac.T @ jac_w_buf[:count] + damping
        last = it == iterations
        if not last:
            delta = -np.linalg.solve(h, jac.T @ wr)
            pose += delta
            last = abs(delta[0]) < 1e-5 and abs(delta[1]) < 1e-5 and abs(delta[2]) < 1e-6
        if last:
            # the fit at the final pairs (before the step they gave): only this one is used
            sw = float(w.sum())
            fit = (h, float(np.sum(wr * r)) / max(sw - 3.0, 1.0))
            break
    covariance: FloatArray | None = None
    if fit is not None:
        covariance = np.asarray(fit[1] * np.linalg.inv(fit[0]), dtype=np.float64)
    pose[2] = float(wrap_angle(pose[2]))
    if covariance is not None:
        covariance = 0.5 * (covariance + covariance.T)
    return pose, inlier_share, covariance
